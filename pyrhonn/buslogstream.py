"""A bus log read, decoded and aligned a chunk of frames at a time: memory bounded whatever its length.

:class:`BusStream` gives the samples :func:`pyrhonn.buslog.read_bus_log` gives (the same values, lost
samples, cut ends and counts: :func:`pyrhonn.buslog.align`'s rules, the same helpers), as chunks of
:class:`pyrhonn.datafile.Data`, reading the log frame by frame through python-can's readers (candump,
ASC, BLF and MDF4 bus logs alike) and holding only:

- ``chunk_frames`` frames read, sorted by timestamp before they are aligned, and the last
  ``chunk_frames // 4`` of them held back (logs of several channels interleave slightly out of order:
  a frame that comes later in the file but earlier than one already aligned cannot be placed, and the
  log is read whole instead, see :class:`Reread`);
- the frames whose sample is still open: those of the latest clock frame's sample and after it (one
  period of frames, unless the clock message pauses while others go on);
- the samples after the latest one with every input (a stretch without inputs: it becomes lost
  samples if inputs come back, or is cut off at the end of the log); only their times and counts.

What carries over from chunk to chunk: the latest sample's instant (or its counter), the clock frames'
intervals against the sample period (counted, for the period check at the end), the frames of the open
sample, and whether the run has started, the samples held and the signals' counts.

Every refusal is the whole-log read's, word for word: a truncated log (known from its end or its header,
before any frame is aligned) is read to its end without keeping a frame and refused as
:func:`pyrhonn.buslog.read_frames` refuses it; any other defect (a signal the DBC does not have, a message
without frames, a clock whose frames disagree with the sample period, no sample with every input ...)
raises :class:`Reread`, and the caller reads the log whole to say what is wrong as it always did.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Generator, Iterator, Sequence

import numpy as np

from .buslog import (PERIOD_TOLERANCE, AlignedSummary, BusMap, _COUNTS, _count_on, _counter_signal, _counter_values,
                     _decode, _gather, _given_period, _kept, _Log, _plan, _stat_sums, _stats, _tick_on, frame_keys,
                     load_dbc)
from .buslog import latest as buslog_latest
from .datafile import Data
from .framedecode import Payloads

__all__ = ["CHUNK_FRAMES", "BusStream", "Reread"]

#: frames read before they are sorted and aligned
CHUNK_FRAMES = 1 << 15


def _median_inside(counts: list[int], extremes: list[float], N: int, T: float) -> bool:
    """Is the median of N clock intervals within the period's tolerance, as the whole read's check
    (:func:`pyrhonn.buslog._period`) finds it? ``counts``: how many intervals lie below, inside and above
    the tolerance band; ``extremes``: the largest below, the smallest and the largest inside, the
    smallest above. The median is the middle interval (N odd) or the mean of the middle pair: a pair
    inside the band has its mean inside, a pair on one side of it its mean on that side, and a pair
    across two groups is the last of one and the first of the next, extremes both, averaged as
    numpy's median averages them."""
    below, inside, _ = counts

    def value(j: int) -> tuple[int, float | None]:  # (group, the interval where it is an extreme)
        if j < below:
            return 0, extremes[0] if j == below - 1 else None
        if j < below + inside:
            return 1, extremes[1] if j == below else extremes[2] if j == below + inside - 1 else None
        return 2, extremes[3] if j == below + inside else None

    (g1, v1), (g2, v2) = value((N - 1) // 2), value(N // 2)
    if g1 == g2:
        return g1 == 1
    assert v1 is not None and v2 is not None  # adjacent across groups: both are extremes
    med = float(np.median(np.array([v1, v2])))
    return not abs(med - T) > PERIOD_TOLERANCE * T


class Reread(Exception):
    """The streamed read cannot give the whole-log read's result: a defect the whole-log read names (in its
    own words and order), or frames out of time order by more than is held back. Read the log whole."""


class _Frames:
    """Frames in time order: ``t``, message ``key`` (:func:`pyrhonn.buslog.frame_keys`), ``data``."""

    def __init__(self, t: np.ndarray, key: np.ndarray, data: Payloads) -> None:
        self.t, self.key, self.data = t, key, data

    @classmethod
    def empty(cls) -> _Frames:
        return cls(np.zeros(0), np.zeros(0, dtype=np.int64), Payloads.of([]))

    def take(self, rows: np.ndarray) -> _Frames:
        return _Frames(self.t[rows], self.key[rows], self.data.take(rows))

    def __add__(self, other: _Frames) -> _Frames:
        return _Frames(np.r_[self.t, other.t], np.r_[self.key, other.key], Payloads.join([self.data, other.data]))

    def __len__(self) -> int:
        return int(self.t.size)


class BusStream:
    """The samples of the bus log ``log`` (decoded with the DBC file ``dbc``, aligned as ``bus`` says) as
    chunks (:meth:`chunks`); :attr:`summary` after the last. ``chunk_frames``: frames read at once
    (default :data:`CHUNK_FRAMES`).
    Raises :class:`Reread` where the log must be read whole (see the module docs), and the whole-log
    read's ValueError for a DBC, a log or a truncation it refuses before reading any frame."""

    def __init__(self, log: str | Path, dbc: str | Path, bus: BusMap, state_names: Sequence[str],
                 input_names: Sequence[str], *, start: float | None = None, stop: float | None = None,
                 partial: bool = False, chunk_frames: int | None = None, **options: str) -> None:
        chunk_frames = CHUNK_FRAMES if chunk_frames is None else chunk_frames
        if chunk_frames < 1:
            raise ValueError(f"chunk_frames: must be >= 1, got {chunk_frames}")
        self.db = load_dbc(dbc, options.get("dbc_option", "--dbc"))
        self.log = _Log(log, options.get("log_option", "--can-log"), partial)
        self.source, self.dbc = str(log), str(dbc)
        self.bus, self.start, self.stop, self.chunk = bus, start, stop, chunk_frames
        self.input_names = list(input_names)
        try:
            self.plan = _plan(self.db, bus, state_names, input_names, self.dbc,
                              options.get("clock_option", "bus.clock"))
            given = _given_period(self.plan.clock_msg, bus, options.get("period_option", "bus.sample_period"),
                                  self.dbc)
            self.counter = None if bus.counter is None else _counter_signal(self.db, bus.counter, self.plan.clock_msg,
                                                                            self.dbc)
        except ValueError:
            raise Reread from None
        if given is None:
            raise Reread
        self.T, self.period_source = given
        self.summary: AlignedSummary | None = None
        #: the most frames held at once (read and not yet aligned), for the bound on memory
        self.peak_frames = 0

    # -- reading ---------------------------------------------------------------------------------------

    def _sorted(self) -> Iterator[_Frames]:
        """The log's frames of the messages used, in time order, a chunk at a time; the log's own refusals."""
        keys = sorted({self.plan.key(m) for m in self.plan.used_msgs.values()})
        held = _Frames.empty()
        emitted = -np.inf  # the latest frame aligned
        hold = max(self.chunk // 4, 1)
        frames = 0
        latest = -np.inf
        blocks = self.log.blocks(self.chunk)
        done = False
        while not done:
            block = next(blocks, None)
            done = block is None or len(block) < self.chunk
            if block is not None and len(block):
                top = buslog_latest(block.t)
                latest = top if frames == 0 else buslog_latest(np.array([latest, top]))
                frames += len(block)
                if self.log.incomplete and not self.log.partial:
                    block = None  # refused at the end, as the whole read refuses it: nothing kept
            fresh = _Frames.empty()
            watermark = np.inf if done else -np.inf
            if block is not None and len(block):
                ts = block.t
                if not np.isfinite(ts).all():
                    raise Reread  # a timestamp the whole read names
                key = frame_keys(block.ids, block.extended)
                used = np.isin(key, keys)
                fresh = _Frames(ts[used], key[used], block.data.take(used))
                if fresh.t.size and fresh.t.min() < emitted:
                    raise Reread  # a frame earlier than one aligned: further out of order than is held back
                if not done:
                    watermark = float(ts[-hold:].min())
            both = held + fresh
            self.peak_frames = max(self.peak_frames, len(both))
            both = both.take(np.argsort(both.t, kind="stable"))
            out = both.t < watermark
            if out.any():
                emitted = float(both.t[out][-1])
                yield both.take(out)
            held = both.take(~out)
        self.log.check_read(frames, latest)
        self.latest = latest

    # -- aligning --------------------------------------------------------------------------------------

    def chunks(self) -> Iterator[Data]:
        """The aligned samples, a chunk at a time (lines: those of samples.csv, from 2)."""
        plan, bus, T = self.plan, self.bus, self.T
        n = plan.n
        aT = bus.window_start * T
        clock_key = plan.key(plan.clock_msg)
        value_msgs = plan.value_msgs()
        clock_values = plan.clock_msg.name in value_msgs
        other_keys = {plan.key(m): m.name for m in value_msgs.values() if m.name != plan.clock_msg.name}
        seen = {name: False for name in plan.used_msgs}
        key_name = {plan.key(m): m.name for m in plan.used_msgs.values()}
        modulus = 0 if self.counter is None else 1 << int(self.counter[1].length)
        tau = np.zeros(0)  # instants of the open samples, s_done..known-1
        s_done = 0
        known = 0
        last_tau = 0.0
        last_count: tuple[int, int, float] | None = None
        tau0: float | None = None
        prev_tc: float | None = None
        intervals = np.zeros(3, dtype=np.int64)  # clock intervals below, inside, above the period's tolerance
        # and the extremes of those groups (the largest below, the smallest and largest inside, the smallest
        # above): the only intervals a median whose middle pair straddles two groups can be made of
        extremes = [-math.inf, math.inf, -math.inf, math.inf]
        clock_frames = 0
        inserted = 0
        pend_clock_sample = np.zeros(0, dtype=np.int64)
        pend_clock = _Frames.empty()
        pend = _Frames.empty()  # frames of the other value messages, not yet in a closed sample
        cols = len(plan.names)
        run = _Run(self, n, cols)
        for chunk in self._sorted():
            for k in np.unique(chunk.key).tolist():
                seen[key_name[int(k)]] = True
            is_clock = chunk.key == clock_key
            if is_clock.any():
                clocks = chunk.take(is_clock)
                tc = clocks.t
                clock_frames += tc.size
                steps = np.diff(tc) if prev_tc is None else np.diff(np.r_[prev_tc, tc])
                prev_tc = float(tc[-1])
                dev = np.abs(steps - T) > PERIOD_TOLERANCE * T
                intervals += [int((dev & (steps < T)).sum()), int((~dev).sum()), int((dev & (steps > T)).sum())]
                for group, pick, at in ((dev & (steps < T), np.max, 0), (~dev, np.min, 1), (~dev, np.max, 2),
                                        (dev & (steps > T), np.min, 3)):
                    if group.any():
                        value = float(pick(steps[group]))
                        extremes[at] = max(extremes[at], value) if pick is np.max else min(extremes[at], value)
                if self.counter is None:
                    if tau0 is None:
                        tau0 = last_tau = float(tc[0])
                        new, sample, more = _tick_on(tc[1:], T, last_tau)
                        new, sample = [tau0, *new], np.r_[np.int64(0), sample]
                    else:
                        new, sample, more = _tick_on(tc, T, last_tau)
                        sample = sample + (known - 1)
                    if new:
                        last_tau = float(new[-1])
                    new_tau = np.asarray(new, dtype=np.float64)
                else:
                    assert bus.counter is not None
                    try:
                        counts = _counter_values(bus.counter, *self.counter, tc, clocks.data, self.source)
                    except ValueError:
                        raise Reread from None
                    if last_count is None:
                        tau0 = float(tc[0])
                        last_count = (int(counts[0]), 0, tau0)
                        rest, sample, more, last_count = _count_on(tc[1:], counts[1:], modulus, last_count)
                        new_tau, sample = np.r_[tau0, rest], np.r_[np.int64(0), sample]
                    else:
                        new_tau, sample, more, last_count = _count_on(tc, counts, modulus, last_count)
                inserted += more
                tau = np.r_[tau, new_tau]
                known += new_tau.size
                if clock_values:
                    pend_clock = pend_clock + clocks
                    pend_clock_sample = np.r_[pend_clock_sample, sample]
            others = np.isin(chunk.key, list(other_keys))
            if others.any():
                pend = pend + chunk.take(others)
            if tau0 is None:  # no sample yet: a frame more than two periods before the latest cannot count
                if len(pend):
                    pend = pend.take(pend.t >= pend.t[-1] - 2 * T)
                continue
            close = known - 1
            if close > s_done:
                starts = tau + aT
                s_done, tau, pend, pend_clock, pend_clock_sample = yield from run.close(
                    s_done, close, tau, starts, None, pend, pend_clock, pend_clock_sample, other_keys, tau0)
            self.peak_frames = max(self.peak_frames, len(pend) + len(pend_clock))
        if tau0 is None or not all(seen[plan.resolved[name][0].name] for name in plan.names):
            raise Reread  # no frame of a message (or none of the clock): the whole read names which
        if clock_frames > 1 and not _median_inside(intervals.tolist(), extremes, clock_frames - 1, T):
            raise Reread
        starts = tau + aT
        end = float(starts[-1] + T)
        s_done, tau, pend, pend_clock, pend_clock_sample = yield from run.close(
            s_done, known, tau, starts, end, pend, pend_clock, pend_clock_sample, other_keys, tau0)
        yield from run.finish()
        self.summary = AlignedSummary(
            start=tau0, clock=plan.clock_msg.name, sample_period=T, period_source=self.period_source,
            window_start=bus.window_start, clock_frames=clock_frames, clock_missing=inserted,
            cut_start=run.cut_start, cut_end=run.cut_end, stats=_stats(plan, bus, run.sums),
            n_samples=run.emitted, incomplete=self.log.missing(self.latest))


class _Run:
    """The stretch of samples kept (see :func:`pyrhonn.buslog.align`): the samples before the first with
    every input cut off, those after the latest held until another comes (lost samples) or the log ends
    (cut off); the signals' counts over the samples kept."""

    def __init__(self, stream: BusStream, n: int, cols: int) -> None:
        self.s = stream
        self.n = n
        self.cut_start = 0
        self.cut_end = 0
        self.started = False
        self.emitted = 0
        self.sums = np.zeros((7, cols), dtype=np.int64)
        self.held_t: list[np.ndarray] = []
        self.held_sums = np.zeros((7, cols), dtype=np.int64)

    def close(self, s_done: int, close: int, tau: np.ndarray, starts: np.ndarray, end: float | None,
              pend: _Frames, pend_clock: _Frames, pend_clock_sample: np.ndarray, other_keys: dict[int, str],
              tau0: float) -> Generator[Data, None, tuple[int, np.ndarray, _Frames, _Frames, np.ndarray]]:
        """Samples s_done..close-1 decoded, gathered and kept or held; returns the open state that remains."""
        plan = self.s.plan
        K = close - s_done
        decoded: dict[str, tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]] = {}
        done_clock = pend_clock_sample < close
        if plan.clock_msg.name in plan.value_msgs():
            window = pend_clock_sample[done_clock] - s_done
            ok, arrays = _decode(plan.clock_msg, pend_clock.take(done_clock).data,
                                 plan.used_sigs[plan.clock_msg.name])
            decoded[plan.clock_msg.name] = (window, ok, arrays)
        limit = end if end is not None else float(starts[close - s_done])
        inside = (pend.t >= starts[0]) & (pend.t < limit)
        gone = pend.t < limit
        for k, name in other_keys.items():
            rows = inside & (pend.key == k)
            window = np.searchsorted(starts, pend.t[rows], side="right") - 1
            ok, arrays = _decode(plan.value_msgs()[name], pend.take(rows).data, plan.used_sigs[name])
            decoded[name] = (window, ok, arrays)
        value, got, counts = _gather(plan, decoded, K)
        yield from self._keep(tau[:K] - tau0, value, got, counts)
        return (close, tau[K:], pend.take(~gone), pend_clock.take(~done_clock), pend_clock_sample[~done_clock])

    def _keep(self, t_all: np.ndarray, value: np.ndarray, got: np.ndarray,
              counts: dict[str, np.ndarray]) -> Iterator[Data]:
        n = self.n
        have = _kept(t_all, self.s.start, self.s.stop) & got[:, n:].all(axis=1)
        if not self.started:
            if not have.any():
                self.cut_start += t_all.size
                return
            i = int(np.argmax(have))
            self.cut_start += i
            self.started = True
            t_all, value, got, have = t_all[i:], value[i:], got[i:], have[i:]
            counts = {k: v[i:] for k, v in counts.items()}
        if not have.any():
            self._hold(t_all, counts)
            return
        j = t_all.size - int(np.argmax(have[::-1]))  # after the last sample with every input
        if self.held_t:  # the samples held were lost samples inside the run
            t_held = np.concatenate(self.held_t)
            cols = value.shape[1]
            yield self._data(t_held, np.full((t_held.size, cols), np.nan), np.zeros((t_held.size, cols), dtype=bool),
                             np.ones(t_held.size, dtype=bool))
            self.sums += self.held_sums
            self.held_t, self.held_sums = [], np.zeros_like(self.held_sums)
        lost = ~have[:j]
        v, g = value[:j].copy(), got[:j].copy()
        v[lost] = np.nan
        g[lost] = False
        self.sums += _stat_sums({k: c[:j] for k, c in counts.items()}, g)
        yield self._data(t_all[:j], v, g, lost)
        if j < t_all.size:
            self._hold(t_all[j:], {k: c[j:] for k, c in counts.items()})

    def _hold(self, t_all: np.ndarray, counts: dict[str, np.ndarray]) -> None:
        self.held_t.append(t_all)
        self.held_sums += _stat_sums(counts, np.zeros(counts[_COUNTS[0]].shape, dtype=bool))

    def _data(self, t: np.ndarray, value: np.ndarray, got: np.ndarray, lost: np.ndarray) -> Data:
        n, K = self.n, t.size
        lines = np.arange(self.emitted + 2, self.emitted + K + 2, dtype=np.int64)
        self.emitted += K
        return Data(X=value[:, :n], U=value[:, n:], valid=got[:, :n], t=t, lines=lines, ignored=(), lost=lost)

    def finish(self) -> Iterator[Data]:
        """At the end of the log: the samples held are cut off; fewer than two kept is the whole read's refusal."""
        self.cut_end = int(sum(t.size for t in self.held_t))
        self.held_t = []
        if not self.started or self.emitted < 2:
            raise Reread
        yield from ()

