"""``pyrhonn identify --can-log RUN --dbc FILE``: a bus recording instead of a CSV file.

The options of :func:`add_options` say where each state and input is on the
bus (on top of the config's ``[bus]`` table, :mod:`pyrhonn.buslog`);
:func:`read` decodes and aligns the log into the arrays a CSV file gives, and
:func:`stream` into chunks of them (:mod:`pyrhonn.buslogstream`), so
``identify`` runs and writes exactly as for a CSV, plus ``samples.csv``: the
aligned samples in the CSV format (``pyrhonn identify``, ``tune --data`` and
``select`` read it; the ``line`` column of the predictions refers to it).
"""
from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..buslog import LOG_SUFFIXES, AlignedSummary, BusMap, SignalRef, read_bus_log
from ..buslogstream import BusStream, Reread
from ..configfile import ConfigFile
from ..datafile import Data
from .options import real_option

__all__ = ["BusInput", "SAMPLES", "add_options", "read", "stream"]

#: the aligned samples, written beside the predictions
SAMPLES = "samples.csv"

_HELP = (
    "Read the states and inputs from a CAN log (.blf, .asc: python-can's can.Logger; .log: candump -l; "
    ".mf4: an MDF4 bus log) "
    "with a DBC, instead of DATA.csv. The config's [bus] table (or --signal) maps every state and input to "
    "a DBC signal \"Message.Signal\"; each frame of the clock message is one sample (numbered by its "
    "--counter if it has one). Missing and late "
    "messages are never invented: a state whose message has no frame in a sample's window (lost, or late "
    "into the next window), does not decode, or whose [bus.valid] flag is 0 is a not-valid sample (the "
    "identifier neither learns from it nor feeds it back); the ends of the log without every input are cut "
    "off, and a sample inside the run without every input is a lost sample: the record splits there into "
    "segments as the firmware does (the sample after the gap is not stepped, the identifier restarts on the "
    "next; every gap counted). Writes samples.csv (the aligned samples, in the "
    "CSV format) beside the usual outputs.")


def add_options(p: argparse.ArgumentParser) -> None:
    """The bus-log options of ``pyrhonn identify``."""
    g = p.add_argument_group("bus recording (instead of DATA.csv)", _HELP)
    g.add_argument("--can-log", metavar="RUN.{blf,asc,log,mf4}", help="the bus recording")
    g.add_argument("--dbc", metavar="FILE", help="the DBC that decodes it (required with --can-log)")
    g.add_argument("--signal", action="append", default=[], metavar="NAME=Message.Signal",
                   help="where state or input NAME is on the bus; repeat for each, replaces the config's "
                        "[bus.signals] entry")
    g.add_argument("--sample-period", metavar="S",
                   help="seconds between samples (default: the config's bus.sample_period, else the clock "
                        "message's cycle time in the DBC)")
    g.add_argument("--clock", metavar="MESSAGE",
                   help="the message whose frames are the samples (default: the config's bus.clock, else the "
                        "message of the first state)")
    g.add_argument("--counter", metavar="Message.Signal",
                   help="the clock message's sequence counter, which numbers the samples (default: the config's "
                        "bus.counter, else none: lost clock frames are found from the gaps in time)")
    g.add_argument("--partial-log", action="store_true",
                   help="read a recording that was cut short (no ASC 'End TriggerBlock', a BLF shorter than its "
                        "header says or cut inside an object, a cut last line, an MDF4 cut short or not finalised): its "
                        "complete frames or records are used and the report says what is missing; without it such a "
                        "file is refused")
    g.add_argument("--start", metavar="S", help="leave out the samples before S seconds after the first clock frame")
    g.add_argument("--stop", metavar="S", help="leave out the samples after S seconds after the first clock frame")


