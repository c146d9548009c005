"""``pyrhonn identify``: run an identifier on the user's own data (a CSV file or a bus recording).

``pyrhonn identify data.csv --config cfg.toml [--out DIR] [--dtype float32|float64]
[--valid-suffix _valid] [--warmup N] [--free-run-from K] [--steps-ahead H] [--no-plots]``

``pyrhonn identify --can-log RUN.{blf,asc,log,mf4} --dbc FILE --config cfg.toml [...]`` reads the states
and inputs from a CAN log instead (:mod:`pyrhonn.cli.bus_input`, :mod:`pyrhonn.buslog`), runs and
writes the same outputs, plus ``samples.csv``, the aligned samples in the CSV format.

Input file
----------
The format of :mod:`pyrhonn.datafile` (a header row naming the columns by
the config's ``state_names`` and ``input_names``, optional ``t`` and
``<state><suffix>`` validity columns); every defect is reported with its
line number and exit code 2. A separator ``;`` or tab, decimal commas and a
unit row are read too (``--csv-sep``, ``--decimal``). A file ``DATA.mf4`` is a
signal MDF4 (:mod:`pyrhonn.mdfsignals`: channels by name, resampled on the
identifier's period by a zero-order hold).

Gaps (:mod:`pyrhonn.gaps`): samples that never arrived (a ``lost`` column,
or a bus log's lost frames) split the record into segments as the firmware
does; ``metrics.json``'s ``gaps`` counts them and lists the segments.

Validation (:mod:`pyrhonn.simulation`)
--------------------------------------
Without options the identifier learns online over the whole file and is
scored one step ahead (series-parallel). ``--free-run-from K`` splits the
file: the first K data rows (0-based sample K on) are learnt; from sample K
on the weights are frozen and the network also runs free (the parallel
model: fed its own predictions, the measured inputs only), and every
figure is scored on samples >= K, the part the network has not learnt
from. ``--steps-ahead H`` adds the H-step-ahead prediction x̂(k | k-H) of
every sample (own outputs for H-1 steps, then back to the measurements).

Outputs (in ``--out``, default ``identify-<file stem>``)
--------------------------------------------------------
- ``predictions.csv``: one row per input line, aligned with the
  measurements (row k estimates sample k; ``Identifier.run`` returns the
  same values one row earlier, row t = x̂(t+1)): ``line`` (its line number
  in the data file), ``t`` (if given), and per state ``<name>_hat``, x̂(k),
  the one-step-ahead prediction of this line made from the lines before it
  (line 2 holds the config's x0), and ``<name>_err`` = measured − x̂(k),
  empty where the measurement is invalid and on the first line; with
  ``--free-run-from``, ``<name>_free_run`` (empty before sample K), with
  ``--steps-ahead H``, ``<name>_ahead<H>`` (empty in the first H rows and
  where a branch diverged).
- ``metrics.json`` (version 2): per state and per kind of prediction
  (``one_step``; with a split also ``one_step_learning`` over the learnt
  part and ``free_run``; ``steps_ahead``) the RMSE and the RRSE
  (:mod:`pyrhonn.metrics`) over valid targets only, after dropping the
  first ``--warmup`` pairs, with the number scored; one step also the
  absolute deviation. ``states`` repeats ``one_step`` (the version 1
  layout). Also the prediction x̂(T) beyond the last line, where the free
  run diverged (if it did), and the run settings.
- ``<state>.png`` per state (unless ``--no-plots``, which removes an earlier
  run's ``<state>.png`` for these states): measured vs identified
  (one step, free run, H steps ahead), and the one-step error, against
  ``t`` (or the sample index).

Each file is written to a temporary file and renamed into place, and the
folder holds a file ``INCOMPLETE`` from before the first output until after
the last (:mod:`pyrhonn.atomic`): a run that is interrupted, even by
``kill -9``, leaves every file whole (the previous run's or this one's) and,
unless it finished, the ``INCOMPLETE`` marker saying the set may be mixed.

The identifier runs in the C core in ``--dtype`` (default: the config's
dtype); measurements are read as float64 and rounded to float32 only when
running float32. Metrics compare the float64 measurements of the file with
the predictions.
"""
from __future__ import annotations

