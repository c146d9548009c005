"""``pyrhonn select``: choose the identifier's terms, delays and weights from data.

``pyrhonn select data.csv [more.csv ...] --states x1,x2 [--inputs u1] --out cfg.toml
[--validate val.csv ...] [--fit-rows A:B [--validate-rest]] [--search auto|fixed] [--tie F] [--no-refine]
[--max-delay D] [--delay-step S] [--degree G] [--factors S,x,u,1]
[--activation bipolar,logistic] [--beta 0.5,1,2] [--criterion ebic|bic|aic|holdout]
[--holdout F] [--max-terms L] [--p0 V] [--q V] [--r V] [--dtype float64|float32]
[--report FILE] [--json FILE] [--valid-suffix _valid]``

Reads the data files of ``pyrhonn identify`` (:mod:`pyrhonn.datafile`), with
the columns named by ``--states`` and ``--inputs``. Every DATA file is an
estimation experiment (merged: no regressor reads across two files); with
``--fit-rows A:B`` only samples A..B-1 of each fit, and ``--validate-rest``
makes the samples outside them validation experiments. A file longer than
``--max-fit-rows`` (default 100,000) fits on 10 evenly spaced windows of it,
read a chunk at a time and printed with the reason (and in ``--json``'s
``long_records``); the structure chosen is then validated, weights frozen,
on every row of the record, streamed. ``--validate`` names
validation recordings: they never fit a weight.

By default (``--search auto``, and whenever no candidate-space option is
given) :func:`pyrhonn.search.search` chooses the candidate space itself:
input dead times, a grid of factor kinds, degrees and delays, each space
ranked by its free run on the validation experiments (or on blocked
cross-validation folds of the estimation data without them), weights refined
on the free-run and one-step errors (``--no-refine``: least squares). Any candidate-space
option (``--max-delay``, ``--degree``, ``--factors``, ...) fixes the space
instead (``--search fixed``) and runs :func:`pyrhonn.structure.select` on it.
Writes the config (``--out``, the TOML
format of :mod:`pyrhonn.configfile`, which ``identify``, ``tune`` and
``export`` read) and prints the report: per neuron the terms in the order
chosen with their error reduction ratios, and the estimated delay of each
state; which rows fitted and which validated; then the selected model
checked with its weights frozen (on the validation experiments, else on the
fitting data): one step ahead and in free run (the network
fed its own predictions from the first sample its taps can read on), RMSE
and RRSE per state (:mod:`pyrhonn.simulation`). Every file is replaced whole
(:mod:`pyrhonn.atomic`).
"""
from __future__ import annotations

import argparse
import json
from contextlib import contextmanager
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Iterator

import numpy as np

from .. import atomic
from ..config import DTYPES, Activation, Factor, IdentifierConfig
from ..configfile import ConfigFile, dumps
from ..datafile import Data, DataReader, check_suffix, concatenate, read_data
from ..identifier import Identifier, IdentifierError
from ..metrics import json_value
from ..simulation import Scores, scores, simulate
from ..streamscores import RunningScores
from ..experiments import Experiment, merge
from ..refine import DataRange
from ..search import TIE, SearchResult, Validation, search, validate
from ..structure import FACTOR_NAMES, CandidateSpace, Criterion, Selection, check_data, select
from .options import real_option, row_range

__all__ = ["register", "run"]