@dataclass
class BusInput:
    """A bus log read for ``identify``: read whole, its ``data`` as a CSV would give it; or streamed, its
    ``stream`` (:class:`pyrhonn.buslogstream.BusStream`), whose summary is known once it is read."""

    source: str
    dbc: str
    data: Data | None
    summary_whole: AlignedSummary | None = None
    stream: BusStream | None = None

    @property
    def aligned(self) -> AlignedSummary:
        """How the samples were made (of a streamed log: once its last chunk was read)."""
        found = self.summary_whole if self.stream is None else self.stream.summary
        assert found is not None, "the bus log's summary is known once it is read"
        return found

    def report(self) -> dict[str, Any]:
        """The ``bus`` entry of metrics.json: how the samples were made."""
        a = self.aligned
        return {"log": self.source, "dbc": self.dbc, "clock": a.clock, "sample_period": a.sample_period,
                "sample_period_from": a.period_source, "window_start": a.window_start,
                "start_log_time": a.start, "clock_frames": a.clock_frames,
                "samples_inserted_for_lost_clock_frames": a.clock_missing,
                "samples_cut_before": a.cut_start, "samples_cut_after": a.cut_end, "samples_file": SAMPLES,
                "complete": a.incomplete is None, **({"missing": a.incomplete} if a.incomplete else {}),
                "signals": {name: s.as_dict() for name, s in a.stats.items()}}

    def summary(self) -> list[str]:
        """Lines for the terminal: the clock and, per signal, what was not valid."""
        a = self.aligned
        lines = [f"bus: {a.n_samples} samples of {a.clock} every {a.sample_period:.6g} s ({a.period_source}); "
                 f"{a.clock_missing} for lost clock frames, {a.cut_start} cut before and {a.cut_end} after"]
        if a.incomplete:
            lines.insert(0, f"warning: {self.source} is incomplete, read partially (--partial-log): {a.incomplete}")
        for name, s in a.stats.items():
            why = [f"{count} {what}" for count, what in ((s.missing, "without a frame"),
                                                         (s.flagged, "flagged not valid"),
                                                         (s.nonfinite, "not finite")) if count]
            frames = [f"{count} {what}" for count, what in ((s.undecodable, "did not decode"),
                                                            (s.superseded, "superseded by a later one")) if count]
            if why or frames:
                lines.append(f"  {name} ({s.signal}): " + (f"{a.n_samples - s.used} samples not valid: "
                                                            f"{', '.join(why)}" if why else "every sample valid")
                             + (f"; frames: {', '.join(frames)}" if frames else ""))
        return lines


def _bus_map(args: argparse.Namespace, cf: ConfigFile, config_source: str) -> tuple[BusMap, str, str]:
    """The config's [bus] table with the command line's overrides; the names of the period and clock
    settings (for error messages)."""
    base = cf.bus if cf.bus is not None else BusMap()
    if cf.bus is not None:  # name the config file in errors about its entries
        signals = {k: SignalRef(r.message, r.signal, f"{config_source}: {r.origin}") for k, r in base.signals.items()}
        valid = {k: SignalRef(r.message, r.signal, f"{config_source}: {r.origin}") for k, r in base.valid.items()}
    else:
        signals, valid = {}, {}
    names = (*cf.state_names, *cf.input_names)
    for text in args.signal:
        name, sep, ref = text.partition("=")
        option = f"--signal {text}"
        if not sep:
            raise ValueError(f"{option}: expected NAME=Message.Signal")
        if name.strip() not in names:
            raise ValueError(f"{option}: {name.strip()!r} is not one of the states and inputs of {config_source} "
                             f"({', '.join(names)})")
        signals[name.strip()] = SignalRef.parse(ref.strip(), option)
    period = base.sample_period
    period_option = f"{config_source}: bus.sample_period"
    if args.sample_period is not None:
        period = real_option("--sample-period", args.sample_period, positive=True)
        period_option = "--sample-period"
    counter = None if base.counter is None else SignalRef(base.counter.message, base.counter.signal,
                                                          f"{config_source}: {base.counter.origin}")
    if args.counter is not None:
        counter = SignalRef.parse(args.counter.strip(), "--counter")
    clock = base.clock
    clock_option = f"{config_source}: bus.clock"
    if args.clock is not None:
        clock = args.clock.strip()
        clock_option = "--clock"
        if not clock:
            raise ValueError("--clock: empty; give a message name of the DBC")
    return (BusMap(signals=signals, valid=valid, sample_period=period, clock=clock, window_start=base.window_start,
                   counter=counter),
            period_option if period is not None else "--sample-period (or bus.sample_period in the config)",
            clock_option)


