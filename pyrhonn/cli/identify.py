"""``pyrhonn identify``: run an identifier on the user's own data (a CSV file).

``pyrhonn identify data.csv --config cfg.toml [--out DIR] [--dtype float32|float64]
[--valid-suffix _valid] [--warmup N] [--no-plots]``

Input file
----------
UTF-8 text (a byte-order mark is allowed), comma-separated, first line a
header naming the columns; one line per sample k = 0..T-1, in time order.

- One column per state and per input, named by the config's ``state_names``
  and ``input_names`` (``pyrhonn show-config`` prints them). ``--config``
  also accepts the name of a shipped config (e.g. ``example1``).
- Optional ``t``: the sample time, finite and strictly increasing; used as
  the x axis of the plots and copied to the predictions.
- Optional per-state validity columns ``<state><suffix>`` (suffix
  ``_valid`` unless ``--valid-suffix`` says otherwise) holding ``0`` or
  ``1``: 0 marks a measurement that was not updated (a dropout or a delay).
  The identifier does not learn from it and uses its own prediction in its
  place (see :meth:`pyrhonn.Identifier.run`); its cell may be empty or NaN.
  A state without a validity column is valid on every line.
- Other columns are ignored (and listed on the output).
- Numbers are decimal (``-1.5``, ``2e-3``); spaces around a cell are allowed.
  An empty cell or ``nan`` is a missing value, allowed only in a state
  column whose validity is 0 on that line. Infinities, other text, missing
  inputs or times are errors.

Every defect (undecodable text, malformed CSV, an empty file, a header
without data, duplicate or missing columns, a line with the wrong number of
fields, a non-numeric cell, a missing value in a valid state, a bad
validity flag) is reported as ``<file>: line <N>: ...`` with N 1-based,
the header being line 1 (a quoted cell spanning lines counts them all; N is
the first line of the record), and exit code 2.

Outputs (in ``--out``, default ``identify-<file stem>``)
--------------------------------------------------------
- ``predictions.csv``: one row per input line: ``line`` (its line number in
  the data file), ``t`` (if given), and per state ``<name>_hat``, x̂(k), the
  one-step-ahead prediction of this line made from the lines before it
  (line 2 holds the config's x0), and ``<name>_err`` = measured − x̂(k),
  empty where the measurement is invalid and on the first line.
- ``metrics.json``: per state the RMSE and absolute deviation
  (:mod:`pyrhonn.metrics`) of the one-step-ahead error: prediction row k
  (made at sample k) against measurement row k+1, over valid targets only,
  after dropping the first ``--warmup`` pairs; also the number of pairs
  scored, the prediction x̂(T) beyond the last line, and the run settings.
- ``<state>.png`` per state (unless ``--no-plots``): measured vs identified,
  and the error, against ``t`` (or the sample index).

The identifier runs in the C core in ``--dtype`` (default: the config's
dtype); measurements are read as float64 and rounded to float32 only when
running float32. Metrics compare the float64 measurements of the file with
the predictions.
"""
from __future__ import annotations

import argparse
import csv
import io
import json
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from ..config import DTYPES, IdentifierConfig
from ..configfile import ConfigFile, load_named
from ..identifier import Identifier, IdentifierError
from ..metrics import absolute_deviation, rmse

__all__ = ["Data", "read_data", "register", "run"]