_OPTIONS = {"max_delay": "--max-delay", "delay_step": "--delay-step", "degree": "--degree",
            "factors": "--factors", "input_max_delay": "--input-max-delay", "max_terms": "--max-terms",
            "holdout": "--holdout", "betas": "--beta", "activations": "--activation", "n_states": "--states", "n_inputs": "--inputs", "state_names": "--states",
            "input_names": "--inputs", "p0": "--p0", "q": "--q", "r": "--r", "input_min_delay": "--input-max-delay", "fraction": "--holdout"}


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "select", help="choose the identifier's terms and delays from data (forward orthogonal least squares)",
        description="Select each neuron's high-order terms and delays from a CSV file of states and inputs by "
                    "forward orthogonal least squares (error reduction ratio) on the one-step targets, and "
                    "write an identifier config that identify, tune and export accept.")
    p.add_argument("data", metavar="DATA.csv", nargs="+",
                   help="the estimation experiments (the format of pyrhonn identify); several are merged, "
                        "no regressor reading across two")
    p.add_argument("--states", required=True, metavar="NAMES", help="comma-separated state columns, in order")
    p.add_argument("--inputs", default="", metavar="NAMES", help="comma-separated input columns (default: none)")
    p.add_argument("--out", required=True, metavar="CFG.toml", help="the config file to write")
    p.add_argument("--validate", action="append", default=[], metavar="VAL.csv",
                   help="a validation experiment (repeatable): ranks the structures and scores the model, "
                        "never fits a weight")
    p.add_argument("--fit-rows", metavar="A:B",
                   help="only samples A..B-1 (0-based; A or B may be left out) of each DATA file fit")
    p.add_argument("--max-fit-rows", type=_budget, default=FIT_BUDGET, metavar="N",
                   help=f"a DATA file longer than N rows (without --fit-rows) fits on {WINDOWS} evenly spaced windows "
                        f"of N/{WINDOWS} rows, read a chunk at a time, and the structure chosen is then validated on "
                        f"every row of it, streamed (default {FIT_BUDGET}; 0: fit on every row)")
    p.add_argument("--validate-rest", action="store_true",
                   help="with --fit-rows: the samples outside A..B-1 are validation experiments")
    p.add_argument("--search", choices=("auto", "fixed"),
                   help="auto: choose the candidate space from data (the default unless a space option is "
                        "given); fixed: the space the options below describe")
    p.add_argument("--tie", metavar="FRACTION",
                   help="auto search: spaces whose free-run score is within this fraction of the best one's are "
                        f"tied with it, and the one-step error picks finalists among them (default {TIE:g})")
    p.add_argument("--no-refine", action="store_true",
                   help="auto search: keep the least-squares weights instead of refining them on the "
                        "free-run and one-step errors")
    space = p.add_argument_group("a fixed candidate space (any of these implies --search fixed)")
    space.add_argument("--max-delay", metavar="D", help="deepest state tap x(k-D) (default 0)")
    space.add_argument("--delay-step", metavar="S", help="state taps every S samples (default 1)")
    space.add_argument("--degree", metavar="G", help="products of up to G factors (default 2)")
    space.add_argument("--factors", metavar="KINDS",
                       help="factor kinds among S (activation of a state), x (raw state), u (input), 1 (bias); "
                            "default S,u,1")
    space.add_argument("--input-max-delay", metavar="D", help="input taps u(k-0..D) (default 0)")
    space.add_argument("--activation", metavar="NAMES", help="activations searched (default bipolar,logistic)")
    space.add_argument("--beta", metavar="VALUES", help="slopes of S searched (default 1)")
    p.add_argument("--criterion", default="ebic", choices=[c.value for c in Criterion],
                   help="where each neuron's term selection stops: extended BIC (default), BIC, AIC, or the "
                        "one-step error on held-out rows")
    p.add_argument("--holdout", metavar="F",
                   help="the fraction of each estimation experiment held out: by --criterion holdout "
                        "(default 0.2), and by the auto search's cross-validation folds when no validation "
                        "data is given (default 0.3)")
    p.add_argument("--max-terms", default="16", metavar="L", help="at most L terms per neuron (default 16)")
    p.add_argument("--p0", metavar="V", help="P0 of every neuron (default: from its fit)")
    p.add_argument("--q", metavar="V", help="Q of every neuron (default: from its fit)")
    p.add_argument("--r", metavar="V", help="R of every neuron (default: its residual variance)")
    p.add_argument("--dtype", choices=DTYPES, default="float64", help="dtype written to the config")
    p.add_argument("--report", metavar="FILE", help="also write the report (text) to FILE")
    p.add_argument("--json", metavar="FILE", help="also write the selection as JSON to FILE")
    p.add_argument("--valid-suffix", default="_valid", metavar="SUFFIX",
                   help="validity columns are named <state><SUFFIX> (default: _valid)")
    p.set_defaults(func=run)


#: the rows a long record fits on at most (--max-fit-rows), in WINDOWS evenly spaced windows
FIT_BUDGET = 100_000
WINDOWS = 10


