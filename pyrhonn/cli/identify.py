"""``pyrhonn identify``: run an identifier on the user's own data (a CSV file or a bus recording).

``pyrhonn identify data.csv --config cfg.toml [--out DIR] [--dtype float32|float64]
[--valid-suffix _valid] [--warmup N] [--no-plots]``

``pyrhonn identify --can-log RUN.{blf,asc,log} --dbc FILE --config cfg.toml [...]`` reads the states
and inputs from a CAN log instead (:mod:`pyrhonn.cli.bus_input`, :mod:`pyrhonn.buslog`), runs and
writes the same outputs, plus ``samples.csv``, the aligned samples in the CSV format.

Input file
----------
The format of :mod:`pyrhonn.datafile` (a header row naming the columns by
the config's ``state_names`` and ``input_names``, optional ``t`` and
``<state><suffix>`` validity columns); every defect is reported with its
line number and exit code 2.

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
from ..datafile import Data, TIME_COLUMN, check_suffix, read_data, write_data
from ..identifier import Identifier, IdentifierError
from ..metrics import absolute_deviation, rmse
from . import bus_input

__all__ = ["register", "run"]

def _nonnegative_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number of samples, got {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {value}")
    return value


def _suffix(text: str) -> str:
    try:
        return check_suffix(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _units(text: str) -> dict[str, str]:
    """--units: NAME=UNIT pairs, comma-separated; names are checked against the config in run()."""
    units: dict[str, str] = {}
    for item in text.split(","):
        name, sep, unit = item.partition("=")
        name, unit = name.strip(), unit.strip()
        if not sep or not name or not unit:
            raise argparse.ArgumentTypeError(f"expected NAME=UNIT[,NAME=UNIT...], got {item.strip()!r}")
        if name in units:
            raise argparse.ArgumentTypeError(f"{name!r} is given twice")
        units[name] = unit
    return units


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "identify", help="identify a plant from a CSV file of states and inputs (or a CAN log)",
        description="Run the RHONN identifier (C core) on a CSV file whose columns are named by the config; "
                    "write one-step-ahead predictions, metrics (RMSE, absolute deviation) and plots.")
    p.add_argument("data", metavar="DATA.csv", nargs="?",
                   help="the measurements: header row, then one line per sample (or --can-log)")
    p.add_argument("--config", required=True, metavar="CFG",
                   help="identifier config: a .toml file (see pyrhonn show-config) or a shipped config name")
    p.add_argument("--out", metavar="DIR", help="output folder (default: identify-<data file stem>)")
    p.add_argument("--dtype", choices=DTYPES, help="build of the C core to run (default: the config's dtype)")
    p.add_argument("--valid-suffix", type=_suffix, default="_valid", metavar="SUFFIX",
                   help="validity columns are named <state><SUFFIX> (default: _valid)")
    p.add_argument("--warmup", type=_nonnegative_int, default=0, metavar="N",
                   help="leave the first N one-step-ahead pairs out of the metrics (default 0)")
    p.add_argument("--no-plots", action="store_true", help="do not write the PNG plots")
    p.add_argument("--units", type=_units, default={}, metavar="NAME=UNIT[,NAME=UNIT...]",
                   help="units of the states (and of the time column t) for the plots' axes, e.g. "
                        "q_m=m,v=m/s,t=s; the CSV carries none, so a state without one is labelled "
                        "'(no unit given)'")
    bus_input.add_options(p)
    p.set_defaults(func=run)


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
    with atomic.replacing(path, "w", newline="") as fh:
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


NOT_VALID_LABEL = "not valid (not learnt; predicted from its own outputs)"  #: legend entry of the shaded samples


def _plot(path: Path, name: str, data: Data, Xhat: np.ndarray, j: int, warmup: int,
          units: dict[str, str]) -> None:
    """Measured and identified state j over the error: every y axis carries the state's unit
    (``--units``), and the samples whose measurement was not valid are shaded, in the legend."""
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
    source = bus.source if bus else args.data
    data = bus.data if bus else read_data(source, cf, valid_suffix=args.valid_suffix, config_source=config_source)
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
    written = [out / "predictions.csv", out / "metrics.json"] + plots + ([out / bus_input.SAMPLES] if bus else [])
    _refuse_overwriting_inputs([*written, out / atomic.MARKER],
                               {"the data file": source, "the config file": config_source,
                                **({"the DBC": bus.dbc} if bus else {})})
    dtype = args.dtype or cf.config.dtype
    cfg = cf.config if dtype == cf.config.dtype else cf.config.replace(dtype=dtype)
    xhat0, Xhat = _run_identifier(cfg, data, cf, source, config_source)
    r, ad, count = _metrics(data, Xhat, args.warmup)

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
        **({"bus": bus.report()} if bus else {}),
    }
    with atomic.output_folder(out, "pyrhonn identify"):  # marked INCOMPLETE until every file is in place
        if bus:
            write_data(out / bus_input.SAMPLES, data, cf, valid_suffix=args.valid_suffix)
        _write_predictions(out / "predictions.csv", data, cf, xhat0, Xhat)
        atomic.write_text(out / "metrics.json", json.dumps(report, indent=2) + "\n")
        for j, path in enumerate(plots):
            _plot(path, cf.state_names[j], data, Xhat, j, args.warmup, args.units)

    print(f"identified {source}: {T} samples, {_count(cfg.n_states, 'state')}, {_count(cfg.n_inputs, 'input')}, "
          f"config {config_source}, {dtype}")
    if data.ignored:
        print("ignored columns: " + ", ".join(data.ignored))
    for line in bus.summary() if bus else []:
        print(line)
    print(f"one-step-ahead error over valid targets, warmup {args.warmup}:")
    width = max(5, *(len(s) for s in cf.state_names))
    print(f"  {'state':<{width}}  {'scored':>7}  {'RMSE':>12}  {'abs. dev.':>12}")
    for j, name in enumerate(cf.state_names):
        print(f"  {name:<{width}}  {int(count[j]):>7}  {r[j]:>12.6g}  {ad[j]:>12.6g}")
    print("wrote " + ", ".join(str(p) for p in written))
    return 0