_NUMBER = re.compile(r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?\Z")
_MISSING = ("", "nan", "NaN", "NAN")
_INFINITE = re.compile(r"[+-]?(?:inf|Inf|INF|infinity|Infinity|INFINITY)\Z")
TIME_COLUMN = "t"


def _nonnegative_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number of samples, got {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {value}")
    return value


def _suffix(text: str) -> str:
    if not text or any(c in text for c in ",\"\r\n") or text != text.strip():
        raise argparse.ArgumentTypeError(f"expected a non-empty column-name suffix, got {text!r}")
    return text


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "identify", help="identify a plant from a CSV file of states and inputs",
        description="Run the RHONN identifier (C core) on a CSV file whose columns are named by the config; "
                    "write one-step-ahead predictions, metrics (RMSE, absolute deviation) and plots.")
    p.add_argument("data", metavar="DATA.csv", help="the measurements: header row, then one line per sample")
    p.add_argument("--config", required=True, metavar="CFG",
                   help="identifier config: a .toml file (see pyrhonn show-config) or a shipped config name")
    p.add_argument("--out", metavar="DIR", help="output folder (default: identify-<data file stem>)")
    p.add_argument("--dtype", choices=DTYPES, help="build of the C core to run (default: the config's dtype)")
    p.add_argument("--valid-suffix", type=_suffix, default="_valid", metavar="SUFFIX",
                   help="validity columns are named <state><SUFFIX> (default: _valid)")
    p.add_argument("--warmup", type=_nonnegative_int, default=0, metavar="N",
                   help="leave the first N one-step-ahead pairs out of the metrics (default 0)")
    p.add_argument("--no-plots", action="store_true", help="do not write the PNG plots")
    p.set_defaults(func=run)


# -- reading ----------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Data:
    """A data file as read: T samples.

    ``X`` (T, n) float64 with NaN where a state is missing, ``U`` (T, m),
    ``valid`` (T, n) bool, ``t`` (T,) or None, ``lines`` (T,) the file line
    of each sample, ``ignored`` the columns not used.
    """

    X: np.ndarray
    U: np.ndarray
    valid: np.ndarray
    t: np.ndarray | None
    lines: np.ndarray
    ignored: tuple[str, ...]

    @property
    def n_samples(self) -> int:
        return int(self.X.shape[0])


def _decode(raw: bytes, source: str) -> str:
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = raw.count(b"\n", 0, exc.start) + 1
        raise ValueError(f"{source}: line {line}: not UTF-8 text (byte {exc.start})") from None


def _records(text: str, source: str) -> list[tuple[int, list[str]]]:
    """Every CSV record with the line it starts on; blank lines are kept as []."""
    reader = csv.reader(io.StringIO(text, newline=""), strict=True)
    out: list[tuple[int, list[str]]] = []
    last = 0
    while True:
        try:
            record = next(reader)
        except StopIteration:
            return out
        except csv.Error as exc:
            hint = " (a quote that is never closed?)" if "end of data" in str(exc) else ""
            raise ValueError(f"{source}: line {last + 1}: malformed CSV: {exc}{hint}") from None
        if len(record) == 1 and not record[0].strip():
            record = []
        out.append((last + 1, record))
        last = reader.line_num


def _cell(source: str, line: int, column: str, text: str) -> float:
    """A numeric cell: a float, NaN for a missing value; ValueError otherwise."""
    s = text.strip()
    if _NUMBER.match(s):
        value = float(s)
        if not np.isfinite(value):
            raise ValueError(f"{source}: line {line}, column {column!r}: {s!r} is out of the float64 range")
        return value
    if s in _MISSING:
        return float("nan")
    if _INFINITE.match(s):
        raise ValueError(f"{source}: line {line}, column {column!r}: not finite: {s!r}")
    raise ValueError(f"{source}: line {line}, column {column!r}: not a number: {text!r}")


def read_data(path: str | Path, cf: ConfigFile, *, valid_suffix: str = "_valid",
              config_source: str = "the config") -> Data:
    """Read and check a data file for the config ``cf`` (see the module docs)."""
    source = str(path)
    text = _decode(Path(path).read_bytes(), source)
    if not text.strip():
        raise ValueError(f"{source}: empty file (expected a header row naming the columns, then the data)")
    records = _records(text, source)
    header_line, header = records[0]
    if not header:
        raise ValueError(f"{source}: line {header_line}: empty line where the header row was expected")
    names = [h.strip() for h in header]
    where: dict[str, int] = {}
    for c, name in enumerate(names):
        if not name:
            raise ValueError(f"{source}: line {header_line}: column {c + 1} has an empty name")
        if name in where:
            raise ValueError(f"{source}: line {header_line}: duplicate column {name!r} "
                             f"(columns {where[name] + 1} and {c + 1})")
        where[name] = c
    required = list(cf.state_names) + list(cf.input_names)
    missing = [name for name in required if name not in where]
    if missing:
        raise ValueError(
            f"{source}: line {header_line}: missing column{'s' if len(missing) > 1 else ''} "
            + ", ".join(repr(m) for m in missing)
            + f" ({config_source} names the states {', '.join(cf.state_names)}"
            + (f" and the inputs {', '.join(cf.input_names)})" if cf.input_names else " and no inputs)"))
    validity: dict[int, int] = {}
    for j, name in enumerate(cf.state_names):
        vname = f"{name}{valid_suffix}"
        if vname in required or vname == TIME_COLUMN:
            raise ValueError(f"--valid-suffix: the validity column of state {name!r} would be {vname!r}, "
                             "which is also a state, input or time column; choose another suffix")
        if vname in where:
            validity[j] = where[vname]
    used = set(required) | {f"{cf.state_names[j]}{valid_suffix}" for j in validity} | {TIME_COLUMN}
    ignored = tuple(name for name in names if name not in used)
    body = records[1:]
    while body and not body[-1][1]:
        body.pop()  # blank lines at the end of the file
    if not body:
        raise ValueError(f"{source}: line {header_line}: header only, no data rows")
    n, m, T = len(cf.state_names), len(cf.input_names), len(body)
    X = np.empty((T, n))
    U = np.empty((T, m))
    valid = np.ones((T, n), dtype=bool)
    t = np.empty(T) if TIME_COLUMN in where else None
    lines = np.empty(T, dtype=np.int64)
    state_cols = [where[name] for name in cf.state_names]
    input_cols = [where[name] for name in cf.input_names]
    width = len(names)
    for k, (line, record) in enumerate(body):
        lines[k] = line
        if not record:
            raise ValueError(f"{source}: line {line}: empty line inside the data")
        if len(record) != width:
            raise ValueError(f"{source}: line {line}: expected {width} fields as in the header, got {len(record)}")
        if t is not None:
            value = _cell(source, line, TIME_COLUMN, record[where[TIME_COLUMN]])
            if np.isnan(value):
                raise ValueError(f"{source}: line {line}, column 't': missing time")
            if k and not value > t[k - 1]:
                raise ValueError(f"{source}: line {line}, column 't': time {value!r} is not after "
                                 f"{float(t[k - 1])!r} on line {int(lines[k - 1])} (times must increase)")
            t[k] = value
        for j, c in validity.items():
            flag = record[c].strip()
            if flag not in ("0", "1"):
                raise ValueError(f"{source}: line {line}, column {names[c]!r}: expected 0 or 1, got {record[c]!r}")
            valid[k, j] = flag == "1"
        for j, c in enumerate(state_cols):
            value = _cell(source, line, names[c], record[c])
            if np.isnan(value) and valid[k, j]:
                how = (f"{names[validity[j]]} = 1" if j in validity
                       else f"no {cf.state_names[j]}{valid_suffix!s} column; add one with 0 on this line "
                            "to mark a missing measurement")
                raise ValueError(f"{source}: line {line}, column {names[c]!r}: missing value (empty or NaN) "
                                 f"but the state is marked valid ({how})")
            X[k, j] = value
        for j, c in enumerate(input_cols):
            value = _cell(source, line, names[c], record[c])
            if np.isnan(value):
                raise ValueError(f"{source}: line {line}, column {names[c]!r}: missing input value "
                                 "(inputs must be given on every line)")
            U[k, j] = value
    return Data(X=X, U=U, valid=valid, t=t, lines=lines, ignored=ignored)


# -- running ----------------------------------------------------------------------------------------


def _to_dtype(a: np.ndarray, dtype: str, data: Data, names: Sequence[str], source: str,
              mask: np.ndarray | None = None) -> np.ndarray:
    """``a`` in ``dtype``; ValueError naming the line if a value overflows it."""
    with np.errstate(over="ignore"):
        out = a.astype(dtype)
    bad = ~np.isfinite(out) & np.isfinite(a)
    if mask is not None:
        bad &= mask
    if bad.any():
        k, j = (int(i) for i in np.argwhere(bad)[0])
        raise ValueError(f"{source}: line {int(data.lines[k])}, column {names[j]!r}: {float(a[k, j])!r} "
                         f"overflows {dtype} (--dtype {dtype})")
    return out


def _run_identifier(cfg: IdentifierConfig, data: Data, cf: ConfigFile, source: str,
                    config_source: str) -> tuple[np.ndarray, np.ndarray]:
    """``(xhat0, Xhat)``: x̂(0) and the run's predictions, row k = x̂(k+1)."""
    try:
        ident = Identifier(cfg)
    except ValueError as exc:
        raise ValueError(f"{config_source}: {exc}") from None
    X = _to_dtype(data.X, cfg.dtype, data, cf.state_names, source, data.valid)
    U = _to_dtype(data.U, cfg.dtype, data, cf.input_names, source)
    xhat0 = ident.prediction
    try:
        Xhat = ident.run(X, U, data.valid)
    except IdentifierError as exc:
        found = re.search(r"at sample (\d+)", str(exc))
        where = f"line {int(data.lines[int(found.group(1))])}: " if found else ""
        raise ValueError(f"{source}: {where}the identifier stopped: {exc}") from None
    return xhat0, Xhat


def _metrics(data: Data, Xhat: np.ndarray, warmup: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per state ``(rmse, absolute deviation, count)``: prediction row k vs
    measurement row k+1, valid targets only, pairs k >= warmup (NaN if none)."""
    truth = data.X[1:]
    estimate = Xhat[:-1].astype(np.float64)
    scored = data.valid[1:].copy()
    scored[:warmup] = False
    n = truth.shape[1]
    r, ad = np.full(n, np.nan), np.full(n, np.nan)
    count = scored.sum(axis=0)
    for j in range(n):
        mask = scored[:, j]
        if mask.any():
            x, xh = truth[mask, j][:, None], estimate[mask, j][:, None]
            r[j] = rmse(x, xh)[0]
            ad[j] = absolute_deviation(x, xh)[0]
    return r, ad, count


def _count(k: int, noun: str) -> str:
    return f"{k} {noun}{'' if k == 1 else 's'}"


def _number(v: float) -> float | None:
    return None if not np.isfinite(v) else float(v)


def _write_predictions(path: Path, data: Data, cf: ConfigFile, xhat0: np.ndarray, Xhat: np.ndarray) -> None:
    T = data.n_samples
    hat = np.vstack([xhat0[None, :], Xhat[:-1]]).astype(np.float64)
    err = data.X - hat
    header = ["line"] + ([TIME_COLUMN] if data.t is not None else [])
    for name in cf.state_names:
        header += [f"{name}_hat", f"{name}_err"]
    with path.open("w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(header)
        for k in range(T):
            row: list[Any] = [int(data.lines[k])]
            if data.t is not None:
                row.append(repr(float(data.t[k])))
            for j in range(len(cf.state_names)):
                row.append(repr(float(hat[k, j])))
                row.append(repr(float(err[k, j])) if k and data.valid[k, j] else "")
            w.writerow(row)


def _plot(path: Path, name: str, data: Data, Xhat: np.ndarray, j: int, warmup: int) -> None:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    x_axis = data.t if data.t is not None else np.arange(data.n_samples, dtype=np.float64)
    measured = np.where(data.valid[:, j], data.X[:, j], np.nan)
    identified = Xhat[:-1, j].astype(np.float64)
    error = measured[1:] - identified
    fig = Figure(figsize=(8.0, 5.0), layout="constrained")
    FigureCanvasAgg(fig)
    top, bottom = fig.subplots(2, 1, sharex=True, height_ratios=[3, 1.4])
    top.plot(x_axis, measured, color="0.15", lw=1.2, marker=".", ms=2.5, label=f"{name} (measured)")
    top.plot(x_axis[1:], identified, color="tab:red", lw=1.0, ls="--", label=f"{name} identified (one step ahead)")
    top.set_ylabel(name)
    top.set_title(f"{name}: real vs identified")
    bottom.plot(x_axis[1:], error, color="tab:blue", lw=0.9)
    bottom.axhline(0.0, color="0.6", lw=0.6)
    bottom.set_ylabel("error")
    bottom.set_xlabel("t" if data.t is not None else "sample")
    if warmup:
        for ax in (top, bottom):
            ax.axvspan(x_axis[0], x_axis[min(warmup, data.n_samples - 1)], color="0.9", lw=0, zorder=0,
                       label="warm-up (not scored)" if ax is top else None)
    top.legend(loc="best", fontsize="small")
    fig.savefig(path, dpi=100)


def run(args: argparse.Namespace) -> int:
    cf = load_named(args.config)
    config_source = args.config
    source = args.data
    data = read_data(source, cf, valid_suffix=args.valid_suffix, config_source=config_source)
    T = data.n_samples
    if T < 2:
        raise ValueError(f"{source}: line {int(data.lines[0])}: only one data row; one-step-ahead "
                         "identification needs at least two")
    if args.warmup >= T - 1:
        raise ValueError(f"--warmup {args.warmup}: leaves nothing to score ({T} data rows give {T - 1} "
                         "one-step-ahead pairs)")
    dtype = args.dtype or cf.config.dtype
    cfg = cf.config if dtype == cf.config.dtype else cf.config.replace(dtype=dtype)
    xhat0, Xhat = _run_identifier(cfg, data, cf, source, config_source)
    r, ad, count = _metrics(data, Xhat, args.warmup)

    out = Path(args.out) if args.out else Path(f"identify-{Path(source).stem}")
    out.mkdir(parents=True, exist_ok=True)
    _write_predictions(out / "predictions.csv", data, cf, xhat0, Xhat)
    report = {
        "format": "pyrhonn-identify-metrics",
        "version": 1,
        "data": str(source),
        "config": config_source,
        "dtype": dtype,
        "samples": T,
        "pairs": T - 1,
        "warmup": args.warmup,
        "valid_suffix": args.valid_suffix,
        "ignored_columns": list(data.ignored),
        "definition": "one-step-ahead: the prediction made at sample k against the measurement at sample "
                      "k+1, over valid targets only, pairs k >= warmup; rmse and absolute_deviation "
                      "(mean |e - mean e|) as in pyrhonn.metrics",
        "states": {name: {"rmse": _number(r[j]), "absolute_deviation": _number(ad[j]), "scored": int(count[j]),
                          "invalid_samples": int((~data.valid[:, j]).sum())}
                   for j, name in enumerate(cf.state_names)},
        "next_prediction": {name: float(Xhat[-1, j]) for j, name in enumerate(cf.state_names)},
    }
    (out / "metrics.json").write_text(json.dumps(report, indent=2) + "\n", encoding="utf-8")
    plots = []
    if not args.no_plots:
        for j, name in enumerate(cf.state_names):
            plots.append(out / f"{name}.png")
            _plot(plots[-1], name, data, Xhat, j, args.warmup)

    print(f"identified {source}: {T} samples, {_count(cfg.n_states, 'state')}, {_count(cfg.n_inputs, 'input')}, "
          f"config {config_source}, {dtype}")
    if data.ignored:
        print("ignored columns: " + ", ".join(data.ignored))
    print(f"one-step-ahead error over valid targets, warmup {args.warmup}:")
    width = max(5, *(len(s) for s in cf.state_names))
    print(f"  {'state':<{width}}  {'scored':>7}  {'RMSE':>12}  {'abs. dev.':>12}")
    for j, name in enumerate(cf.state_names):
        print(f"  {name:<{width}}  {int(count[j]):>7}  {r[j]:>12.6g}  {ad[j]:>12.6g}")
    written = [out / "predictions.csv", out / "metrics.json"] + plots
    print("wrote " + ", ".join(str(p) for p in written))
    return 0