def _budget(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number of rows, got {text!r}") from None
    if value != 0 and value < 2 * WINDOWS:
        raise argparse.ArgumentTypeError(f"expected 0 (no limit) or at least {2 * WINDOWS} rows, got {value}")
    return value


@dataclass(frozen=True)
class _Long:
    """A DATA file longer than the fitting budget: its rows, the windows that fitted and why."""

    path: str
    rows: int
    windows: tuple[tuple[int, int], ...]
    budget: int

    def why(self) -> str:
        return (f"{self.path}: {self.rows:,} rows, more than --max-fit-rows {self.budget:,}: fitted on "
                f"{len(self.windows)} evenly spaced windows of {self.windows[0][1] - self.windows[0][0]:,} rows "
                f"(rows {', '.join(f'{a}..{b - 1}' for a, b in self.windows)}), the structure then validated on "
                "every row, read a chunk at a time")

    def as_json(self) -> dict[str, object]:
        return {"file": self.path, "rows": self.rows, "budget": self.budget,
                "windows": [[a, b - 1] for a, b in self.windows],
                "why": f"the file has more rows than --max-fit-rows: {len(self.windows)} windows evenly spaced over "
                       "it (by its line count) fit, so that the fit sees the whole record's range of operation in "
                       "bounded memory and time; the model is then scored on every row"}


def _line_count(path: str) -> int:
    """The data rows of a CSV file by its line ends (the header left out; a unit row or blank lines
    make it an overestimate, which only places the windows)."""
    count, last = 0, b"\n"
    with open(path, "rb") as fh:  # read only
        for block in iter(lambda: fh.read(1 << 24), b""):
            count += block.count(b"\n")
            last = block[-1:]
    return max(count - (1 if last == b"\n" else 0), 0)


def _windows(path: str, names: ConfigFile, suffix: str, states: tuple[str, ...], inputs: tuple[str, ...],
             budget: int) -> tuple[list[Experiment], _Long | None, Data | None]:
    """The fitting windows of a file longer than ``budget`` rows, read a chunk at a time (None when it is
    not longer: the caller reads it whole)."""
    estimate = _line_count(path) if Path(path).is_file() else 0
    if not budget or estimate <= budget:
        return [], None, None
    size = budget // WINDOWS
    starts = sorted({int(a) for a in np.linspace(0, estimate - size, WINDOWS)})
    windows = [(a, a + size) for a in starts]
    parts: list[list[Data]] = [[] for _ in windows]
    reader = DataReader(path, names, valid_suffix=suffix, config_source="--states/--inputs")
    k0 = 0
    for c in reader.chunks():
        L = c.n_samples
        for i, (a, b) in enumerate(windows):
            lo, hi = max(a, k0), min(b, k0 + L)
            if lo < hi:
                parts[i].append(_rows_of(c, lo - k0, hi - k0))
        k0 += L
    exps: list[Experiment] = []
    kept: list[tuple[int, int]] = []
    first: Data | None = None
    for (a, _), got in zip(windows, parts):
        if not got or sum(d.n_samples for d in got) < 2:
            continue
        data = concatenate(got)
        check_data(data.X, data.U, data.valid, states, inputs, data.lines)
        exps.append(Experiment(data.X, data.U, data.valid, name=path, first=a))
        kept.append((a, a + data.n_samples))
        first = first or data
    if not exps:
        raise ValueError(f"{path}: no window of --max-fit-rows {budget} holds 2 rows")
    return exps, _Long(path=path, rows=k0, windows=tuple(kept), budget=budget), first


def _rows_of(c: Data, a: int, b: int) -> Data:
    return Data(X=c.X[a:b], U=c.U[a:b], valid=c.valid[a:b], t=None if c.t is None else c.t[a:b],
                lines=c.lines[a:b], ignored=c.ignored)


def _validated_streamed(config: IdentifierConfig, long: _Long, names: ConfigFile, suffix: str,
                        start: int) -> dict[str, Scores]:
    """One-step and free-run scores of ``config`` with its weights frozen over every row of the long file
    (valid targets from sample ``start`` on), read a chunk at a time: two identifiers side by side, the
    second fed its own predictions from ``start`` on (the free run); a free run that diverges scores inf."""
    one, free = Identifier(config), Identifier(config)
    one.learning = free.learning = False
    n = config.n_states
    k0 = 0
    diverged = False
    with RunningScores(n) as r1, RunningScores(n) as r2:
        for c in DataReader(long.path, names, valid_suffix=suffix, config_source="--states/--inputs").chunks():
            L = c.n_samples
            X = np.where(c.valid, c.X, 0.0).astype(config.dtype)
            U = c.U.astype(config.dtype) if config.n_inputs else None
            mask = c.valid.copy()
            mask[:max(0, min(start - k0, L))] = False
            r1.add(c.X, simulate(one, X, U, c.valid).one_step.astype(np.float64), mask)
            fv = c.valid.copy()
            fv[max(0, min(start - k0, L)):] = False
            est = np.full((L, n), np.nan)
            if not diverged:
                try:
                    est = simulate(free, X, U, fv).one_step.astype(np.float64)
                except IdentifierError:
                    diverged = True
            r2.add(c.X, est, mask)
            k0 += L
        return {"one_step": r1.scores(), "free_run": r2.scores()}


@contextmanager
def _options_named() -> Iterator[None]:
    """Library errors name their fields (``max_delay: ...``, ``state_names[1]: ...``); here
    they name the command-line option instead (``--max-delay: ...``, ``--states: ...``)."""
    try:
        yield
    except ValueError as exc:
        field, sep, rest = str(exc).partition(": ")
        option = _OPTIONS.get(field.split("[", 1)[0]) if sep else None
        if option is None:
            raise
        raise ValueError(f"{option}: {field}: {rest}" if "[" in field else f"{option}: {rest}") from None


def _names(option: str, text: str) -> tuple[str, ...]:
    names = tuple(s.strip() for s in text.split(",")) if text.strip() else ()
    if any(not s for s in names):
        raise ValueError(f"{option}: empty name in {text!r} (comma-separated column names)")
    return names


def _int(option: str, text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise ValueError(f"{option}: expected a whole number, got {text!r}") from None


#: The options that describe a fixed candidate space, with their defaults.
_SPACE_DEFAULTS = {"max_delay": "0", "delay_step": "1", "degree": "2", "factors": "S,u,1", "input_max_delay": "0",
                   "activation": "bipolar,logistic", "beta": "1"}


def _space(args: argparse.Namespace) -> CandidateSpace:
    opt = {key: default if getattr(args, key) is None else getattr(args, key) for key, default in _SPACE_DEFAULTS.items()}
    factors = _names("--factors", opt["factors"])
    for name in factors:
        if name not in FACTOR_NAMES:
            raise ValueError(f"--factors: {name!r} is not a factor kind; expected some of {', '.join(FACTOR_NAMES)}")
    acts = []
    for name in _names("--activation", opt["activation"]):
        try:
            acts.append(Activation(name))
        except ValueError:
            raise ValueError(f"--activation: {name!r}: expected bipolar or logistic") from None
    betas = tuple(real_option("--beta", b, positive=True) for b in _names("--beta", opt["beta"]))
    if not betas:
        raise ValueError("--beta: expected at least one slope")
    return CandidateSpace(max_delay=_int("--max-delay", opt["max_delay"]),
                          delay_step=_int("--delay-step", opt["delay_step"]),
                          degree=_int("--degree", opt["degree"]), factors=factors,
                          input_max_delay=_int("--input-max-delay", opt["input_max_delay"]),
                          activations=tuple(acts), betas=betas)


def _experiments(args: argparse.Namespace, names: ConfigFile, suffix: str, states: tuple[str, ...],
                 inputs: tuple[str, ...], longs: list[_Long]) -> tuple[list[Experiment], list[Experiment], list[Data]]:
    """The estimation and validation experiments the options name, each file checked line by line."""
    if args.validate_rest and args.fit_rows is None:
        raise ValueError("--validate-rest: needs --fit-rows (the samples outside them validate)")
    est: list[Experiment] = []
    val: list[Experiment] = []
    files: list[Data] = []
    longs.clear()
    for path in args.data:
        if args.fit_rows is None:
            windows, long, first = _windows(path, names, suffix, states, inputs, args.max_fit_rows)
            if long is not None and first is not None:
                est += windows
                files.append(first)
                longs.append(long)
                continue
        data = read_data(path, names, valid_suffix=suffix, config_source="--states/--inputs")
        check_data(data.X, data.U, data.valid, states, inputs, data.lines)
        files.append(data)
        whole = Experiment(data.X, data.U, data.valid, name=str(path))
        T = data.n_samples
        try:
            a, b = row_range("--fit-rows", args.fit_rows, T)
        except ValueError as exc:
            raise ValueError(f"{exc} ({path})") from None
        est.append(whole.cut(a, b) if (a, b) != (0, T) else whole)
        if args.validate_rest:
            val += [whole.cut(s, e) for s, e in ((0, a), (b, T)) if e - s >= 2]
    if args.validate_rest and not val:
        raise ValueError(f"--validate-rest: --fit-rows {args.fit_rows} leaves no samples to validate")
    for path in args.validate:
        data = read_data(path, names, valid_suffix=suffix, config_source="--states/--inputs")
        check_data(data.X, data.U, data.valid, states, inputs, data.lines)
        val.append(Experiment(data.X, data.U, data.valid, name=str(path)))
    return est, val, files


def _tuned(config: IdentifierConfig, tuning: dict[str, float | None]) -> IdentifierConfig:
    if all(v is None for v in tuning.values()):
        return config

    def given(key: str, own: float | np.ndarray) -> float | np.ndarray:
        value = tuning[key]
        return own if value is None else value

    return config.replace(neurons=tuple(replace(nr, p0=given("p0", nr.p0), q=given("q", nr.q),
                                                r=nr.r if tuning["r"] is None else tuning["r"])
                                        for nr in config.neurons))


def run(args: argparse.Namespace) -> int:
    states, inputs = _names("--states", args.states), _names("--inputs", args.inputs)
    if not states:
        raise ValueError("--states: expected at least one state column")
    try:
        suffix = check_suffix(args.valid_suffix)
    except ValueError as exc:
        raise ValueError(f"--valid-suffix: {exc}") from None
    tuning = {key: None if getattr(args, key) is None else
              real_option(f"--{key}", getattr(args, key), positive=key != "q", nonnegative=key == "q")
              for key in ("p0", "q", "r")}
    given = [f"--{key.replace('_', '-')}" for key in _SPACE_DEFAULTS if getattr(args, key) is not None]
    mode = args.search or ("fixed" if given else "auto")
    if mode == "auto" and given:
        raise ValueError(f"--search auto: {', '.join(given)} fix(es) the candidate space; leave them out or "
                         "use --search fixed")
    if mode == "fixed" and args.tie is not None:
        raise ValueError("--tie: ties between candidate spaces are the automatic search's; a fixed space has none")
    tie = TIE if args.tie is None else real_option("--tie", args.tie, nonnegative=True)
    with _options_named():
        space = _space(args)
        max_terms = _int("--max-terms", args.max_terms)
        holdout = real_option("--holdout", args.holdout or ("0.3" if mode == "auto" else "0.2"))
        if not 0.0 < holdout < 1.0:
            raise ValueError(f"--holdout: expected a fraction in (0, 1), got {args.holdout}")
        # the names as a config file would hold them (checked there), to read the columns
        probe = IdentifierConfig.uniform(((Factor.one(),),), n_states=len(states), n_inputs=len(inputs))
        names = ConfigFile.from_config(probe, state_names=states, input_names=inputs)
    longs: list[_Long] = []
    est, val, files = _experiments(args, names, suffix, states, inputs, longs)
    for long in longs:
        print(long.why())
    fit_samples = sum(ex.n_samples for ex in est)
    if mode == "auto":
        with _options_named():
            found = search(est, val, criterion=args.criterion, max_terms=max_terms, holdout=holdout,
                           refine_weights=not args.no_refine, dtype=args.dtype, state_names=states,
                           input_names=inputs, tie=tie)
        cf = found.config_file(states, inputs)
        cf = ConfigFile.from_config(_tuned(cf.config, tuning), state_names=states, input_names=inputs,
                                    description=cf.description, why=cf.why)
        report = found.selection.report(states) + "\n" + found.report(states, inputs)
        payload: dict[str, object] = {**_as_json(found.selection, states), "search": _search_json(found, states)}
    else:
        X, U, valid, starts = merge(est)
        with _options_named():
            sel = select(X, U, valid, space=space, criterion=args.criterion, max_terms=max_terms, holdout=holdout,
                         state_names=states, input_names=inputs, starts=starts,
                         first_line=files[0].lines if len(files) == 1 and (est[0].n_samples == files[0].n_samples)
                         else None)
            cf = sel.config_file(states, inputs, dtype=args.dtype, **tuning)
        fit_rows = "; ".join(f"{ex.name} rows {ex.rows}" for ex in est)
        if val:
            checked_v = validate(cf.config, val, DataRange.of(est))
            report = (sel.report(states) + f"\nfitted on: {fit_rows}\n"
                      + _validation_table(checked_v, states, "; ".join(f"{ex.name} rows {ex.rows}" for ex in val)))
            payload = {**_as_json(sel, states), "fit_rows": [f"{ex.name} rows {ex.rows}" for ex in est],
                       "validation": _validation_json(checked_v, states, [f"{ex.name} rows {ex.rows}" for ex in val])}
        else:
            start = space.window + 1
            merged = Data(X, U, valid, None, np.arange(X.shape[0]), ())
            checked = _validation(cf.config, merged, start)
            report = (sel.report(states) + f"\nfitted on: {fit_rows}\n"
                      + _validation_text(checked, states, start))
            payload = {**_as_json(sel, states), "fit_rows": [f"{ex.name} rows {ex.rows}" for ex in est],
                       "validation": {"from_sample": start, "weights": "least squares, frozen",
                                      **{kind: {name: {"rmse": json_value(sc.rmse[j]), "rrse": json_value(sc.rrse[j])}
                                                for j, name in enumerate(states)} for kind, sc in checked.items()}}}
    for long in longs:  # the structure chosen on the windows, checked on every row of the record
        deepest = max((f.delay for nr in cf.config.neurons for term in nr.terms for f in term), default=0)
        start = min(long.rows - 1, deepest + 1)  # the first sample whose taps all read measured samples
        checked = _validated_streamed(cf.config, long, names, suffix, start)
        report += f"\n{long.why()}\n" + _validation_text(checked, states, start).replace(
            "on the same data", f"on every row of {long.path}", 1)
        records = payload.setdefault("long_records", [])
        assert isinstance(records, list)
        records.append(
            {**long.as_json(), "validation": {"from_sample": start, "weights": "frozen", "rows": long.rows,
                                              **{kind: {name: {"rmse": json_value(sc.rmse[j]),
                                                               "rrse": json_value(sc.rrse[j])}
                                                        for j, name in enumerate(states)}
                                                 for kind, sc in checked.items()}}})
    atomic.write_text(args.out, dumps(cf))
    if args.report:
        atomic.write_text(args.report, report + "\n")
    if args.json:
        atomic.write_text(args.json, json.dumps(payload, indent=2) + "\n")
    print(f"selected from {', '.join(args.data)}: {fit_samples} samples fitted; wrote {args.out}")
    print(report)
    return 0


def _validation_table(v: Validation, states: tuple[str, ...], rows: str) -> str:
    width = max(5, *(len(s) for s in states))
    lines = [f"the selected model, weights frozen, on the validation data ({rows}):",
             f"  {'state':<{width}}  {'one-step RMSE':>14}  {'RRSE':>9}  {'free-run RMSE':>14}  {'RRSE':>9}"]
    gone = v.left_range is not None
    for j, name in enumerate(states):
        lines.append(f"  {name:<{width}}  {v.one_rmse[j]:14.4g}  {v.one_rrse[j]:9.4g}  "
                     f"{'diverged' if gone else f'{v.free_rmse[j]:.4g}':>14}  "
                     f"{'-' if gone else f'{v.free_rrse[j]:.4g}':>9}")
    if gone:
        assert v.left_range is not None
        lines.append(f"  the free run left the data's range at sample {v.left_range[1]} of {v.left_range[0]}")
    return "\n".join(lines)


def _validation_json(v: Validation, states: tuple[str, ...], rows: list[str]) -> dict[str, object]:
    return {"rows": rows, "weights": "frozen", "scored": v.scored,
            "free_run_left_range": None if v.left_range is None else
            {"experiment": v.left_range[0], "sample": v.left_range[1]},
            "one_step": {name: {"rmse": json_value(v.one_rmse[j]), "rrse": json_value(v.one_rrse[j])}
                         for j, name in enumerate(states)},
            "free_run": {name: {"rmse": json_value(v.free_rmse[j]), "rrse": json_value(v.free_rrse[j]),
                                "fit_percent": json_value(100.0 * (1.0 - v.free_rrse[j]))}
                         for j, name in enumerate(states)}}


def _search_json(found: SearchResult, states: tuple[str, ...]) -> dict[str, object]:
    ref = found.refinement
    return {
        "fit_rows": list(found.fit_rows),
        "ranked_on": list(found.validation_rows),
        "ranked_by": "blocked cross-validation of the estimation data" if found.held_out else "validation data",
        "input_dead_times": list(found.dead_times),
        "state_delay": found.state_delay,
        "chosen_by": "one-step error (no model simulates)" if found.by_one_step else "free run",
        "tie": found.tie,
        "spaces": [{"factors": list(sc.space.factors), "degree": sc.space.degree, "max_delay": sc.space.max_delay,
                    "input_taps": [sc.space.input_min_delay, sc.space.input_max_delay] if "u" in sc.space.factors
                    else None, "extra_state_delays": list(sc.space.extra_delays), "terms": sc.terms, "status": sc.status, "max_terms_reached": sc.capped,
                    "free_run_rrse": json_value(sc.score),
                    "one_step_rrse": None if sc.validation is None else json_value(float(np.mean(sc.validation.one_rrse)))}
                   for sc in found.scores],
        "chosen": found.chosen,
        "refinement": None if ref is None else {"objective": ref.objective, "cost_before": ref.cost_before,
                                                "cost_after": ref.cost_after,
                                                "one_step_before": json_value(ref.one_step_before),
                                                "one_step_after": json_value(ref.one_step_after),
                                                "iterations": ref.iterations, "evaluations": ref.evaluations,
                                                "stopped": ref.stopped},
        "validation": None if found.validation is None else
        _validation_json(found.validation, states, list(found.validation_rows)),
        "in_sample": _validation_json(found.in_sample, states, list(found.fit_rows)),
        "search_samples": found.search_samples,
        "notes": list(found.notes),
        "seconds": found.seconds,
    }


def _validation(config: IdentifierConfig, data: Data, start: int) -> dict[str, Scores]:
    """One-step and free-run scores of ``config`` with its weights frozen over the data,
    valid targets from sample ``start`` on (the first whose taps all read measured samples)."""
    ident = Identifier(config)
    ident.learning = False
    X = np.where(data.valid, data.X, 0.0).astype(config.dtype)
    U = data.U.astype(config.dtype)
    start = min(start, data.n_samples - 1)
    sim = simulate(ident, X, U if config.n_inputs else None, data.valid, free_run_from=start)
    assert sim.free_run is not None
    mask = data.valid.copy()
    mask[:start] = False
    return {"one_step": scores(data.X, sim.one_step.astype(np.float64), mask),
            "free_run": scores(data.X, sim.free_run.astype(np.float64), mask)}


def _validation_text(checked: dict[str, Scores], states: tuple[str, ...], start: int) -> str:
    def cell(v: float) -> str:
        return "diverged" if v == np.inf else "-" if np.isnan(v) else f"{v:.4g}"

    width = max(5, *(len(s) for s in states))
    lines = [f"the selected model, least-squares weights frozen, on the same data from sample {start} on:",
             f"  {'state':<{width}}  {'one-step RMSE':>14}  {'RRSE':>9}  {'free-run RMSE':>14}  {'RRSE':>9}"]
    one, free = checked["one_step"], checked["free_run"]
    for j, name in enumerate(states):
        lines.append(f"  {name:<{width}}  {cell(one.rmse[j]):>14}  {cell(one.rrse[j]):>9}  "
                     f"{cell(free.rmse[j]):>14}  {cell(free.rrse[j]):>9}")
    return "\n".join(lines)


def _as_json(sel: Selection, states: tuple[str, ...]) -> dict[str, object]:
    delays = sel.state_delays()
    return {
        "format": "pyrhonn-select",
        "version": 1,
        "criterion": sel.criterion.value,
        "candidates": sel.n_candidates,
        "rows": sel.rows,
        "rows_held_out": sel.rows_held_out,
        "rows_dropped": sel.rows_dropped,
        "seconds": sel.seconds,
        "neurons": [{"state": states[nr.state], "activation": nr.activation.value, "beta": nr.beta,
                     "score": nr.score, "residual_variance": nr.residual_variance,
                     "terms": [{"term": t.text, "err": t.err, "weight": t.weight} for t in nr.terms]}
                    for nr in sel.neurons],
        "state_delays": {states[j]: d for j, d in enumerate(delays)},
    }