import argparse
import csv
import json
import os
import re
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from .. import atomic
from ..config import DTYPES, IdentifierConfig
from ..configfile import ConfigFile, load_named
from ..datafile import (ROWS_AT_ONCE, SEPARATORS, Data, TIME_COLUMN, check_suffix, decimal_cells, read_data,
                        write_data)
from ..gaps import Segments, segments_of, simulate_segments
from ..mdfsignals import METHOD, MdfSignals, read_signal_mdf
from ..identifier import Identifier, IdentifierError
from ..metrics import absolute_deviation, json_value
from ..residuals import departure, divergence_range
from ..simulation import Simulation, scores, simulate
from . import bus_input
from .options import real_option, units_option

__all__ = ["register", "run"]

def _nonnegative_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number of samples, got {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {value}")
    return value


def _positive_int(text: str) -> int:
    value = _nonnegative_int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {value}")
    return value


def _suffix(text: str) -> str:
    try:
        return check_suffix(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "identify", help="identify a plant from a CSV file of states and inputs (or a CAN log)",
        description="Run the RHONN identifier (C core) on a CSV file whose columns are named by the config; "
                    "write one-step-ahead predictions, metrics (RMSE, absolute deviation) and plots.")
    p.add_argument("data", metavar="DATA.csv", nargs="?",
                   help="the measurements: a CSV file (header row, then one line per sample), a signal MDF4 "
                        "file of named channels (.mf4), or none with --can-log")
    p.add_argument("--config", required=True, metavar="CFG",
                   help="identifier config: a .toml file (see pyrhonn show-config) or a shipped config name")
    p.add_argument("--out", metavar="DIR", help="output folder (default: identify-<data file stem>)")
    p.add_argument("--dtype", choices=DTYPES, help="build of the C core to run (default: the config's dtype)")
    p.add_argument("--valid-suffix", type=_suffix, default="_valid", metavar="SUFFIX",
                   help="validity columns are named <state><SUFFIX> (default: _valid)")
    p.add_argument("--warmup", type=_nonnegative_int, default=0, metavar="N",
                   help="leave the first N one-step-ahead pairs out of the metrics (default 0)")
    p.add_argument("--free-run-from", type=_nonnegative_int, metavar="K",
                   help="learn samples 0..K-1, then freeze the weights and score samples >= K one step ahead "
                        "and in free run (the network fed its own predictions)")
    p.add_argument("--steps-ahead", type=_positive_int, metavar="H",
                   help="also score the H-step-ahead prediction of every sample (own outputs for H-1 steps)")
    p.add_argument("--no-plots", action="store_true", help="do not write the PNG plots")
    p.add_argument("--units", type=units_option, default={}, metavar="NAME=UNIT[,NAME=UNIT...]",
                   help="units of the states (and of the time column t) for the plots' axes, e.g. "
                        "q_m=m,v=m/s,t=s; over the CSV's unit row, if it has one; a state without one is labelled "
                        "'(no unit given)'")
    p.add_argument("--csv-sep", type=_separator, metavar="SEP",
                   help="the CSV's column separator: ',', ';' or tab (default: the one that splits the header into "
                        "the config's names)")
    p.add_argument("--decimal", choices=(".", ","), metavar="MARK",
                   help="the CSV's decimal mark (default: '.', or ',' when the file is not comma-separated and its "
                        "numbers have decimal commas)")
    p.add_argument("--channel", action="append", default=[], metavar="NAME=CHANNEL",
                   help="with a signal MDF4 DATA.mf4: the channel of state or input NAME (default: the channel "
                        "named NAME); repeat for each. The channels are resampled on --sample-period (default: "
                        "the first state's median interval) by a zero-order hold of the latest sample; a state is "
                        "valid only where its channel has a new sample in the period before")
    bus_input.add_options(p)
    p.set_defaults(func=run)


def _separator(text: str) -> str:
    sep = {"tab": "\t", "\\t": "\t"}.get(text, text)
    if sep not in SEPARATORS:
        raise argparse.ArgumentTypeError(f"expected ',', ';' or tab, got {text!r}")
    return sep


# -- running ----------------------------------------------------------------------------------------


def _signal_mdf(args: argparse.Namespace, cf: ConfigFile) -> tuple[Data, MdfSignals]:
    """A signal MDF4 DATA.mf4 on the identifier's grid, as the arrays a CSV gives (lines: samples.csv's)."""
    if args.csv_sep is not None or args.decimal is not None:
        raise ValueError(f"{'--csv-sep' if args.csv_sep is not None else '--decimal'}: only for a CSV file")
    names = (*cf.state_names, *cf.input_names)
    channels: dict[str, str] = {}
    for text in args.channel:
        name, sep, channel = text.partition("=")
        if not sep or not channel.strip():
            raise ValueError(f"--channel {text}: expected NAME=CHANNEL")
        if name.strip() not in names:
            raise ValueError(f"--channel {text}: {name.strip()!r} is not one of the states and inputs of "
                             f"{args.config} ({', '.join(names)})")
        channels[name.strip()] = channel.strip()
    period = None if args.sample_period is None else real_option("--sample-period", args.sample_period,
                                                                   positive=True)
    m = read_signal_mdf(args.data, cf.state_names, cf.input_names, period=period, channels=channels,
                        partial=bool(args.partial_log))
    K = m.t.shape[0]
    data = Data(X=m.X, U=m.U, valid=m.valid, t=m.t, lines=np.arange(2, K + 2, dtype=np.int64), ignored=(),
                units=m.units)
    return data, m


def _run_identifier(cfg: IdentifierConfig, data: Data, cf: ConfigFile, source: str, config_source: str,
                    free_run_from: int | None, steps: int | None,
                    segs: Segments | None) -> tuple[Simulation, np.ndarray | None, np.ndarray | None]:
    """The run's one-step (and free-run, k-step) predictions, aligned with the data rows, and (with
    gaps) the rows the free run and the k-step predictions reach."""
    try:
        ident = Identifier(cfg)
    except ValueError as exc:
        raise ValueError(f"{config_source}: {exc}") from None
    X, U = data.in_dtype(cfg.dtype, cf.state_names, cf.input_names, source)
    try:
        if segs is not None:
            return simulate_segments(ident, X, U, data.valid, segs, free_run_from=free_run_from, steps=steps)
        return simulate(ident, X, U, data.valid, free_run_from=free_run_from, steps=steps), None, None
    except IdentifierError as exc:
        found = re.search(r"at sample (\d+)", str(exc))
        where = f"line {int(data.lines[int(found.group(1))])}: " if found else ""
        raise ValueError(f"{source}: {where}the identifier stopped: {exc}") from None


def _scored(data: Data, first: int, stop: int | None = None, rows: np.ndarray | None = None) -> np.ndarray:
    """Bool (T, n): the valid targets among data rows first..stop-1 (and ``rows``, (T,) bool, if given)."""
    mask = data.valid.copy()
    mask[:first] = False
    if stop is not None:
        mask[stop:] = False
    if rows is not None:
        mask &= rows[:, None]
    return mask


def _section(data: Data, cf: ConfigFile, estimate: np.ndarray, mask: np.ndarray, definition: str,
             with_deviation: bool = False) -> dict[str, Any]:
    sc = scores(data.X, estimate.astype(np.float64), mask)
    states: dict[str, Any] = {}
    for j, name in enumerate(cf.state_names):
        entry: dict[str, Any] = {"rmse": json_value(sc.rmse[j]), "rrse": json_value(sc.rrse[j]),
                                 "scored": int(sc.scored[j])}
        if sc.missing[j]:
            entry["missing"] = int(sc.missing[j])
        if with_deviation:
            rows = mask[:, j]
            entry["absolute_deviation"] = (json_value(absolute_deviation(
                data.X[rows, j][:, None], estimate[rows, j][:, None].astype(np.float64))[0])
                if rows.any() and not sc.missing[j] else None)
            entry["invalid_samples"] = int((~data.valid[:, j]).sum())
        states[name] = entry
    return {"definition": definition, "states": states}


def _shown(v: float | str | None, spec: str = ".6g") -> str:
    return "-" if v is None else str(v) if isinstance(v, str) else format(v, spec)


def _count(k: int, noun: str) -> str:
    return f"{k} {noun}{'' if k == 1 else 's'}"


def _write_predictions(path: Path, data: Data, cf: ConfigFile, sim: Simulation, errors: np.ndarray) -> None:
    """predictions.csv; ``errors`` (T,) bool: the rows whose prediction is a one-step prediction of
    that row's sample (not row 0, nor the first row of a segment after a gap)."""
    T = data.n_samples
    hat = sim.one_step.astype(np.float64)
    err = data.X - hat
    extra: list[tuple[str, np.ndarray]] = []
    if sim.free_run is not None:
        extra.append(("free_run", sim.free_run.astype(np.float64)))
    if sim.ahead is not None:
        extra.append((f"ahead{sim.steps}", sim.ahead.astype(np.float64)))
    header = ["line"] + ([TIME_COLUMN] if data.t is not None else [])
    for name in cf.state_names:
        header += [f"{name}_hat", f"{name}_err"] + [f"{name}_{kind}" for kind, _ in extra]
    with atomic.replacing(path, "w", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(header)
        for a in range(0, T, ROWS_AT_ONCE):  # column by column, a block of rows at a time
            rows = slice(a, min(a + ROWS_AT_ONCE, T))
            columns: list[list[Any]] = [data.lines[rows].tolist()]
            if data.t is not None:
                columns.append(decimal_cells(data.t[rows]))
            for j in range(len(cf.state_names)):
                columns.append(decimal_cells(hat[rows, j]))
                columns.append(decimal_cells(err[rows, j], errors[rows] & data.valid[rows, j]))
                columns += [decimal_cells(values[rows, j]) for _, values in extra]
            w.writerows(zip(*columns))


NOT_VALID_LABEL = "not valid (not learnt; predicted from its own outputs)"  #: legend entry of the shaded samples


def _plot(path: Path, name: str, data: Data, sim: Simulation, j: int, warmup: int,
          units: dict[str, str]) -> None:
    """Measured and identified state j over the error: every y axis carries the state's unit
    (``--units``), and the samples whose measurement was not valid are shaded, in the legend."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    x_axis = data.t if data.t is not None else np.arange(data.n_samples, dtype=np.float64)
    measured = np.where(data.valid[:, j], data.X[:, j], np.nan)
    identified = sim.one_step[1:, j].astype(np.float64)
    error = measured[1:] - identified
    fig = Figure(figsize=(8.0, 5.0), layout="constrained")
    FigureCanvasAgg(fig)
    top, bottom = fig.subplots(2, 1, sharex=True, height_ratios=[3, 1.4])
    top.plot(x_axis, measured, color="0.15", lw=1.2, marker=".", ms=2.5, label=f"{name} (measured)")
    top.plot(x_axis[1:], identified, color="tab:red", lw=1.0, ls="--", label=f"{name} identified (one step ahead)")
    if sim.ahead is not None:
        top.plot(x_axis, sim.ahead[:, j].astype(np.float64), color="tab:purple", lw=0.9, ls="-.",
                 label=f"{name} identified ({sim.steps} steps ahead)")
    if sim.free_run is not None and sim.free_run_from is not None:
        top.plot(x_axis, sim.free_run[:, j].astype(np.float64), color="tab:green", lw=1.1,
                 label=f"{name} free run (weights frozen, own outputs)")
        for ax in (top, bottom):
            ax.axvline(x_axis[sim.free_run_from], color="tab:green", lw=0.8, ls=":",
                       label="weights frozen from here" if ax is top else None)
    unit = f"[{units[name]}]" if name in units else "(no unit given)"
    top.set_ylabel(f"{name} {unit}")
    top.set_title(f"{name}: real vs identified")
    bottom.plot(x_axis[1:], error, color="tab:blue", lw=0.9)
    bottom.axhline(0.0, color="0.6", lw=0.6)
    bottom.set_ylabel(f"error {unit}")
    bottom.set_xlabel((f"t [{units['t']}]" if "t" in units else "t") if data.t is not None else "sample")
    bad = ~data.valid[:, j]
    if bad.any():  # runs of not-valid samples, shaded on both axes, one legend entry
        edges = np.flatnonzero(np.diff(np.r_[0, bad.astype(np.int8), 0]))
        for n, (a, b) in enumerate(zip(edges[::2], edges[1::2])):
            for ax in (top, bottom):
                ax.axvspan(x_axis[a], x_axis[min(b, data.n_samples - 1)], color="tab:orange", alpha=0.18, lw=0,
                           zorder=0, label=NOT_VALID_LABEL if ax is top and n == 0 else None)
    if warmup:
        for ax in (top, bottom):
            ax.axvspan(x_axis[0], x_axis[min(warmup, data.n_samples - 1)], color="0.9", lw=0, zorder=0,
                       label="warm-up (not scored)" if ax is top else None)
    top.legend(loc="best", fontsize="small")
    atomic.save_figure(fig, path, dpi=100)


def _output_dir(out: str | None, source: str) -> Path:
    if out is None:
        return Path(f"identify-{Path(source).stem}")
    if not out.strip():
        raise ValueError("--out: empty; give a folder (default: identify-<data file stem>)")
    return Path(out)


def _refuse_overwriting_inputs(outputs: Sequence[Path], inputs: dict[str, str]) -> None:
    """An output that is one of the inputs (``--out`` pointed at the data's own
    folder, say) would replace the measurements with their predictions."""
    for path in outputs:
        for what, src in inputs.items():
            if path.exists() and Path(src).exists() and os.path.samefile(path, src):
                raise ValueError(f"--out {path.parent}: would overwrite {what} {src} with its {path.name}; "
                                 "choose another folder")


def run(args: argparse.Namespace) -> int:
    cf = load_named(args.config)
    config_source = args.config
    bus_input.check_options(args)
    bus = bus_input.read(args, cf, config_source) if args.can_log is not None else None
    mdf = _signal_mdf(args, cf) if bus is None and Path(args.data).suffix.lower() == ".mf4" else None
    source = bus.source if bus else args.data
    if bus and (args.csv_sep is not None or args.decimal is not None):
        raise ValueError(f"{'--csv-sep' if args.csv_sep is not None else '--decimal'}: only for a CSV file, not with "
                         "--can-log")
    data = bus.data if bus else mdf[0] if mdf else read_data(source, cf, valid_suffix=args.valid_suffix,
                                                             config_source=config_source, sep=args.csv_sep,
                                                             decimal=args.decimal, allow_lost=True)
    units = {**{k: v for k, v in (data.units or {}).items() if k in cf.state_names or k == TIME_COLUMN},
             **args.units}  # --units over the file's unit row
    T = data.n_samples
    if T < 2:
        raise ValueError(f"{source}: line {int(data.lines[0])}: only one data row; one-step-ahead "
                         "identification needs at least two")
    if args.warmup >= T - 1:
        raise ValueError(f"--warmup {args.warmup}: leaves nothing to score ({T} data rows give {T - 1} "
                         "one-step-ahead pairs)")
    unknown = sorted(set(args.units) - set(cf.state_names) - {"t"})
    if unknown:
        raise ValueError(f"--units: {', '.join(unknown)}: not a state of the config (states: "
                         f"{', '.join(cf.state_names)}; t for time)")
    out = _output_dir(args.out, source)
    plots = [] if args.no_plots else [out / f"{name}.png" for name in cf.state_names]
    samples = [out / bus_input.SAMPLES] if bus or mdf else []  # the aligned or resampled samples
    written = [out / "predictions.csv", out / "metrics.json"] + plots + samples
    _refuse_overwriting_inputs([*written, out / atomic.MARKER],
                               {"the data file": source, "the config file": config_source,
                                **({"the DBC": bus.dbc} if bus else {})})
    dtype = args.dtype or cf.config.dtype
    cfg = cf.config if dtype == cf.config.dtype else cf.config.replace(dtype=dtype)
    K = args.free_run_from
    if K is not None and K >= T:
        raise ValueError(f"--free-run-from {K}: beyond the data ({T} rows, samples 0..{T - 1})")
    if K is not None and args.warmup + 1 >= T:
        raise ValueError(f"--warmup {args.warmup}: leaves nothing to score")
    if args.steps_ahead is not None and args.steps_ahead >= T:
        raise ValueError(f"--steps-ahead {args.steps_ahead}: needs more than {args.steps_ahead} data rows, "
                         f"the file has {T}")
    segs = segments_of(data.lost) if data.lost is not None and data.lost.any() else None
    sim, free_rows, ahead_rows = _run_identifier(cfg, data, cf, source, config_source, K, args.steps_ahead, segs)
    # one-step rows: stepped, and not the first of a segment (its x̂ was made for a sample before the gap)
    one_rows = None if segs is None else segs.stepped & ~segs.starts()
    if segs is not None and free_rows is not None and one_rows is not None:
        free_rows &= one_rows | (np.arange(T) == K)
    first = args.warmup + 1  # row 0 holds x0, not a prediction; --warmup drops that many pairs more
    split = max(first, K) if K is not None else first
    weights = "online" if K is None else f"frozen from sample {K}"
    sections: dict[str, Any] = {
        "one_step": _section(data, cf, sim.one_step, _scored(data, split, rows=one_rows),
                             f"one step ahead: x̂(k) made at sample k-1 from measured values, against the "
                             f"measurement of sample k, valid targets k >= {split}; weights {weights}",
                             with_deviation=True)}
    if K is not None:
        sections["one_step_learning"] = _section(
            data, cf, sim.one_step, _scored(data, first, K, rows=one_rows),
            f"one step ahead over the learnt samples {first}..{K - 1}, weights learning online",
            with_deviation=True)
        assert sim.free_run is not None
        sections["free_run"] = _section(
            data, cf, sim.free_run, _scored(data, split, rows=free_rows),
            f"free run (parallel model): weights frozen from sample {K}, the network fed its own predictions "
            f"and the measured inputs, against the measurements of samples k >= {split}")
        sections["free_run"]["from_sample"] = K
        sections["free_run"]["from_line"] = int(data.lines[K])
        sections["free_run"]["diverged_at_line"] = (None if sim.free_run_diverged is None
                                                    else int(data.lines[sim.free_run_diverged]))
        low, high = divergence_range(data.X, data.valid)
        rows = np.zeros(T, dtype=bool)
        rows[K:] = True
        if free_rows is not None:
            rows &= free_rows
        left = departure(sim.free_run.astype(np.float64), rows, low, high)
        gone = [int(k) for k in left if k >= 0]
        left_range = min(gone) if gone else None
        sections["free_run"]["left_range_at_line"] = None if left_range is None else int(data.lines[left_range])
        sections["free_run"]["range"] = ("a free run leaves the data's range at the first sample outside "
                                         "[min - span, max + span] of a state's valid measurements in the file")
    if args.steps_ahead is not None:
        assert sim.ahead is not None
        H = args.steps_ahead
        sections["steps_ahead"] = _section(
            data, cf, sim.ahead, _scored(data, max(split, H), rows=ahead_rows),
            f"{H} steps ahead: x̂(k | k-{H}), the network as after learning sample k-{H} fed its own "
            f"predictions for {H - 1} steps, against the measurements of samples k >= {max(split, H)}; "
            f"weights {weights}")
        sections["steps_ahead"]["steps"] = H

    report = {
        "format": "pyrhonn-identify-metrics",
        "version": 2,
        "data": str(source),
        "config": config_source,
        "dtype": dtype,
        "samples": T,
        "pairs": T - 1,
        "warmup": args.warmup,
        "free_run_from": K,
        "ahead_steps": args.steps_ahead,
        "valid_suffix": args.valid_suffix,
        "ignored_columns": list(data.ignored),
        **({"units": data.units} if data.units else {}),
        "definition": "rmse, rrse (root relative squared error) and absolute_deviation (mean |e - mean e|) as "
                      "in pyrhonn.metrics; 'states' repeats one_step.states",
        "states": sections["one_step"]["states"],
        **sections,
        "next_prediction": {name: float(sim.next_prediction[j]) for j, name in enumerate(cf.state_names)},
        **({"bus": bus.report()} if bus else {}),
        **({"gaps": segs.report(data.t, data.lines, data.valid, tuple(cf.state_names))} if segs else {}),
        **({"mdf": mdf[1].report()} if mdf else {}),
    }
    with atomic.output_folder(out, "pyrhonn identify"):  # marked INCOMPLETE until every file is in place
        if bus or mdf:
            write_data(out / bus_input.SAMPLES, data, cf, valid_suffix=args.valid_suffix)
        errors = np.arange(T) > 0 if one_rows is None else one_rows
        _write_predictions(out / "predictions.csv", data, cf, sim, errors)
        atomic.write_text(out / "metrics.json", json.dumps(report, indent=2) + "\n")
        for j, path in enumerate(plots):
            _plot(path, cf.state_names[j], data, sim, j, args.warmup, units)
        for stale in [] if plots else [out / f"{name}.png" for name in cf.state_names]:
            stale.unlink(missing_ok=True)  # an earlier run's plot would pass for this run's

    print(f"identified {source}: {T} samples, {_count(cfg.n_states, 'state')}, {_count(cfg.n_inputs, 'input')}, "
          f"config {config_source}, {dtype}")
    if data.ignored:
        print("ignored columns: " + ", ".join(data.ignored))
    for line in bus.summary() if bus else []:
        print(line)
    if mdf:
        m = mdf[1]
        if m.incomplete:
            print(f"warning: {source} is incomplete, read partially (--partial-log): {m.incomplete}")
        print(f"mdf: {T} samples every {m.period:.6g} s ({m.period_source}); resampled by {METHOD}")
        for name, ch in m.channels.items():
            if ch.get("not_valid"):
                print(f"  {name} ({ch['channel']}): {ch['not_valid']} samples not valid (no new sample)")
    if segs is not None:
        print(f"gaps: {segs.lost} lost samples in {_count(len(segs.gaps), 'gap')}; {len(segs.gaps)} not stepped after "
              f"them, {_count(segs.restarts, 'restart')}; {_count(len(segs.bounds), 'segment')} "
              f"({', '.join(str(b - a) for a, b in segs.bounds[:8])}{' ...' if len(segs.bounds) > 8 else ''} samples)")
    kinds = [("one_step", "one step")] + ([("free_run", "free run")] if K is not None else []) + \
        ([("steps_ahead", f"{args.steps_ahead} steps ahead")] if args.steps_ahead is not None else [])
    scope = f"samples >= {K}, weights frozen" if K is not None else "weights learning online"
    print(f"errors over valid targets ({scope}), warmup {args.warmup}:")
    width = max(5, *(len(s) for s in cf.state_names))
    print(f"  {'state':<{width}}  {'scored':>7}" + "".join(f"  {label + ' RMSE':>18}  {'RRSE':>8}" for _, label in kinds))
    for name in cf.state_names:
        row = f"  {name:<{width}}  {sections['one_step']['states'][name]['scored']:>7}"
        for kind, _ in kinds:
            st = sections[kind]["states"][name]
            row += f"  {_shown(st['rmse']):>18}  {_shown(st['rrse'], '.4g'):>8}"
        print(row)
    if K is not None and sim.free_run_diverged is not None:
        print(f"the free run diverged at line {int(data.lines[sim.free_run_diverged])} (its prediction was not "
              f"finite in {dtype}): its errors are inf")
    elif K is not None and sections["free_run"]["left_range_at_line"] is not None:
        print(f"the free run left the data's range at line {sections['free_run']['left_range_at_line']} (beyond "
              "each state's measured range widened by its span): a model that does not simulate")
    print("wrote " + ", ".join(str(p) for p in written))
    return 0
