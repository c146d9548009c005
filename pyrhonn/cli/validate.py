"""``pyrhonn validate``: a validation report of a trained identifier, as MATLAB's ``compare`` and ``resid``.

``pyrhonn validate DATA.csv [DATA2.csv ...] --config CFG.toml [--out DIR] [--steps-ahead H] [--lags L]
[--min-fit PCT] [--fit-kind free_run|one_step|steps_ahead] [--dtype float32|float64]
[--valid-suffix SUFFIX] [--no-plots]``

Each data file is one validation experiment, in the format ``pyrhonn identify``
reads (:mod:`pyrhonn.datafile`: columns named by the config's ``state_names``
and ``input_names``). For every file the identifier is built afresh from the
config (so each experiment starts from the config's x0 and w0, never from
where the previous file left it) and runs with **learning off**: the weights
are the config's ``w0``, frozen; nothing is fitted on validation data.

Predictions (:mod:`pyrhonn.simulation`), per file and per state
---------------------------------------------------------------
With D the deepest delay of any state or input tap in the config's terms
(:attr:`IdentifierConfig.max_delay`), K = D + 1 is the first sample whose
prediction x̂(K) read only measured samples (rows K-1-D .. K-1); before it
the core reads its initial history (the first sample repeated).

- **one step**: x̂(k | k-1), made at sample k-1 from the measurements.
- **H steps ahead** (``--steps-ahead``, default 10): x̂(k | k-H), the network
  fed its own predictions for H-1 steps from the measurements at k-H; its
  first prediction that read only measured samples is at k = K + H - 1.
- **free run** (simulation, the parallel model): from sample K on the
  network is fed only its own predictions and the measured inputs.

Each is scored on the valid targets from its first sample on (K, K + H - 1, K):
fit % (MATLAB's NRMSE fit, 100 (1 - ||x - x̂|| / ||x - mean(x)||)), RMSE and
RRSE (:mod:`pyrhonn.metrics`, :func:`pyrhonn.residuals.fit_percent`). A
prediction that stops being finite or leaves the data's range far (the
measured range of the state in that file widened by its span on both
sides, :func:`pyrhonn.residuals.divergence_range`) from its first sample on
is **diverged**: reported with the sample (and line) where it left, and no
error figures (they would only measure how far it went).

Residual analysis (:mod:`pyrhonn.residuals`)
--------------------------------------------
On the one-step residuals e_i(k) = x_i(k) - x̂_i(k | k-1), pooled over the
files: only the samples k >= K whose target is valid and whose prediction
read measurements only (every state valid in rows k-1-D .. k-1,
:func:`pyrhonn.residuals.usable_residuals`); these fall into contiguous
stretches (a dropout or a file boundary ends one), and no correlation
product spans two stretches. Per state: the autocorrelation r_ee(tau),
tau = 0..L (``--lags``, default 25), and per input u_j the cross-correlation
r_ue(tau), tau = -L..L, normalised, with the 99 % confidence bound
+-2.576/sqrt(N) of the whiteness and independence tests (the null
hypothesis: the residuals are white and independent of the inputs); the
count and fraction of lags outside, and the verdict (white / not white;
independent of / correlated with u_j): rejected when more lags fall outside
than chance gives, or one lag lies beyond the family-wise bound
(:mod:`pyrhonn.residuals` has both rules; together they reject a white
residual at most 1 % of the time).

Outputs (in ``--out``, default ``validate-<first data file stem>``)
-----------------------------------------------------------------
- ``validation.json``: per file, per state, per kind the fit %, RMSE, RRSE,
  the number scored and the diverged sample/line (null if none); the
  correlation arrays, bounds, counts and verdicts; the ``--min-fit``
  verdict with its threshold.
- ``report.txt``: the text report, also printed.
- Unless ``--no-plots``, per state ``<state>_compare.png`` (measured, one
  step, H steps, free run; one panel per file) and ``<state>_residuals.png``
  (the autocorrelation and each input cross-correlation as stems, with the
  bound as a band).

Every file is written whole or not at all and the folder is marked
``INCOMPLETE`` while it is written, as by ``pyrhonn identify``
(:mod:`pyrhonn.atomic`).

Exit status: 0; with ``--min-fit PCT``, 1 when any state's fit % of
``--fit-kind`` (default free_run) in any file is below PCT, has no fit or
diverged, or any free run diverged (each listed); 2 for bad input (a
missing or malformed file, a bad option, data too short for the config's
window), with a one-line message.
"""
from __future__ import annotations