def check_options(args: argparse.Namespace) -> None:
    """DATA.csv or --can-log, not both; the bus options only with --can-log."""
    if args.can_log is None:
        signal_mdf = args.data is not None and Path(args.data).suffix.lower() == ".mf4"
        given = [opt for opt, value in (("--dbc", args.dbc), ("--signal", args.signal or None),
                                        ("--sample-period", None if signal_mdf else args.sample_period),
                                        ("--clock", args.clock), ("--counter", args.counter),
                                        ("--start", args.start), ("--stop", args.stop),
                                        ("--partial-log", None if signal_mdf else args.partial_log or None))
                 if value is not None]
        if given:
            also = " or a signal MDF4 DATA.mf4" if given[0] in ("--sample-period", "--partial-log") else ""
            raise ValueError(f"{given[0]}: only with --can-log (a bus recording){also}")
        if args.channel and not signal_mdf:
            raise ValueError("--channel: only with a signal MDF4 DATA.mf4")
        if args.data is None:
            raise ValueError("give DATA.csv, or --can-log RUN.{blf,asc,log,mf4} with --dbc FILE")
        return
    if args.data is not None:
        raise ValueError(f"--can-log: give either DATA.csv ({args.data}) or --can-log, not both")
    if args.channel:
        raise ValueError("--channel: only with a signal MDF4 DATA.mf4 (with --can-log, --signal maps the states)")
    if args.dbc is None:
        raise ValueError("--dbc: required with --can-log (the DBC that decodes the log)")
    if Path(args.can_log).suffix.lower() not in LOG_SUFFIXES:
        raise ValueError(f"--can-log {args.can_log}: unsupported log format {Path(args.can_log).suffix or '(none)'!r}; "
                         f"expected {', '.join(LOG_SUFFIXES)}")


def _window(args: argparse.Namespace) -> tuple[float | None, float | None]:
    start = None if args.start is None else real_option("--start", args.start, nonnegative=True)
    stop = None if args.stop is None else real_option("--stop", args.stop, nonnegative=True)
    if start is not None and stop is not None and not stop > start:
        raise ValueError(f"--stop {args.stop}: must be after --start {args.start}")
    return start, stop


def read(args: argparse.Namespace, cf: ConfigFile, config_source: str) -> BusInput:
    """The log of ``--can-log``, decoded with ``--dbc`` and aligned (ValueError naming the option,
    key, signal or frame on any defect)."""
    bus, period_option, clock_option = _bus_map(args, cf, config_source)
    start, stop = _window(args)
    aligned = read_bus_log(args.can_log, args.dbc, bus, cf.state_names, cf.input_names, start=start, stop=stop,
                           partial=bool(args.partial_log), period_option=period_option, clock_option=clock_option)
    K = aligned.n_samples
    data = Data(X=aligned.X, U=aligned.U, valid=aligned.valid, t=aligned.t,
                lines=np.arange(2, K + 2, dtype=np.int64), ignored=(),  # the lines of samples.csv
                lost=aligned.lost if aligned.lost.any() else None)
    return BusInput(source=str(args.can_log), dbc=str(args.dbc), data=data, summary_whole=aligned)


def stream(args: argparse.Namespace, cf: ConfigFile, config_source: str) -> BusInput:
    """The log of ``--can-log`` to be read a chunk of frames at a time (:mod:`pyrhonn.buslogstream`), or read
    whole (:func:`read`) where it cannot be streamed: the same samples either way, and the same refusals."""
    bus, period_option, clock_option = _bus_map(args, cf, config_source)
    start, stop = _window(args)
    try:
        s = BusStream(args.can_log, args.dbc, bus, cf.state_names, cf.input_names, start=start, stop=stop,
                      partial=bool(args.partial_log), period_option=period_option, clock_option=clock_option)
    except Reread:
        return read(args, cf, config_source)
    return BusInput(source=str(args.can_log), dbc=str(args.dbc), data=None, stream=s)
