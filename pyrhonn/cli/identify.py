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
  ``t`` (or the sample index). A record of more than 2,048 samples is drawn
  as its min-max envelope (:mod:`pyrhonn.envelope`), which the title says.

Long records
------------
Without ``--free-run-from`` and ``--steps-ahead`` the record is streamed: a
CSV file is read a block at a time (:class:`pyrhonn.datafile.DataReader`),
a bus log a chunk of frames at a time (:mod:`pyrhonn.buslogstream`; its
samples.csv staged as it goes; a log it cannot stream, or that it refuses,
is read whole, to the same result or message), a signal MDF4 a block of records of each channel at a time
(:class:`pyrhonn.mdfsignals.SignalMdfStream`), the core runs chunk by chunk keeping its state (the predictions are the
whole record's, bit for bit), gaps are found chunk by chunk
(:class:`pyrhonn.gaps.SegmentTracker`), ``predictions.csv`` is written as
the chunks come and the metrics are running sums
(:mod:`pyrhonn.streamscores`): memory does not grow with the record. Every mode
streams: with ``--free-run-from`` and ``--steps-ahead`` the network stepped on the
measurements and the free run are both carried from chunk to chunk, and the last
H samples of a chunk wait for the next one's inputs before their H-step branches
are run (:mod:`pyrhonn.simulationstream`). Where the free run leaves the data's
range (the whole file's) is found without a second pass: only the free-run
samples outside the range of the measurements read so far are kept, in a
scratch file, and tested against the final range at the end. Settings that need
the record's length are checked at its end, with the same messages, before
anything is written. The results are those of the record held whole, byte for
byte.

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
import json
import os
import re
import shutil
import tempfile
from dataclasses import dataclass, replace
from pathlib import Path
from typing import IO, Any, Iterable, Iterator, Sequence

import numpy as np

from .. import atomic
from ..config import DTYPES, IdentifierConfig
from ..configfile import ConfigFile, load_named
from ..csvcodec import format_rows
from ..buslogstream import Reread
from ..datafile import (BLOCK_BYTES, ROWS_AT_ONCE, SEPARATORS, Data, DataReader, TIME_COLUMN, check_suffix,
                        concatenate, data_columns, data_rows, header_line, write_data)
from ..envelope import Envelope
from ..gaps import SegmentTracker, Segments, segments_of, simulate_segments
from ..mdfsignals import METHOD, MdfSignals, SignalMdfStream, read_signal_mdf
from ..identifier import Identifier, IdentifierError
from ..metrics import json_value
from ..residuals import departure, divergence_range
from ..simulation import Simulation, simulate
from ..simulationstream import Rows, SimulationStream
from ..streamscores import RunningScores
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
                    "write one-step-ahead predictions, metrics (RMSE, absolute deviation) and plots. The record is "
                    "streamed a chunk at a time in every mode (memory does not grow with its length).")
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


def _signal_mdf(args: argparse.Namespace, cf: ConfigFile, streamed: bool
                ) -> tuple[Data | None, MdfSignals | SignalMdfStream]:
    """A signal MDF4 DATA.mf4 on the identifier's grid: read whole, as the arrays a CSV gives (lines:
    samples.csv's), or (``streamed``) opened to be read a block of records at a time (no data yet)."""
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
    if streamed:
        return None, SignalMdfStream(args.data, cf.state_names, cf.input_names, period=period, channels=channels,
                                     partial=bool(args.partial_log))
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


class _Scoring:
    """The metrics' sections as running figures (:mod:`pyrhonn.streamscores`), fed a chunk at a time or the whole
    record at once, to the same figures: one step (over samples >= ``split``, and with a free run over the learnt
    samples ``first``..K-1), the free run and the H-step predictions; each over the valid targets of its rows."""

    def __init__(self, n: int, first: int, split: int, K: int | None, H: int | None) -> None:
        self.first, self.split, self.K, self.H = first, split, K, H
        self.invalid = np.zeros(n, dtype=np.int64)
        self.running: dict[str, RunningScores] = {"one_step": RunningScores(n, deviation=True)}
        if K is not None:
            self.running["one_step_learning"] = RunningScores(n, deviation=True)
            self.running["free_run"] = RunningScores(n)
        if H is not None:
            self.running["steps_ahead"] = RunningScores(n)

    def add(self, k0: int, X: np.ndarray, valid: np.ndarray, one_step: np.ndarray, one_rows: np.ndarray,
            free: np.ndarray | None = None, free_rows: np.ndarray | None = None, ahead: np.ndarray | None = None,
            ahead_rows: np.ndarray | None = None) -> None:
        """Rows k0.. of the record: measurements ``X`` (L, n) float64 and ``valid``, the estimates (L, n) and
        the rows (L,) bool each may be scored on."""
        k = np.arange(k0, k0 + X.shape[0])
        self.invalid += (~valid).sum(axis=0)

        def feed(kind: str, estimate: np.ndarray, rows: np.ndarray) -> None:
            self.running[kind].add(X, estimate.astype(np.float64), valid & rows[:, None])

        feed("one_step", one_step, one_rows & (k >= self.split))
        if self.K is not None:
            assert free is not None and free_rows is not None
            feed("one_step_learning", one_step, one_rows & (k >= self.first) & (k < self.K))
            feed("free_run", free, free_rows & (k >= self.split))
        if self.H is not None:
            assert ahead is not None and ahead_rows is not None
            feed("steps_ahead", ahead, ahead_rows & (k >= max(self.split, self.H)))

    def section(self, kind: str, names: Sequence[str], definition: str) -> dict[str, Any]:
        """One section of metrics.json: per state the RMSE, RRSE and count scored (the one-step ones also the
        absolute deviation and the samples not valid)."""
        running = self.running[kind]
        sc = running.scores()
        deviation = running.absolute_deviation() if kind.startswith("one_step") else None
        states: dict[str, Any] = {}
        for j, name in enumerate(names):
            entry: dict[str, Any] = {"rmse": json_value(sc.rmse[j]), "rrse": json_value(sc.rrse[j]),
                                     "scored": int(sc.scored[j])}
            if sc.missing[j]:
                entry["missing"] = int(sc.missing[j])
            if deviation is not None:
                dev = deviation[j]
                entry["absolute_deviation"] = None if dev is None else json_value(dev)
                entry["invalid_samples"] = int(self.invalid[j])
            states[name] = entry
        return {"definition": definition, "states": states}

    def sections(self, names: Sequence[str], weights: str) -> dict[str, Any]:
        """metrics.json's sections (the free run's without its where-it-went entries)."""
        first, split, K, H = self.first, self.split, self.K, self.H
        out = {"one_step": self.section(
            "one_step", names, f"one step ahead: x̂(k) made at sample k-1 from measured values, against the "
                               f"measurement of sample k, valid targets k >= {split}; weights {weights}")}
        if K is not None:
            out["one_step_learning"] = self.section(
                "one_step_learning", names,
                f"one step ahead over the learnt samples {first}..{K - 1}, weights learning online")
            out["free_run"] = self.section(
                "free_run", names,
                f"free run (parallel model): weights frozen from sample {K}, the network fed its own predictions "
                f"and the measured inputs, against the measurements of samples k >= {split}")
        if H is not None:
            out["steps_ahead"] = self.section(
                "steps_ahead", names,
                f"{H} steps ahead: x̂(k | k-{H}), the network as after learning sample k-{H} fed its own "
                f"predictions for {H - 1} steps, against the measurements of samples k >= {max(split, H)}; "
                f"weights {weights}")
            out["steps_ahead"]["steps"] = H
        return out

    def close(self) -> None:
        for r in self.running.values():
            r.close()


#: what metrics.json says of where a free run leaves the data's range
RANGE_RULE = ("a free run leaves the data's range at the first sample outside [min - span, max + span] of a "
              "state's valid measurements in the file")


def _free_run_entries(section: dict[str, Any], K: int, from_line: int, diverged_line: int | None,
                      left_line: int | None) -> None:
    section["from_sample"] = K
    section["from_line"] = from_line
    section["diverged_at_line"] = diverged_line
    section["left_range_at_line"] = left_line
    section["range"] = RANGE_RULE


class _RangeWatch:
    """Where a free run first leaves the data's range (:func:`pyrhonn.residuals.divergence_range` of the whole
    record's measurements, :func:`pyrhonn.residuals.departure`), found a chunk at a time without holding the
    record: the range of the measurements read so far, widened by its span, lies inside the whole record's
    (the extremes only grow, and so does the span; a state that has not moved yet is widened by nothing), so
    a free-run value inside it is inside the final range. Only the other rows (their line and values) are
    kept, in a temporary file, and tested against the final range after the last chunk."""

    def __init__(self, n: int) -> None:
        self.n = n
        self.lo = np.full(n, np.inf)
        self.hi = np.full(n, -np.inf)
        self._kind = np.dtype([("line", "<i8"), ("x", "<f8", (n,))])
        self._spill: IO[bytes] = tempfile.TemporaryFile()  # noqa: SIM115

    def add(self, X: np.ndarray, valid: np.ndarray, free: np.ndarray, rows: np.ndarray, lines: np.ndarray) -> None:
        """A chunk: measurements ``X`` (L, n) float64 and ``valid``, the free run (L, n), the ``rows`` (L,) bool
        it is watched on, their ``lines``."""
        self.lo = np.minimum(self.lo, np.where(valid, X, np.inf).min(axis=0, initial=np.inf))
        self.hi = np.maximum(self.hi, np.where(valid, X, -np.inf).max(axis=0, initial=-np.inf))
        x = free.astype(np.float64)
        with np.errstate(invalid="ignore", over="ignore"):
            span = self.hi - self.lo  # -inf where nothing was measured yet: every value is kept
            outside = ~np.isfinite(x) | (x < self.lo - span) | (x > self.hi + span)
        keep = rows & outside.any(axis=1)
        if keep.any():
            block = np.empty(int(keep.sum()), dtype=self._kind)
            block["line"] = lines[keep]
            block["x"] = x[keep]
            self._spill.write(block.tobytes())

    def left_line(self) -> int | None:
        """The line of the first row kept outside the whole record's range (None if none)."""
        seen = self.lo <= self.hi
        low, high = divergence_range(np.vstack([np.where(seen, self.lo, 0.0), np.where(seen, self.hi, 0.0)]),
                                     np.vstack([seen, seen]))
        self._spill.seek(0)
        while True:
            raw = self._spill.read(self._kind.itemsize * (1 << 16))
            if not raw:
                return None
            block = np.frombuffer(raw, dtype=self._kind)
            gone = [int(k) for k in departure(np.ascontiguousarray(block["x"]), np.ones(block.size, dtype=bool),
                                              low, high) if k >= 0]
            if gone:
                return int(block["line"][min(gone)])

    def close(self) -> None:
        self._spill.close()


def _shown(v: float | str | None, spec: str = ".6g") -> str:
    return "-" if v is None else str(v) if isinstance(v, str) else format(v, spec)


def _count(k: int, noun: str) -> str:
    return f"{k} {noun}{'' if k == 1 else 's'}"


def _prediction_header(has_t: bool, cf: ConfigFile, kinds: Sequence[str]) -> list[str]:
    """predictions.csv's columns; ``kinds`` the extra columns per state (``free_run``, ``ahead<H>``)."""
    header = ["line"] + ([TIME_COLUMN] if has_t else [])
    for name in cf.state_names:
        header += [f"{name}_hat", f"{name}_err"] + [f"{name}_{kind}" for kind in kinds]
    return header


def _extra(free: np.ndarray | None, ahead: np.ndarray | None, steps: int | None) -> list[tuple[str, np.ndarray]]:
    """The extra columns of predictions.csv: the free run, the H-step predictions (those given)."""
    extra: list[tuple[str, np.ndarray]] = []
    if free is not None:
        extra.append(("free_run", free.astype(np.float64)))
    if ahead is not None:
        extra.append((f"ahead{steps}", ahead.astype(np.float64)))
    return extra


def _prediction_rows(fh: IO[bytes], data: Data, cf: ConfigFile, one_step: np.ndarray,
                     extra: list[tuple[str, np.ndarray]], errors: np.ndarray) -> None:
    """predictions.csv's rows of ``data`` (a chunk, or the whole record) written to ``fh``; ``errors`` (T,)
    bool: the rows whose prediction is a one-step prediction of that row's sample (not row 0, nor the first
    row of a segment after a gap). Every value is written as its shortest round-trip decimal
    (:func:`pyrhonn.csvcodec.format_rows`): it reads back as the same float64."""
    T = data.n_samples
    n = len(cf.state_names)
    hat = one_step.astype(np.float64)
    err = data.X - hat
    lead = 1 + (data.t is not None)
    per_state = 2 + len(extra)
    for a in range(0, T, ROWS_AT_ONCE):  # a block of rows at a time
        rows = slice(a, min(a + ROWS_AT_ONCE, T))
        L = rows.stop - rows.start
        values = np.empty((L, lead + n * per_state))
        show = np.ones(values.shape, dtype=bool)
        values[:, 0] = data.lines[rows]
        if data.t is not None:
            values[:, 1] = data.t[rows]
        for j in range(n):
            c = lead + j * per_state
            values[:, c] = hat[rows, j]
            values[:, c + 1] = err[rows, j]
            show[:, c + 1] = errors[rows] & data.valid[rows, j]
            for i, (_, v) in enumerate(extra):
                values[:, c + 2 + i] = v[rows, j]
        fh.write(format_rows(values, show, integer=[True] + [False] * (values.shape[1] - 1)))


def _write_predictions(path: Path, data: Data, cf: ConfigFile, sim: Simulation, errors: np.ndarray) -> None:
    """predictions.csv of the whole record (see :func:`_prediction_rows`)."""
    with atomic.replacing(path, "wb") as fh:
        extra = _extra(sim.free_run, sim.ahead, sim.steps)
        fh.write(header_line(_prediction_header(data.t is not None, cf, [kind for kind, _ in extra])))
        _prediction_rows(fh, data, cf, sim.one_step, extra, errors)


NOT_VALID_LABEL = "not valid (not learnt; predicted from its own outputs)"  #: legend entry of the shaded samples


#: the series an identify plot draws per state, in the order of the envelope's columns
_KINDS = ("measured", "identified", "error", "free_run", "ahead")


def _envelope(n: int) -> Envelope:
    """The plots' envelope: per state the series of :data:`_KINDS`, and a flag: measurement not valid."""
    return Envelope(len(_KINDS) * n, flags=n)


def _feed(env: Envelope, data: Data, one_step: np.ndarray, k0: int, free: np.ndarray | None = None,
          ahead: np.ndarray | None = None) -> None:
    """Rows k0.. of the record (``data``, a chunk or the whole) into the plots' envelope."""
    T, n = data.X.shape
    x_axis = data.t if data.t is not None else np.arange(k0, k0 + T, dtype=np.float64)
    measured = np.where(data.valid, data.X, np.nan)
    identified = one_step.astype(np.float64)
    if k0 == 0:  # row 0 holds x0, not a prediction
        identified = identified.copy()
        identified[0] = np.nan
    nan = np.full((T, n), np.nan)
    values = np.hstack([measured, identified, measured - identified,
                        nan if free is None else free.astype(np.float64),
                        nan if ahead is None else ahead.astype(np.float64)])
    env.feed(x_axis, values, ~data.valid)


def _plot(path: Path, name: str, j: int, n: int, env: Envelope, has_t: bool, warmup: int, units: dict[str, str],
          free_run_from: int | None = None, steps: int | None = None) -> None:
    """Measured and identified state j over the error: every y axis carries the state's unit
    (``--units``), and the samples whose measurement was not valid are shaded, in the legend. A long
    record is drawn as its min-max envelope (:mod:`pyrhonn.envelope`), said in the title."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    def series(kind: str) -> tuple[np.ndarray, np.ndarray]:
        return env.line(_KINDS.index(kind) * n + j)

    fig = Figure(figsize=(8.0, 5.0), layout="constrained")
    FigureCanvasAgg(fig)
    top, bottom = fig.subplots(2, 1, sharex=True, height_ratios=[3, 1.4])
    dense = env.width == 1
    top.plot(*series("measured"), color="0.15", lw=1.2, marker="." if dense else None, ms=2.5,
             label=f"{name} (measured)")
    top.plot(*series("identified"), color="tab:red", lw=1.0, ls="--", label=f"{name} identified (one step ahead)")
    if steps is not None:
        top.plot(*series("ahead"), color="tab:purple", lw=0.9, ls="-.", label=f"{name} identified ({steps} steps ahead)")
    if free_run_from is not None:
        top.plot(*series("free_run"), color="tab:green", lw=1.1, label=f"{name} free run (weights frozen, own outputs)")
        for ax in (top, bottom):
            ax.axvline(env.x_of(free_run_from), color="tab:green", lw=0.8, ls=":",
                       label="weights frozen from here" if ax is top else None)
    unit = f"[{units[name]}]" if name in units else "(no unit given)"
    top.set_ylabel(f"{name} {unit}")
    top.set_title(f"{name}: real vs identified" if dense else
                  f"{name}: real vs identified ({env.samples:,} samples: each stroke the min and max of {env.width})")
    bottom.plot(*series("error"), color="tab:blue", lw=0.9)
    bottom.axhline(0.0, color="0.6", lw=0.6)
    bottom.set_ylabel(f"error {unit}")
    bottom.set_xlabel((f"t [{units['t']}]" if "t" in units else "t") if has_t else "sample")
    spans = [(a, b - a) for a, b in env.runs(j)]
    if spans:  # runs of not-valid samples, shaded on both axes (one collection each), one legend entry
        for ax in (top, bottom):
            ax.broken_barh(spans, (0, 1), transform=ax.get_xaxis_transform(), color="tab:orange", alpha=0.18,
                           lw=0, zorder=0, label=NOT_VALID_LABEL if ax is top else None)
    if warmup:
        for ax in (top, bottom):
            ax.axvspan(env.x_of(0), env.x_of(min(warmup, env.samples - 1)), color="0.9", lw=0, zorder=0,
                       label="warm-up (not scored)" if ax is top else None)
    top.legend(loc="best" if dense else "upper right", fontsize="small")  # "best" tests every point and span
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


def _check_length(args: argparse.Namespace, T: int, source: str, first_line: int) -> None:
    if T < 2:
        raise ValueError(f"{source}: line {first_line}: only one data row; one-step-ahead "
                         "identification needs at least two")
    if args.warmup >= T - 1:
        raise ValueError(f"--warmup {args.warmup}: leaves nothing to score ({T} data rows give {T - 1} "
                         "one-step-ahead pairs)")


def _report(args: argparse.Namespace, settings: dict[str, str], T: int, ignored: Sequence[str],
            units: dict[str, str] | None, sections: dict[str, Any], next_prediction: np.ndarray, cf: ConfigFile,
            extras: dict[str, Any], gaps: dict[str, Any] | None) -> dict[str, Any]:
    """metrics.json."""
    return {
        "format": "pyrhonn-identify-metrics",
        "version": 2,
        **settings,
        "samples": T,
        "pairs": T - 1,
        "warmup": args.warmup,
        "free_run_from": args.free_run_from,
        "ahead_steps": args.steps_ahead,
        "valid_suffix": args.valid_suffix,
        "ignored_columns": list(ignored),
        **({"units": units} if units else {}),
        "definition": "rmse, rrse (root relative squared error) and absolute_deviation (mean |e - mean e|) as "
                      "in pyrhonn.metrics; 'states' repeats one_step.states",
        "states": sections["one_step"]["states"],
        **sections,
        "next_prediction": {name: float(next_prediction[j]) for j, name in enumerate(cf.state_names)},
        **({"bus": extras["bus"]} if "bus" in extras else {}),
        **({"gaps": gaps} if gaps else {}),
        **({"mdf": extras["mdf"]} if "mdf" in extras else {}),
    }


def _write_rest(out: Path, report: dict[str, Any], plots: list[Path], cf: ConfigFile, env: Envelope, warmup: int,
                units: dict[str, str], free_run_from: int | None = None, steps: int | None = None) -> None:
    """metrics.json and the plots (or, without plots, an earlier run's removed)."""
    atomic.write_text(out / "metrics.json", json.dumps(report, indent=2) + "\n")
    n = len(cf.state_names)
    for j, path in enumerate(plots):
        _plot(path, cf.state_names[j], j, n, env, env.has_t, warmup, units, free_run_from, steps)
    for stale in [] if plots else [out / f"{name}.png" for name in cf.state_names]:
        stale.unlink(missing_ok=True)  # an earlier run's plot would pass for this run's


#: run on the record held whole (simulate over all of it; the reference a streamed run equals, for tests)
_WHOLE_RECORD = False
#: cut every chunk read into pieces of at most this many rows (None: as read; for tests of where chunks fall)
_PIECE_ROWS: int | None = None

#: rows of a record held in memory as one chunk when it is streamed (a record read whole is cut so)
CHUNK_ROWS = 1 << 16


def _pieces(data: Data, rows: int = CHUNK_ROWS) -> Iterator[Data]:
    """``data`` as chunks of ``rows`` rows (views)."""
    for a in range(0, data.n_samples, rows):
        yield _slice(data, a, min(a + rows, data.n_samples))


class _Staged:
    """predictions.csv written while the record streams: to an anonymous scratch file (in the output
    folder, or the nearest folder above it that exists; gone with the process, however it ends), copied
    into place by :meth:`commit` inside the output folder's block (:mod:`pyrhonn.atomic`)."""

    def __init__(self, target: Path) -> None:
        self.target = target
        folder = target.parent
        while not folder.is_dir() and folder != folder.parent:
            folder = folder.parent
        self.folder = folder
        self.fh: Any = None

    def __enter__(self) -> _Staged:
        self.fh = tempfile.TemporaryFile("w+b", dir=self.folder)
        return self

    def commit(self, header: bytes = b"", drop_last_column: bool = False) -> None:
        """The file in place: ``header``, then the rows staged (each without its last column, ``,0``, if
        ``drop_last_column``)."""
        self.fh.flush()
        self.fh.seek(0)
        with atomic.replacing(self.target, "wb") as out:
            out.write(header)
            if not drop_last_column:
                shutil.copyfileobj(self.fh, out, 1 << 22)
                return
            for block in iter(lambda: self.fh.readlines(1 << 22), []):
                out.write(b"".join(line[:line.rindex(b",")] + b"\n" for line in block))

    def __exit__(self, *exc: Any) -> None:
        if self.fh is not None:
            self.fh.close()


@dataclass
class _Streamed:
    """What :func:`_stream` found: the samples, metrics' sections, x̂(T), the gaps, the plots' envelope, the file's
    units, the line where the free run diverged."""

    T: int
    sections: dict[str, Any]
    next_prediction: np.ndarray
    segments: SegmentTracker
    env: Envelope
    units: dict[str, str] | None
    diverged_line: int | None


def _stream(args: argparse.Namespace, cf: ConfigFile, cfg: IdentifierConfig, source: str, config_source: str,
            chunks: Iterable[Data], staged: _Staged, plots: bool) -> _Streamed:
    """The identification of a record a chunk at a time (:class:`pyrhonn.simulationstream.SimulationStream`: the
    one-step pass, the free run and the H-step branches carried across chunks, so the result is the whole
    record's): predictions.csv written to ``staged`` as the rows are finished, the metrics as running sums
    (:class:`_Scoring`), the gaps found chunk by chunk (:class:`pyrhonn.gaps.SegmentTracker`), where the free
    run leaves the data's range (:class:`_RangeWatch`) and the plots' envelope (:mod:`pyrhonn.envelope`).
    The settings that need the record's length are checked at its end, with the messages of the record held
    whole; so is a failure of the identifier, which ends the stepping but not the reading."""
    try:
        ident = Identifier(cfg)
    except ValueError as exc:
        raise ValueError(f"{config_source}: {exc}") from None
    n = cfg.n_states
    names = tuple(cf.state_names)
    K, H = args.free_run_from, args.steps_ahead
    engine = SimulationStream(ident, free_run_from=K, steps=H)
    tracker = SegmentTracker(names)
    env = _envelope(n)
    for k in (0, args.warmup, *([K] if K is not None else [])):
        env.mark(k)
    first = args.warmup + 1  # row 0 holds x0, not a prediction; --warmup drops that many pairs more
    split = max(first, K) if K is not None else first
    kinds = (["free_run"] if K is not None else []) + ([f"ahead{H}"] if H is not None else [])
    read = 0  # rows read
    first_line = 0
    units: dict[str, str] | None = None
    held: list[Data] = []  # rows read, not yet finished
    marks: dict[str, int | None] = {"from_line": None, "diverged_line": None}
    stopped: ValueError | None = None  # the identifier's failure, said after the record's length is known
    scoring = _Scoring(n, first, split, K, H)
    watch = _RangeWatch(n) if K is not None else None

    def finished(rows: Rows | None) -> None:
        nonlocal held
        if rows is None:
            return
        L = rows.n_rows
        joined = held[0] if len(held) == 1 else concatenate(held)
        c, rest = _slice(joined, 0, L), _slice(joined, L, joined.n_samples)
        held = [rest] if rest.n_samples else []
        k0 = rows.k0
        k = np.arange(k0, k0 + L)
        one_rows = rows.stepped & ~rows.starts  # not the first of a segment: its x̂ was made before the gap
        free_rows = None
        if K is not None:
            assert rows.free_rows is not None and rows.free_run is not None and watch is not None
            free_rows = rows.free_rows & (one_rows | (k == K))
            if k0 <= K < k0 + L:
                marks["from_line"] = int(c.lines[K - k0])
            watch.add(c.X, c.valid, rows.free_run, free_rows & (k >= K), c.lines)
        d = engine.free_run_diverged
        if d is not None and k0 <= d < k0 + L:
            marks["diverged_line"] = int(c.lines[d - k0])
        _prediction_rows(staged.fh, c, cf, rows.one_step, _extra(rows.free_run, rows.ahead, H), one_rows)
        scoring.add(k0, c.X, c.valid, rows.one_step, one_rows, rows.free_run, free_rows, rows.ahead, rows.ahead_rows)
        if plots:
            _feed(env, c, rows.one_step, k0, rows.free_run, rows.ahead)

    def stepped(c: Data | None, step_rows: np.ndarray | None = None) -> None:
        """Chunk ``c`` into the identification (None: the end of the record); a defect it finds (a value that
        overflows the dtype, the identifier's failure) ends the stepping, said after the record's length."""
        nonlocal stopped
        if stopped is not None:
            return
        try:
            if c is None:
                finished(engine.finish())
                return
            assert step_rows is not None
            X, U = c.in_dtype(cfg.dtype, cf.state_names, cf.input_names, source)
            held.append(replace(c, lost=None))  # the gaps are the tracker's (a chunk may have no lost flags)
            finished(engine.feed(X, U, c.valid, step_rows))
        except IdentifierError as exc:
            found = re.search(r"at sample (\d+)", str(exc))
            where = ""
            if found:
                at = int(found.group(1))
                lines = np.concatenate([h.lines for h in held]) if held else np.zeros(0, dtype=np.int64)
                base = read - lines.size
                where = f"line {int(lines[at - base])}: " if 0 <= at - base < lines.size else ""
            stopped = ValueError(f"{source}: {where}the identifier stopped: {exc}")
            held.clear()
        except ValueError as exc:
            stopped = exc
            held.clear()

    try:
        for c in chunks:
            L = c.n_samples
            if read == 0:
                first_line, units = int(c.lines[0]), c.units
                env.has_t = c.t is not None
                staged.fh.write(header_line(_prediction_header(c.t is not None, cf, kinds)))
            lost = c.lost if c.lost is not None else np.zeros(L, dtype=bool)
            step_rows, _ = tracker.feed(lost, c.valid, c.lines, c.t)
            read += L
            stepped(c, step_rows)
        tracker.finish()
        stepped(None)
        T = read
        _check_length(args, T, source, first_line)
        _check_settings(args, T)
        if stopped is not None:
            raise stopped
        weights = "online" if K is None else f"frozen from sample {K}"
        sections = scoring.sections(names, weights)
        if K is not None:
            assert watch is not None and marks["from_line"] is not None
            _free_run_entries(sections["free_run"], K, marks["from_line"], marks["diverged_line"], watch.left_line())
    finally:
        scoring.close()
        if watch is not None:
            watch.close()
    return _Streamed(T=T, sections=sections, next_prediction=engine.next_prediction, segments=tracker, env=env,
                     units=units, diverged_line=marks["diverged_line"])


def _slice(data: Data, a: int, b: int) -> Data:
    """Rows a..b-1 of ``data`` (views)."""
    return Data(X=data.X[a:b], U=data.U[a:b], valid=data.valid[a:b], t=None if data.t is None else data.t[a:b],
                lines=data.lines[a:b], ignored=data.ignored, lost=None if data.lost is None else data.lost[a:b],
                units=data.units)


def _check_settings(args: argparse.Namespace, T: int) -> None:
    """The settings that need the record's length (``T`` rows)."""
    K = args.free_run_from
    if K is not None and K >= T:
        raise ValueError(f"--free-run-from {K}: beyond the data ({T} rows, samples 0..{T - 1})")
    if K is not None and args.warmup + 1 >= T:
        raise ValueError(f"--warmup {args.warmup}: leaves nothing to score")
    if args.steps_ahead is not None and args.steps_ahead >= T:
        raise ValueError(f"--steps-ahead {args.steps_ahead}: needs more than {args.steps_ahead} data rows, "
                         f"the file has {T}")


def _cut(chunks: Iterable[Data], rows: int | None) -> Iterator[Data]:
    """``chunks`` cut into pieces of at most ``rows`` rows (None: as they come)."""
    for c in chunks:
        if rows is None:
            yield c
            continue
        for a in range(0, c.n_samples, rows):
            yield _slice(c, a, min(a + rows, c.n_samples))


def run(args: argparse.Namespace) -> int:
    cf = load_named(args.config)
    config_source = args.config
    bus_input.check_options(args)
    bus = None
    if args.can_log is not None:  # the log streamed (or read whole where it cannot be)
        bus = (bus_input.read if _WHOLE_RECORD else bus_input.stream)(args, cf, config_source)
    try:
        return _run(args, cf, config_source, bus)
    except Reread:  # what the log read whole says (a refusal, in its own words), or its results
        return _run(args, cf, config_source, bus_input.read(args, cf, config_source))


def _drain(chunks: Iterable[Data]) -> None:
    """The rest of a streamed bus log read (nothing kept): its own refusal, found at its end, comes before any
    other error, as when the log is read whole before anything else is done."""
    for _ in chunks:
        pass


def _samples_rows(chunks: Iterable[Data], fh: IO[bytes], cf: ConfigFile, lost_column: bool = True) -> Iterator[Data]:
    """``chunks`` passed on, their rows written to ``fh`` as samples.csv's (with the ``lost`` column or not)."""
    for c in chunks:
        for text in data_rows(c, cf, lost_column=lost_column):
            fh.write(text)
        yield c


def _mdf_chunks(m: SignalMdfStream) -> Iterator[Data]:
    """A streamed signal MDF4's grid as data chunks (lines: samples.csv's)."""
    k0 = 0
    for t, X, valid, U in m.chunks(CHUNK_ROWS):
        L = t.shape[0]
        yield Data(X=X, U=U, valid=valid, t=t, lines=np.arange(k0 + 2, k0 + L + 2, dtype=np.int64), ignored=(),
                   units=m.units)
        k0 += L


def _run(args: argparse.Namespace, cf: ConfigFile, config_source: str, bus: bus_input.BusInput | None) -> int:
    streaming = not _WHOLE_RECORD
    mdf = _signal_mdf(args, cf, streaming) if bus is None and Path(args.data).suffix.lower() == ".mf4" else None
    mdf_stream = mdf[1] if mdf is not None and not isinstance(mdf[1], MdfSignals) else None
    streamed = bus.stream if bus is not None else None
    source = bus.source if bus else args.data
    try:
        if bus and (args.csv_sep is not None or args.decimal is not None):
            raise ValueError(f"{'--csv-sep' if args.csv_sep is not None else '--decimal'}: only for a CSV file, not "
                             "with --can-log")
        whole = bus.data if bus else mdf[0] if mdf else None
        reader = None if whole is not None or streamed is not None or mdf_stream is not None else DataReader(
            source, cf, valid_suffix=args.valid_suffix, config_source=config_source, sep=args.csv_sep,
            decimal=args.decimal, allow_lost=True, block_bytes=BLOCK_BYTES)
        file_units = (whole.units if whole is not None else reader.units if reader is not None else
                      mdf_stream.units if mdf_stream is not None else None)
        ignored = whole.ignored if whole is not None else reader.ignored if reader is not None else ()
        units = {**{k: v for k, v in (file_units or {}).items() if k in cf.state_names or k == TIME_COLUMN},
                 **args.units}  # --units over the file's unit row
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
    except ValueError:
        if streamed is not None:
            _drain(streamed.chunks())
        raise
    dtype = args.dtype or cf.config.dtype
    cfg = cf.config if dtype == cf.config.dtype else cf.config.replace(dtype=dtype)
    K = args.free_run_from
    settings = {"data": str(source), "config": config_source, "dtype": dtype}
    segs: SegmentTracker | Segments | None
    sections: dict[str, Any]
    if streaming:  # a chunk at a time
        with _Staged(out / "predictions.csv") as staged, _Staged(out / bus_input.SAMPLES) as staged_samples:
            chunks = (_samples_rows(streamed.chunks(), staged_samples.fh, cf) if streamed is not None else
                      _samples_rows(_mdf_chunks(mdf_stream), staged_samples.fh, cf, lost_column=False)
                      if mdf_stream is not None else
                      _pieces(whole) if whole is not None else reader.chunks() if reader is not None else iter(()))
            try:
                got = _stream(args, cf, cfg, source, config_source, _cut(chunks, _PIECE_ROWS), staged,
                              plots=bool(plots))
            except ValueError:
                if streamed is not None:
                    _drain(chunks)
                raise
            T, sections, segs, env = got.T, got.sections, got.segments, got.env
            extras = {**({"bus": bus.report()} if bus else {}), **({"mdf": mdf[1].report()} if mdf else {})}
            gaps = segs.report() if segs.gap_count else None
            report = _report(args, settings, T, ignored, got.units, sections, got.next_prediction, cf, extras, gaps)
            with atomic.output_folder(out, "pyrhonn identify"):  # marked INCOMPLETE until every file is in place
                if whole is not None:
                    write_data(out / bus_input.SAMPLES, whole, cf, valid_suffix=args.valid_suffix)
                elif streamed is not None:  # the rows as written, without the lost column if nothing was lost
                    staged_samples.commit(header_line(data_columns(True, cf, args.valid_suffix, segs.gap_count > 0)),
                                          drop_last_column=not segs.gap_count)
                elif mdf_stream is not None:
                    staged_samples.commit(header_line(data_columns(True, cf, args.valid_suffix, False)))
                staged.commit()
                _write_rest(out, report, plots, cf, env, args.warmup, units, free_run_from=K, steps=args.steps_ahead)
        diverged_line = got.diverged_line
    else:  # the record held whole: the reference the streamed run equals
        extras = {**({"bus": bus.report()} if bus else {}), **({"mdf": mdf[1].report()} if mdf else {})}
        data = whole if whole is not None else concatenate(list(reader.chunks())) if reader is not None else None
        assert data is not None
        T = data.n_samples
        _check_length(args, T, source, int(data.lines[0]))
        _check_settings(args, T)
        wsegs = segments_of(data.lost) if data.lost is not None and data.lost.any() else None
        sim, free_rows, ahead_rows = _run_identifier(cfg, data, cf, source, config_source, K, args.steps_ahead, wsegs)
        # one-step rows: stepped, and not the first of a segment (its x̂ was made for a sample before the gap)
        one_rows = np.arange(T) > 0 if wsegs is None else wsegs.stepped & ~wsegs.starts()
        if wsegs is not None and free_rows is not None:
            free_rows &= one_rows | (np.arange(T) == K)
        first = args.warmup + 1  # row 0 holds x0, not a prediction; --warmup drops that many pairs more
        split = max(first, K) if K is not None else first
        every = np.ones(T, dtype=bool)
        scoring = _Scoring(cf.config.n_states, first, split, K, args.steps_ahead)
        try:
            scoring.add(0, data.X, data.valid, sim.one_step, one_rows, sim.free_run,
                        None if K is None else every if free_rows is None else free_rows, sim.ahead,
                        None if args.steps_ahead is None else every if ahead_rows is None else ahead_rows)
            sections = scoring.sections(cf.state_names, "online" if K is None else f"frozen from sample {K}")
        finally:
            scoring.close()
        diverged_line = (None if sim.free_run_diverged is None or sim.free_run_diverged >= T
                         else int(data.lines[sim.free_run_diverged]))
        if K is not None:
            assert sim.free_run is not None
            low, high = divergence_range(data.X, data.valid)
            rows = np.zeros(T, dtype=bool)
            rows[K:] = True
            if free_rows is not None:
                rows &= free_rows
            left = departure(sim.free_run.astype(np.float64), rows, low, high)
            gone = [int(k) for k in left if k >= 0]
            _free_run_entries(sections["free_run"], K, int(data.lines[K]), diverged_line,
                              None if not gone else int(data.lines[min(gone)]))

        gaps_report = wsegs.report(data.t, data.lines, data.valid, tuple(cf.state_names)) if wsegs else None
        report = _report(args, settings, T, ignored, data.units, sections, sim.next_prediction, cf, extras,
                         gaps_report)
        segs = wsegs
        env = _envelope(cf.config.n_states)
        env.has_t = data.t is not None
        for k in (0, args.warmup, *([K] if K is not None else [])):
            env.mark(k)
        if plots:
            _feed(env, data, sim.one_step, 0, sim.free_run, sim.ahead)
        with atomic.output_folder(out, "pyrhonn identify"):  # marked INCOMPLETE until every file is in place
            if bus or mdf:
                write_data(out / bus_input.SAMPLES, data, cf, valid_suffix=args.valid_suffix)
            _write_predictions(out / "predictions.csv", data, cf, sim, one_rows)
            _write_rest(out, report, plots, cf, env, args.warmup, units, free_run_from=K, steps=args.steps_ahead)

    print(f"identified {source}: {T} samples, {_count(cfg.n_states, 'state')}, {_count(cfg.n_inputs, 'input')}, "
          f"config {config_source}, {dtype}")
    if ignored:
        print("ignored columns: " + ", ".join(ignored))
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
    if segs is not None and segs.gap_count:
        print(f"gaps: {segs.lost} lost samples in {_count(segs.gap_count, 'gap')}; {segs.gap_count} not stepped after "
              f"them, {_count(segs.restarts, 'restart')}; {_count(segs.segment_count, 'segment')} "
              f"({', '.join(str(k) for k in segs.first_sizes(8))}{' ...' if segs.segment_count > 8 else ''} samples)")
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
    if K is not None and diverged_line is not None:
        print(f"the free run diverged at line {diverged_line} (its prediction was not "
              f"finite in {dtype}): its errors are inf")
    elif K is not None and sections["free_run"]["left_range_at_line"] is not None:
        print(f"the free run left the data's range at line {sections['free_run']['left_range_at_line']} (beyond "
              "each state's measured range widened by its span): a model that does not simulate")
    print("wrote " + ", ".join(str(p) for p in written))
    return 0