import argparse
import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from .. import atomic
from ..config import DTYPES, IdentifierConfig
from ..configfile import ConfigFile, load_named
from ..datafile import Data, check_suffix, read_data
from ..identifier import Identifier, IdentifierError
from ..metrics import json_value
from ..residuals import (CONFIDENCE, Z_99, CorrelationTest, departure, divergence_range, fit_percent,
                         independence_test, stretches, usable_residuals, whiteness_test)
from ..simulation import Simulation, scores, simulate
from .options import real_option

__all__ = ["KINDS", "register", "run"]

KINDS = ("one_step", "steps_ahead", "free_run")  #: the predictions scored, in report order
DEFAULT_STEPS = 10
DEFAULT_LAGS = 25
SIGNIFICANT = ".4g"  #: every number of the text report: 4 significant digits
_LEVEL = f"{100 * CONFIDENCE:g} %"  #: "99 %"


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "validate", help="validation report of an identifier on held-out data (fit, residual analysis)",
        description="Run the config's identifier with its weights frozen on one or more validation data files; "
                    "report the fit % (as MATLAB's compare), RMSE and RRSE of its one-step, H-step-ahead and "
                    "free-run predictions, and the whiteness and input independence of its one-step residuals "
                    "(as MATLAB's resid).")
    p.add_argument("data", metavar="DATA.csv", nargs="+",
                   help="validation experiments, one per file (the format of pyrhonn identify)")
    p.add_argument("--config", required=True, metavar="CFG",
                   help="identifier config with its trained weights (w0): a .toml file or a shipped config name")
    p.add_argument("--out", metavar="DIR", help="output folder (default: validate-<first data file stem>)")
    p.add_argument("--steps-ahead", default=str(DEFAULT_STEPS), metavar="H",
                   help=f"horizon of the H-step-ahead prediction (default {DEFAULT_STEPS})")
    p.add_argument("--lags", default=str(DEFAULT_LAGS), metavar="L",
                   help=f"correlation lags of the residual analysis: 0..L and -L..L (default {DEFAULT_LAGS})")
    p.add_argument("--min-fit", metavar="PCT",
                   help="exit 1 if any state's fit %% (of --fit-kind) in any file is below PCT or a free run diverged")
    p.add_argument("--fit-kind", choices=KINDS, default="free_run",
                   help="the prediction --min-fit checks (default free_run)")
    p.add_argument("--dtype", choices=DTYPES, help="build of the C core to run (default: the config's dtype)")
    p.add_argument("--valid-suffix", default="_valid", metavar="SUFFIX",
                   help="validity columns are named <state><SUFFIX> (default: _valid)")
    p.add_argument("--no-plots", action="store_true", help="do not write the PNG plots")
    p.set_defaults(func=run)


# -- options ----------------------------------------------------------------------------------------


def _count_option(option: str, text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise ValueError(f"{option}: expected a whole number, got {text!r}") from None
    if value < 1:
        raise ValueError(f"{option}: must be >= 1, got {value}")
    return value


def _output_dir(out: str | None, first_source: str) -> Path:
    if out is None:
        return Path(f"validate-{Path(first_source).stem}")
    if not out.strip():
        raise ValueError("--out: empty; give a folder (default: validate-<first data file stem>)")
    return Path(out)


def _refuse_overwriting_inputs(outputs: Sequence[Path], inputs: Sequence[tuple[str, str]]) -> None:
    """An output that is one of the inputs would replace it with the report."""
    for path in outputs:
        for what, src in inputs:
            if path.exists() and Path(src).exists() and os.path.samefile(path, src):
                raise ValueError(f"--out {path.parent}: would overwrite {what} {src} with its {path.name}; "
                                 "choose another folder")


# -- one experiment ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class ValidationRun:
    """One validation file: its data, the frozen identifier's predictions and their scores."""

    source: str
    data: Data
    sim: Simulation
    first: dict[str, int]            #: per kind, the first sample scored
    estimates: dict[str, np.ndarray]  #: per kind, (T, n) float64 aligned with the data
    diverged: dict[str, np.ndarray]   #: per kind, per state the first sample out of range (-1: none)
    states: dict[str, dict[str, dict[str, Any]]]  #: state -> kind -> figures (JSON values)

    def free_run_diverged(self) -> int | None:
        d = self.diverged["free_run"]
        return int(d[d >= 0].min()) if (d >= 0).any() else None


def _simulate(cfg: IdentifierConfig, cf: ConfigFile, data: Data, source: str, config_source: str,
              K: int, H: int) -> Simulation:
    """The frozen identifier over one file: a fresh one from the config, learning off."""
    try:
        ident = Identifier(cfg)
    except ValueError as exc:
        raise ValueError(f"{config_source}: {exc}") from None
    ident.learning = False
    X, U = data.in_dtype(cfg.dtype, cf.state_names, cf.input_names, source)
    try:
        return simulate(ident, X, U, data.valid, free_run_from=K, steps=H)
    except IdentifierError as exc:
        where = f"line {int(data.lines[exc.sample])}: " if exc.sample is not None else ""
        raise ValueError(f"{source}: {where}the identifier stopped: {exc}") from None


def _experiment(cfg: IdentifierConfig, cf: ConfigFile, data: Data, source: str, config_source: str,
                K: int, H: int) -> ValidationRun:
    sim = _simulate(cfg, cf, data, source, config_source, K, H)
    assert sim.free_run is not None and sim.ahead is not None
    T = data.n_samples
    first = {"one_step": K, "steps_ahead": K + H - 1, "free_run": K}
    estimates = {"one_step": sim.one_step.astype(np.float64), "steps_ahead": sim.ahead.astype(np.float64),
                 "free_run": sim.free_run.astype(np.float64)}
    low, high = divergence_range(data.X, data.valid)
    diverged: dict[str, np.ndarray] = {}
    states: dict[str, dict[str, dict[str, Any]]] = {name: {} for name in cf.state_names}
    for kind in KINDS:
        rows = np.arange(T) >= first[kind]
        diverged[kind] = departure(estimates[kind], rows, low, high)
        mask = data.valid & rows[:, None]
        sc = scores(data.X, estimates[kind], mask)
        for j, name in enumerate(cf.state_names):
            d = int(diverged[kind][j])
            entry: dict[str, Any] = {"fit_percent": None, "rmse": None, "rrse": None, "scored": int(sc.scored[j]),
                                     "diverged_at_sample": None if d < 0 else d,
                                     "diverged_at_line": None if d < 0 else int(data.lines[d])}
            if d < 0 and sc.scored[j]:
                x = data.X[mask[:, j], j][:, None]
                entry["fit_percent"] = json_value(float(fit_percent(x, estimates[kind][mask[:, j], j][:, None])[0]))
                entry["rmse"] = json_value(float(sc.rmse[j]))
                entry["rrse"] = json_value(float(sc.rrse[j]))
            states[name][kind] = entry
    return ValidationRun(source=source, data=data, sim=sim, first=first, estimates=estimates, diverged=diverged,
                      states=states)


# -- residual analysis ------------------------------------------------------------------------------


@dataclass(frozen=True)
class StateResiduals:
    usable: int
    whiteness: CorrelationTest
    independence: dict[str, CorrelationTest]  #: per input name


def _residual_stretches(experiments: Sequence[ValidationRun], j: int, K: int, D: int
                        ) -> tuple[list[np.ndarray], list[list[np.ndarray]]]:
    """State j's usable one-step residual stretches over every file, and each input cut the same way."""
    e_parts: list[np.ndarray] = []
    m = experiments[0].data.U.shape[1]
    u_parts: list[list[np.ndarray]] = [[] for _ in range(m)]
    for ex in experiments:
        usable = usable_residuals(ex.data.valid, K, D)[:, j]
        e = ex.data.X[:, j] - ex.estimates["one_step"][:, j]
        e_parts += stretches(e, usable)
        for i in range(m):
            u_parts[i] += stretches(ex.data.U[:, i], usable)
    return e_parts, u_parts


def _residuals(experiments: Sequence[ValidationRun], cf: ConfigFile, K: int, D: int, L: int) -> dict[str, StateResiduals]:
    out: dict[str, StateResiduals] = {}
    pieces = {name: _residual_stretches(experiments, j, K, D) for j, name in enumerate(cf.state_names)}
    for name, (e_parts, _) in pieces.items():
        N = sum(a.size for a in e_parts)
        if N <= L:
            raise ValueError(f"--lags {L}: too large for the data: state {name} has "
                             f"{_plural(N, 'usable one-step residual')} over {_plural(len(experiments), 'file')} "
                             f"(valid targets from sample {K} on whose taps read measurements only); "
                             "give fewer lags than that")
    for name, (e_parts, u_parts) in pieces.items():
        out[name] = StateResiduals(
            usable=sum(a.size for a in e_parts), whiteness=whiteness_test(e_parts, L),
            independence={u: independence_test(u_parts[i], e_parts, L) for i, u in enumerate(cf.input_names)})
    return out


def _test_json(test: CorrelationTest, verdict_key: str) -> dict[str, Any]:
    return {"lags": [int(v) for v in test.lags], "values": [json_value(float(v)) for v in test.values],
            "bound": test.bound, "tested": test.tested, "outside": test.outside, "fraction": test.fraction,
            "allowed": test.allowed, "peak_lag": test.peak_lag, "peak": json_value(test.peak),
            "peak_bound": test.peak_bound, verdict_key: test.passed}


# -- text -------------------------------------------------------------------------------------------


def _g(v: float | str | None) -> str:
    """A number of the text report: 4 significant digits ("1e-06", never "0.0000"); '-' for none."""
    if v is None:
        return "-"
    return str(v) if isinstance(v, str) else format(v, SIGNIFICANT)


def _plural(k: int, noun: str, plural: str | None = None) -> str:
    return f"{k} {noun if k == 1 else plural or noun + 's'}"


_LABELS = {"one_step": "one step", "free_run": "free run"}


def _label(kind: str, H: int) -> str:
    return _LABELS.get(kind, f"{H} steps ahead")


def _verdict_text(test: CorrelationTest, good: str, bad: str) -> str:
    if test.passed is None:
        return "no verdict (a constant series has no correlation)"
    if test.passed:
        return good
    reasons = ([f"more than {test.allowed} lags outside"] if test.outside > test.allowed else []) + \
        ([f"lag {test.peak_lag} beyond the family-wise bound"] if abs(test.peak) > test.peak_bound else [])
    return f"{bad} ({'; '.join(reasons)})"


def _test_line(what: str, test: CorrelationTest, verdict: str) -> str:
    peak = "" if test.passed is None else (f", largest {_g(test.peak)} at lag {test.peak_lag} (family-wise bound "
                                           f"+-{_g(test.peak_bound)})")
    return (f"    {what}: {test.outside} of {test.tested} lags outside ({_g(100 * test.fraction)} %, at most "
            f"{test.allowed} by chance){peak}: {verdict}")


def _report_lines(experiments: Sequence[ValidationRun], cf: ConfigFile, config_source: str, dtype: str, K: int, D: int,
                  H: int, L: int, res: dict[str, StateResiduals]) -> list[str]:
    n, m = len(cf.state_names), len(cf.input_names)
    lines = [f"validated {config_source} ({dtype}, {_plural(n, 'state')}, {_plural(m, 'input')}) on "
             f"{_plural(len(experiments), 'experiment')}: learning off, the config's weights frozen, "
             "a fresh identifier per file",
             f"deepest tap delay D = {D}: scored from sample K = D + 1 = {K} (the first whose prediction read "
             f"measured samples only); {H} steps ahead from sample K + H - 1 = {K + H - 1}",
             "fit % = 100 (1 - ||x - x̂|| / ||x - mean x||) over the valid targets; diverged = not finite or beyond "
             "the measured range widened by its span on both sides"]
    width = max(5, *(len(s) for s in cf.state_names))
    kwidth = max(len(_label(k, H)) for k in KINDS)
    for number, ex in enumerate(experiments, 1):
        d = ex.data
        lines += ["", f"experiment {number}: {ex.source} ({d.n_samples} samples, lines {int(d.lines[0])}-"
                      f"{int(d.lines[-1])}), scored from sample {K} (line {int(d.lines[K])})",
                  f"  {'state':<{width}}  {'prediction':<{kwidth}}  {'scored':>6}  {'fit %':>10}  {'RMSE':>10}  "
                  f"{'RRSE':>10}"]
        for name in cf.state_names:
            for kind in KINDS:
                st = ex.states[name][kind]
                row = f"  {name:<{width}}  {_label(kind, H):<{kwidth}}  {st['scored']:>6}  "
                if st["diverged_at_sample"] is not None:
                    row += f"diverged at sample {st['diverged_at_sample']} (line {st['diverged_at_line']})"
                else:
                    row += f"{_g(st['fit_percent']):>10}  {_g(st['rmse']):>10}  {_g(st['rrse']):>10}"
                lines.append(row.rstrip())
    lines += ["", f"residual analysis of the one-step errors (pooled over {_plural(len(experiments), 'file')}; "
                  f"lags 0..{L} and -{L}..{L})",
              f"  null hypothesis: the residuals are white and independent of the inputs; each lag then lies within "
              f"the {_LEVEL} bound +-{Z_99}/sqrt(N) with probability {_LEVEL}; the verdict rejects "
              "it when more lags fall outside than chance gives (at 0.5 %) or one lag is beyond the family-wise "
              "(Bonferroni, 0.5 %) bound: a white residual is rejected at most 1 % of the time",
              f"  samples: valid targets from sample {K} on whose prediction read measurements only (every state "
              f"valid in the {_plural(D + 1, 'row')} before); a gap or a file boundary ends a stretch, and no "
              "product spans two"]
    for name in cf.state_names:
        r = res[name]
        w = r.whiteness
        lines.append(f"  {name}: N = {r.usable} in {_plural(w.stretches, 'stretch', 'stretches')}"
                     f", bound +-{_g(w.bound)}")
        lines.append(_test_line("autocorrelation (lags 1..L)", w, _verdict_text(w, "white", "not white")))
        for u, t in r.independence.items():
            lines.append(_test_line(f"cross-correlation with {u}", t,
                                    _verdict_text(t, f"independent of {u}", f"correlated with {u}")))
    return lines


def _min_fit_failures(experiments: Sequence[ValidationRun], cf: ConfigFile, kind: str, threshold: float,
                      H: int) -> list[str]:
    failures: list[str] = []
    for ex in experiments:
        for name in cf.state_names:
            st = ex.states[name][kind]
            if st["diverged_at_sample"] is not None:
                failures.append(f"{ex.source}: {name}: {_label(kind, H)} diverged at sample "
                                f"{st['diverged_at_sample']} (line {st['diverged_at_line']})")
            elif st["fit_percent"] is None:
                failures.append(f"{ex.source}: {name}: {_label(kind, H)} has no fit (nothing scored, or the "
                                "measurement is constant)")
            elif st["fit_percent"] < threshold:
                failures.append(f"{ex.source}: {name}: {_label(kind, H)} fit {_g(st['fit_percent'])} % "
                                f"< {_g(threshold)} %")
        if kind != "free_run":
            k = ex.free_run_diverged()
            if k is not None:
                failures.append(f"{ex.source}: the free run diverged at sample {k} (line {int(ex.data.lines[k])})")
    return failures


# -- plots ------------------------------------------------------------------------------------------


def _plot_compare(path: Path, name: str, j: int, experiments: Sequence[ValidationRun], H: int) -> None:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(8.0, 1.0 + 2.8 * len(experiments)), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(len(experiments), 1, squeeze=False)[:, 0]
    for ax, ex in zip(axes, experiments):
        d = ex.data
        x_axis = d.t if d.t is not None else np.arange(d.n_samples, dtype=np.float64)
        ax.plot(x_axis, np.where(d.valid[:, j], d.X[:, j], np.nan), color="0.15", lw=1.2, marker=".", ms=2.5,
                label="measured")
        styles = {"one_step": ("tab:red", "--"), "steps_ahead": ("tab:purple", "-."), "free_run": ("tab:green", "-")}
        for kind in KINDS:
            est = ex.estimates[kind][:, j].copy()
            est[:ex.first[kind]] = np.nan
            stop = int(ex.diverged[kind][j])
            if stop >= 0:  # a diverged prediction is drawn up to where it left the range, not beyond
                est[stop:] = np.nan
                ax.axvline(x_axis[stop], color=styles[kind][0], lw=0.8, ls=":",
                           label=f"{_label(kind, H)} diverged here")
            ax.plot(x_axis, est, color=styles[kind][0], ls=styles[kind][1], lw=1.0, label=_label(kind, H))
        free = ex.states[name]["free_run"]
        note = (f" (free run diverged at sample {free['diverged_at_sample']})" if free["diverged_at_sample"] is not None
                else f" (free-run fit {_g(free['fit_percent'])} %)" if free["fit_percent"] is not None else "")
        ax.set_title(f"{name}: {ex.source}{note}", fontsize="medium")
        ax.set_ylabel(name)
        ax.legend(loc="best", fontsize="small")
    axes[-1].set_xlabel("t" if experiments[-1].data.t is not None else "sample")
    atomic.save_figure(fig, path, dpi=100)


def _plot_residuals(path: Path, name: str, r: StateResiduals) -> None:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    tests = [("autocorrelation of the residual", r.whiteness, "white", "not white")] + \
        [(f"cross-correlation of {u} with the residual", t, f"independent of {u}", f"correlated with {u}")
         for u, t in r.independence.items()]
    fig = Figure(figsize=(8.0, 0.6 + 2.4 * len(tests)), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(len(tests), 1, squeeze=False)[:, 0]
    for ax, (title, t, good, bad) in zip(axes, tests):
        ax.axhspan(-t.bound, t.bound, color="tab:blue", alpha=0.15, lw=0, label=f"{_LEVEL} bound")
        values = np.nan_to_num(t.values, nan=0.0)
        ax.vlines(t.lags, 0.0, values, color="0.2", lw=1.2)
        ax.plot(t.lags, values, "o", color="0.2", ms=3)
        ax.axhline(0.0, color="0.6", lw=0.6)
        ax.set_title(f"{name}: {title}: {t.outside} of {t.tested} lags outside, {_verdict_text(t, good, bad)}",
                     fontsize="medium")
        ax.set_ylabel("normalised")
        ax.legend(loc="upper right", fontsize="small")
    axes[-1].set_xlabel("lag (samples)")
    atomic.save_figure(fig, path, dpi=100)


# -- the command ------------------------------------------------------------------------------------


def run(args: argparse.Namespace) -> int:
    H = _count_option("--steps-ahead", args.steps_ahead)
    L = _count_option("--lags", args.lags)
    threshold = None if args.min_fit is None else real_option("--min-fit", args.min_fit)
    try:
        suffix = check_suffix(args.valid_suffix)
    except ValueError as exc:
        raise ValueError(f"--valid-suffix: {exc}") from None
    config_source = args.config
    cf = load_named(config_source)
    dtype = args.dtype or cf.config.dtype
    cfg = cf.config if dtype == cf.config.dtype else cf.config.replace(dtype=dtype)
    D = cfg.max_delay
    K = D + 1
    out = _output_dir(args.out, args.data[0])
    plots = [] if args.no_plots else [out / f"{name}_{what}.png" for name in cf.state_names
                                      for what in ("compare", "residuals")]
    written = [out / "validation.json", out / "report.txt", *plots]
    _refuse_overwriting_inputs([*written, out / atomic.MARKER],
                               [("the config file", config_source), *(("the data file", s) for s in args.data)])

    experiments: list[ValidationRun] = []
    for source in args.data:
        data = read_data(source, cf, valid_suffix=suffix, config_source=config_source)
        T = data.n_samples
        if T < K + 2:
            raise ValueError(f"{source}: {_plural(T, 'data row')}, too short for the config's window: its deepest tap "
                             f"delay is {D}, so scoring starts at sample {K} and needs at least {K + 2} rows")
        if K + H - 1 >= T:
            raise ValueError(f"--steps-ahead {H}: too long for {source}: {_plural(T, 'data row')}, and the first "
                             f"{H}-step prediction from measured samples is at sample {K + H - 1}")
        experiments.append(_experiment(cfg, cf, data, source, config_source, K, H))
    res = _residuals(experiments, cf, K, D, L)

    lines = _report_lines(experiments, cf, config_source, dtype, K, D, H, L, res)
    failures: list[str] = []
    if threshold is not None:
        failures = _min_fit_failures(experiments, cf, args.fit_kind, threshold, H)
        lines += ["", f"verdict (--min-fit {_g(threshold)} % on the {_label(args.fit_kind, H)} fit"
                      f"{'' if args.fit_kind == 'free_run' else ', and no free run diverged'}): "
                      + ("FAIL" if failures else "PASS")]
        lines += [f"  {f}" for f in failures]
        if not failures:
            lines.append(f"  every state's {_label(args.fit_kind, H)} fit is >= {_g(threshold)} % in every file")
    white = all(r.whiteness.passed is not False for r in res.values())
    independent = all(t.passed is not False for r in res.values() for t in r.independence.values())
    lines += ["", "residuals: " + ("white" if white else "not white (see above)") +
              ("" if not cf.input_names else ", " + ("independent of the inputs" if independent
                                                     else "correlated with an input (see above)"))]
    report = {
        "format": "pyrhonn-validate",
        "version": 1,
        "config": config_source,
        "dtype": dtype,
        "learning": False,
        "max_delay": D,
        "first_sample": K,
        "steps_ahead": H,
        "lags": L,
        "valid_suffix": suffix,
        "definitions": {
            "fit_percent": "100 (1 - ||x - xhat|| / ||x - mean(x)||) over the valid targets scored (MATLAB's "
                           "NRMSE fit) = 100 (1 - rrse)",
            "rmse, rrse": "as pyrhonn.metrics, over the valid targets scored",
            "one_step": f"xhat(k | k-1) from measured samples; scored from sample {K}",
            "steps_ahead": f"xhat(k | k-{H}), own predictions for {H - 1} steps; scored from sample {K + H - 1}",
            "free_run": f"the parallel model from sample {K}, fed its own predictions and the measured inputs; "
                        f"scored from sample {K}",
            "diverged": "the first sample (from the first scored) where the prediction is not finite or beyond the "
                        "file's measured range of the state widened by its span on both sides; its figures are null",
            "residuals": "one-step residuals x(k) - xhat(k | k-1), pooled over the files: valid targets from sample "
                         f"{K} on whose prediction read measured samples only (every state valid in the "
                         f"{_plural(D + 1, 'row')} before), in contiguous stretches (a gap or a file boundary ends one; no product spans "
                         "two); normalised biased correlation estimates (pyrhonn.residuals)",
            "bound": f"+-{Z_99}/sqrt(N): the {_LEVEL} confidence bound of each lag under the null hypothesis "
                     "that the residuals are white and independent of the inputs",
            "allowed": "the most lags outside the bound that chance gives at 0.5 % (P(Binomial(tested, 0.01) > "
                       "allowed) <= 0.005); more reject the null hypothesis",
            "peak_bound": "the family-wise (Bonferroni) bound Phi^-1(1 - 0.005 / (2 tested)) / sqrt(N); the largest "
                          "|correlation| (peak, at peak_lag) beyond it rejects the null hypothesis",
            "white, independent": "neither rule rejects (null: a constant series, no verdict); a white residual is "
                                  "rejected at most 1 % of the time",
        },
        "experiments": [
            {"data": ex.source, "samples": ex.data.n_samples, "first_line": int(ex.data.lines[K]),
             "ignored_columns": list(ex.data.ignored),
             "free_run_diverged_at_sample": ex.free_run_diverged(),
             "states": ex.states}
            for ex in experiments],
        "residuals": {
            "confidence": CONFIDENCE, "z": Z_99,
            "states": {name: {"usable": r.usable, "stretches": r.whiteness.stretches,
                              "autocorrelation": _test_json(r.whiteness, "white"),
                              "cross_correlation": {u: _test_json(t, "independent")
                                                    for u, t in r.independence.items()}}
                       for name, r in res.items()},
            "white": white, "independent": independent,
        },
        "verdict": {"min_fit": threshold, "fit_kind": args.fit_kind,
                    "passed": None if threshold is None else not failures, "failures": failures},
    }
    text = "\n".join(lines) + "\n"
    with atomic.output_folder(out, "pyrhonn validate"):  # marked INCOMPLETE until every file is in place
        atomic.write_text(out / "validation.json", json.dumps(report, indent=2) + "\n")
        atomic.write_text(out / "report.txt", text)
        for j, name in enumerate(cf.state_names):
            if not args.no_plots:
                _plot_compare(out / f"{name}_compare.png", name, j, experiments, H)
                _plot_residuals(out / f"{name}_residuals.png", name, res[name])
    print(text, end="")
    print("wrote " + ", ".join(str(p) for p in written))
    return 1 if failures else 0
