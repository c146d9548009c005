"""Signal MDF4 files: channels by name, resampled on the identifier's period.

Read by ``pyrhonn identify RUN.mf4 --config CFG`` (a measurement file of
named channels, as a measurement tool or asammdf writes it; an MDF4 *bus*
log of CAN frames is read with ``--can-log`` instead, :mod:`pyrhonn.buslog`).

- Every state and input is the channel of its name (``channels`` maps a
  config name to another channel name). Its unit is the channel's.
- Channels may come on different time bases. The samples are on one grid
  of period T (``period``; default: the median interval of the first
  state's channel), from the latest first sample of the channels to the
  earliest last one.
- **Resampling, zero-order hold of the latest sample**: at grid time t_k a
  channel's value is its latest sample at or before t_k.
  - An input is held (a drive or DAC holds its output): u(k) is always the
    latest value.
  - A state is a measurement: it is valid at k only if the channel has a
    sample in (t_k - T, t_k] (a new one since the previous grid point).
    Otherwise it is not valid (a dropout: the identifier predicts through
    it), never an old value held as if new. A channel slower than T is
    therefore valid only at the grid points that follow its samples.
- A file whose identification block says it was not finalised
  (``UnFinMF``) is refused unless ``partial``. So is a file cut short (its
  blocks reach past its end): with ``partial`` it is read up to the last
  complete record of each channel group whose channel blocks are before the
  cut (:mod:`pyrhonn.mdfrepair`), ``incomplete`` saying what is missing; a
  cut that leaves no channel group is refused saying so.
- :func:`read_signal_mdf` reads every channel whole; :class:`SignalMdfStream`
  gives the same values a chunk of the grid at a time, reading a block of
  records of each channel at a time (memory bounded whatever the length).

Every defect raises ``ValueError`` naming the file and channel.
"""
from __future__ import annotations

import difflib
import importlib.util
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterator, Mapping, Sequence

import numpy as np

from .mdfrepair import MAX_BLOCKS, plan_cut, repaired_copy
from .validation import near_names

__all__ = ["MdfSignals", "SignalMdfStream", "mdf_damage", "read_signal_mdf", "require_asammdf"]

_BLOCK = struct.Struct("<4s4xQQ")  # id ("##HD"), reserved, block length, number of links
#: the most blocks followed in one file (a long bus log has one data block per few MiB)
MAX_MDF_BLOCKS = MAX_BLOCKS


def require_asammdf(where: str) -> None:
    """A ValueError naming ``where`` when asammdf, which reads MDF4, is not installed."""
    if importlib.util.find_spec("asammdf") is None:
        raise ValueError(f"{where}: reading MDF4 needs asammdf: pip install 'pyrhonn[mdf]' (or asammdf)")


def mdf_damage(path: Path) -> str | None:
    """What is wrong with an MDF4 file's block structure (None: every block it links ends inside the
    file). Follows the links from the header block, reading only block headers: a file cut short or
    a damaged link is found before anything is allocated or decompressed."""
    size = path.stat().st_size
    if size < 64 + _BLOCK.size:
        return f"{size:,} bytes: shorter than an MDF4 identification and header block"
    todo, seen, beyond = [64], set(), 0
    with open(path, "rb") as fh:
        while todo:
            at = todo.pop()
            if at in seen:
                continue
            seen.add(at)
            if len(seen) > MAX_MDF_BLOCKS:
                return f"more than {MAX_MDF_BLOCKS:,} linked blocks"
            if at + _BLOCK.size > size:
                beyond = max(beyond, at + _BLOCK.size)
                continue
            fh.seek(at)
            ident, length, links = _BLOCK.unpack(fh.read(_BLOCK.size))
            if ident[:2] != b"##" or length < _BLOCK.size + 8 * links:
                return f"no valid block at byte {at:,} (a damaged link or block header)"
            if at + length > size:
                beyond = max(beyond, at + length)
                continue
            for link in struct.unpack(f"<{links}Q", fh.read(8 * links)):
                if link:
                    todo.append(link)
    if beyond:
        return (f"cut short: its blocks reach byte {beyond:,}, the file has {size:,} (at least "
                f"{beyond - size:,} bytes missing)")
    return None

#: how the channels are put on the identifier's grid, as the report says it
METHOD = ("zero-order hold of the latest sample at or before each grid time; a state is valid only where its "
          "channel has a new sample in the grid period before it (else not valid, predicted through), an input "
          "is always held")


def _report(period: float, period_source: str, incomplete: str | None,
            channels: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """metrics.json's ``mdf`` section."""
    return {"sample_period": period, "sample_period_from": period_source, "resampling": METHOD,
            "complete": incomplete is None, **({"missing": incomplete} if incomplete else {}), "channels": channels}


@dataclass(frozen=True)
class MdfSignals:
    """A signal MDF4 on the grid: ``t`` (K,) s from the file's start, ``X`` (K, n) NaN where not
    valid, ``valid`` (K, n), ``U`` (K, m), ``units`` per name, ``period`` (s) and where it came from,
    ``channels`` per name: its channel, samples and median interval; ``incomplete`` what an
    unfinalised file may miss (None: finalised)."""

    t: np.ndarray
    X: np.ndarray
    valid: np.ndarray
    U: np.ndarray
    units: dict[str, str]
    period: float
    period_source: str
    channels: dict[str, dict[str, Any]]
    incomplete: str | None

    def report(self) -> dict[str, Any]:
        return _report(self.period, self.period_source, self.incomplete, self.channels)


def _open(path: str | Path, partial: bool) -> tuple[Any, str | None]:
    """The MDF of ``path`` (asammdf's, to close) once its identification and block structure are checked,
    and what it may miss (None: finalised)."""
    p = Path(path)
    source = str(path)
    require_asammdf(source)
    from asammdf import MDF

    if not p.is_file():
        raise ValueError(f"{source}: No such file or directory{near_names(p)}")
    with open(p, "rb") as fh:
        ident = fh.read(8)
    incomplete = None
    if ident == b"UnFinMF ":
        incomplete = "its identification block says 'UnFinMF': not finalised (the writer did not finish the file)"
        if not partial:
            raise ValueError(f"{source}: truncated: {incomplete}; read what is there with --partial-log")
    elif not is_mdf(ident):
        raise ValueError(f"{source}: not an MDF file (it does not start with 'MDF')")
    read = p
    cut = cut_read(p, source, partial, incomplete)
    if cut is not None:
        read, missing = cut
        incomplete = f"{incomplete}; {missing}" if incomplete else missing
    try:
        mdf = MDF(str(read))
    except Exception as exc:  # asammdf raises MdfException, struct.error, ... on a damaged file
        if read != p:
            read.unlink(missing_ok=True)
        text = " ".join(str(exc).split()) or type(exc).__name__
        raise ValueError(f"{source}: cannot read it as MDF ({type(exc).__name__}: {text[:200]})") from None
    return (mdf if read == p else _Repaired(mdf, read)), incomplete


def is_mdf(ident: bytes) -> bool:
    """Whether a file's first 8 bytes (fewer: it is cut there) are an MDF identification's."""
    return ident == b"MDF     " or (len(ident) < 8 and b"MDF     ".startswith(ident))


def cut_read(p: Path, source: str, partial: bool, unfinished: str | None = None) -> tuple[Path, str] | None:
    """None for an MDF4 whose blocks all end inside it; for one cut short (``partial``), a repaired copy to
    read (a temporary file, the caller removes it) and what it misses; else a ValueError naming
    ``source``, what is missing (after ``unfinished``: what its identification block says), and whether
    ``--partial-log`` reads part of it."""
    said = f"{unfinished}; " if unfinished else ""
    size = p.stat().st_size
    if size < 64 + _BLOCK.size:
        raise ValueError(f"{source}: truncated: {size:,} bytes, shorter than an MDF4 identification and header block; "
                         "nothing in it can be read, not even with --partial-log")
    damage = mdf_damage(p)
    if damage is None:
        return None
    if not damage.startswith("cut short"):
        raise ValueError(f"{source}: damaged MDF4: {damage}; not read")
    try:
        cut = plan_cut(p)
    except ValueError as exc:
        raise ValueError(f"{source}: truncated: {said}{damage}; nothing in it can be read, not even with --partial-log: "
                         f"{exc}") from None
    if not partial:
        raise ValueError(f"{source}: truncated: {said}{damage}; read what is there with --partial-log (it would "
                         f"{cut.read()})")
    return repaired_copy(p, cut), f"{damage}; {cut.read()}"


class _Repaired:
    """asammdf's MDF of a repaired copy of a cut file: as the MDF, the copy removed when it is closed."""

    def __init__(self, mdf: Any, copy: Path) -> None:
        self._mdf, self._copy = mdf, copy

    def __getattr__(self, name: str) -> Any:
        return getattr(self._mdf, name)

    def close(self) -> None:
        try:
            self._mdf.close()
        finally:
            self._copy.unlink(missing_ok=True)


def _check_channel(mdf: Any, source: str, name: str, channel: str, incomplete: str | None) -> None:
    if channel not in mdf.channels_db:
        known = [c for c in mdf.channels_db if c not in ("time", "t")]
        close = difflib.get_close_matches(channel, known, n=1)
        hint = f"; did you mean {close[0]!r}?" if close else ""
        raise ValueError(f"{source}: no channel {channel!r} for {name!r}{hint} (it has: "
                         f"{', '.join(known[:20])}{' ...' if len(known) > 20 else ''})"
                         + (f"; truncated: {incomplete}" if incomplete else ""))


def _get(mdf: Any, source: str, channel: str, **records: int) -> tuple[np.ndarray, np.ndarray, str]:
    """Channel ``channel`` (or the ``record_offset``/``record_count`` records of it): time stamps, values
    as float64, unit."""
    try:
        sig = mdf.get(channel, **records)
    except Exception as exc:  # several channels of that name, a conversion asammdf cannot apply ...
        raise ValueError(f"{source}: channel {channel!r}: {' '.join(str(exc).split())[:200]}") from None
    values = np.asarray(sig.samples)
    if values.dtype.kind not in "fiub" or values.ndim != 1:
        raise ValueError(f"{source}: channel {channel!r}: expected numbers, got {values.dtype} of shape "
                         f"{values.shape}")
    return np.asarray(sig.timestamps, dtype=np.float64), values.astype(np.float64), str(sig.unit or "")


def _bad_times(source: str, channel: str) -> ValueError:
    return ValueError(f"{source}: channel {channel!r}: its time stamps must be finite and increasing, at least two")


def _grid_size(source: str, firsts: Sequence[float], lasts: Sequence[float], T: float) -> tuple[float, float, int]:
    """The grid's start, the channels' common end and the grid's number of points."""
    t0, t1 = max(firsts), min(lasts)
    if not t1 > t0:
        raise ValueError(f"{source}: the channels do not overlap in time (from {t0:.6g} to {t1:.6g} s)")
    K = int(np.floor((t1 - t0) / T + 1e-9)) + 1
    if K < 2:
        raise ValueError(f"{source}: the channels overlap for {t1 - t0:.6g} s, less than two periods of {T:.6g} s")
    return t0, t1, K


def _resample(source: str, channel: str, ts: np.ndarray, values: np.ndarray, grid: np.ndarray, T: float,
              t1: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The zero-order hold of a channel at ``grid`` (``ts`` holds every sample from the latest at or before
    grid[0] on, up to one after the last grid time or the channel's end): held values, fresh flags and
    the indices of the samples held."""
    idx = np.searchsorted(ts, grid + 1e-12 * max(1.0, abs(t1)), side="right") - 1  # latest at or before t_k
    held = values[idx]
    fresh = ts[idx] > grid - T * (1 - 1e-9)
    if not np.all(np.isfinite(held)):
        k = int(np.argmax(~np.isfinite(held)))
        raise ValueError(f"{source}: channel {channel!r}: value at {grid[k]:.6g} s is not finite")
    return held, fresh, idx


def _entry(channel: str, samples: int, interval: float, unit: str, state: bool, stale: int) -> dict[str, Any]:
    return {"channel": channel, "samples": samples, "interval": interval, "unit": unit,
            **({"not_valid": stale} if state else {"held": stale})}


def read_signal_mdf(path: str | Path, state_names: Sequence[str], input_names: Sequence[str], *,
                    period: float | None = None, channels: Mapping[str, str] | None = None,
                    partial: bool = False, period_option: str = "--sample-period") -> MdfSignals:
    """The states and inputs of the signal MDF4 ``path`` on a grid of ``period`` s (see the module docs),
    every channel read whole (:class:`SignalMdfStream` reads the same a block of records at a time)."""
    source = str(path)
    mdf, incomplete = _open(path, partial)
    names = list(state_names) + list(input_names)
    channels = dict(channels or {})
    try:
        got: dict[str, tuple[np.ndarray, np.ndarray, str]] = {}
        for name in names:
            channel = channels.get(name, name)
            _check_channel(mdf, source, name, channel, incomplete)
            ts, values, unit = _get(mdf, source, channel)
            if ts.size < 2 or not np.all(np.isfinite(ts)) or np.any(np.diff(ts) <= 0):
                raise _bad_times(source, channel)
            got[name] = (ts, values, unit)
    finally:
        mdf.close()
    first = got[names[0]][0]
    if period is None:
        T = float(np.median(np.diff(first)))
        period_source = f"the median interval of channel {channels.get(names[0], names[0])!r}"
    else:
        T = float(period)
        period_source = period_option
    t0, t1, K = _grid_size(source, [ts[0] for ts, _, _ in got.values()], [ts[-1] for ts, _, _ in got.values()], T)
    grid = t0 + T * np.arange(K)
    n, m = len(state_names), len(input_names)
    X = np.full((K, n), np.nan)
    valid = np.zeros((K, n), dtype=bool)
    U = np.empty((K, m))
    report: dict[str, dict[str, Any]] = {}
    for col, name in enumerate(names):
        ts, values, unit = got[name]
        held, fresh, _ = _resample(source, channels.get(name, name), ts, values, grid, T, t1)
        if col < n:
            valid[:, col] = fresh
            X[fresh, col] = held[fresh]
        else:
            U[:, col - n] = held
        report[name] = _entry(channels.get(name, name), int(ts.size), float(np.median(np.diff(ts))), unit, col < n,
                              int((~fresh).sum()))
    units = {name: got[name][2] for name in names if got[name][2]}
    return MdfSignals(t=grid, X=X, valid=valid, U=U, units=units, period=T, period_source=period_source,
                      channels=report, incomplete=incomplete)


#: records of a channel read at once when a signal MDF4 is streamed
BLOCK_RECORDS = 1 << 16
#: intervals of a channel held at once to find their median; a channel with more is narrowed down over
#: further passes over its time stamps (a block at a time), to the same median
MEDIAN_HOLD = 1 << 20
#: an upper bound of the bit patterns of positive finite float64 (as int64 they sort as the numbers do)
_KEY_END = 0x7FF0000000000000


def _kth(intervals: Callable[[], Iterator[np.ndarray]], k: int, hold: int) -> float:
    """The k-th smallest (from 0) of the positive finite intervals that ``intervals()`` yields a block at a
    time, holding at most ``hold`` of them: each pass counts them in 4,096 bins of their bit patterns and
    keeps the bin of the k-th, until it holds few enough to sort (or one value)."""
    lo, hi, below = 0, _KEY_END, 0  # the k-th's bit pattern is in [lo, hi); ``below`` intervals are under lo
    while hi - lo > 1:
        shift = max(0, (hi - lo - 1).bit_length() - 12)
        counts = np.zeros(((hi - lo - 1) >> shift) + 1, dtype=np.int64)
        kept: list[np.ndarray] = []
        inside = 0
        for d in intervals():
            key = d.view(np.int64)
            key = key[(key >= lo) & (key < hi)]
            inside += key.size
            if inside <= hold:
                kept.append(key)
            counts += np.bincount((key - lo) >> shift, minlength=counts.size)
        if inside <= hold:
            return float(np.sort(np.concatenate(kept))[k - below].view(np.float64))
        cum = np.cumsum(counts)
        b = int(np.searchsorted(cum, k - below, side="right"))
        below += int(cum[b - 1]) if b else 0
        lo, hi = lo + (b << shift), min(hi, lo + ((b + 1) << shift))
    return float(np.int64(lo).view(np.float64))


class SignalMdfStream:
    """A signal MDF4 on the grid, as :func:`read_signal_mdf` gives it (the same values, bit for bit), read
    a block of ``block`` records of each channel at a time: memory does not grow with the record.

    Opening it passes over each channel's records a block at a time: it checks them, finds each
    channel's first and last time (the grid's ends) and the median interval (the default period, the
    report's ``interval``; a channel of more than ``hold`` intervals is passed over again, to the exact
    median, with at most ``hold`` intervals held). :meth:`chunks` then resamples the channels chunk by
    chunk, carrying each channel's latest sample over; :meth:`report` is complete after the last chunk.
    Attributes: ``period``, ``period_source``, ``units``, ``incomplete``, ``samples`` (the grid's
    points), ``channels`` (per name; the counts of samples not valid or held complete after the last
    chunk)."""

    def __init__(self, path: str | Path, state_names: Sequence[str], input_names: Sequence[str], *,
                 period: float | None = None, channels: Mapping[str, str] | None = None, partial: bool = False,
                 period_option: str = "--sample-period", block: int = BLOCK_RECORDS, hold: int = MEDIAN_HOLD) -> None:
        if block < 1 or hold < 1:
            raise ValueError(f"block and hold: must be >= 1, got {block} and {hold}")
        self.path, self.source, self.block, self.partial = path, str(path), block, partial
        self.n = len(state_names)
        self.names = list(state_names) + list(input_names)
        names = dict(channels or {})
        self.channel_of = {name: names.get(name, name) for name in self.names}
        mdf, self.incomplete = _open(path, partial)
        firsts: list[float] = []
        lasts: list[float] = []
        units: dict[str, str] = {}
        counts: dict[str, int] = {}
        intervals: dict[str, float] = {}
        try:
            for name in self.names:
                channel = self.channel_of[name]
                _check_channel(mdf, self.source, name, channel, self.incomplete)
                count, first, last, held, unit = 0, np.nan, np.nan, [], ""
                for ts, _, block_unit in self._blocks(mdf, channel):
                    unit = block_unit
                    prior = ts[:0] if count == 0 else np.array([last])
                    if not np.all(np.isfinite(ts)) or np.any(np.diff(np.r_[prior, ts]) <= 0):
                        raise _bad_times(self.source, channel)
                    if count == 0:
                        first = float(ts[0])
                    if count + ts.size - 1 <= hold:
                        held.append(np.diff(np.r_[prior, ts]))
                    count += ts.size
                    last = float(ts[-1])
                if count < 2:
                    raise _bad_times(self.source, channel)
                if count - 1 <= hold:
                    intervals[name] = float(np.median(np.concatenate(held)))
                else:
                    middle = [_kth(lambda: self._intervals(mdf, channel), k, hold)
                              for k in sorted({(count - 1) // 2, (count - 2) // 2})]
                    intervals[name] = float(np.mean(np.array(middle)))  # as np.median: the mean of the middle two
                firsts.append(first)
                lasts.append(last)
                units[name] = unit
                counts[name] = count
        finally:
            mdf.close()
        if period is None:
            self.period = intervals[self.names[0]]
            self.period_source = f"the median interval of channel {self.channel_of[self.names[0]]!r}"
        else:
            self.period = float(period)
            self.period_source = period_option
        self.t0, self.t1, self.samples = _grid_size(self.source, firsts, lasts, self.period)
        self.units = {name: unit for name, unit in units.items() if unit}
        self.channels = {name: _entry(self.channel_of[name], counts[name], intervals[name], units[name],
                                      col < self.n, 0) for col, name in enumerate(self.names)}

    def _blocks(self, mdf: Any, channel: str) -> Iterator[tuple[np.ndarray, np.ndarray, str]]:
        offset = 0
        while True:
            ts, values, unit = _get(mdf, self.source, channel, record_offset=offset, record_count=self.block)
            if ts.size == 0:
                return
            yield ts, values, unit
            offset += ts.size

    def _intervals(self, mdf: Any, channel: str) -> Iterator[np.ndarray]:
        last = None
        for ts, _, _ in self._blocks(mdf, channel):
            yield np.diff(ts if last is None else np.r_[last, ts])
            last = ts[-1]

    def report(self) -> dict[str, Any]:
        return _report(self.period, self.period_source, self.incomplete, self.channels)

    def chunks(self, rows: int = BLOCK_RECORDS) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
        """The grid ``rows`` points at a time: ``t`` (L,), ``X`` (L, n) NaN where not valid, ``valid`` (L, n),
        ``U`` (L, m), the rows of :func:`read_signal_mdf`'s arrays in order."""
        T, K, n = self.period, self.samples, self.n
        stale = {name: 0 for name in self.names}
        mdf, _ = _open(self.path, self.partial)
        try:
            reads = [self._blocks(mdf, self.channel_of[name]) for name in self.names]
            ts_held = [np.empty(0) for _ in self.names]
            values_held = [np.empty(0) for _ in self.names]
            eps = 1e-12 * max(1.0, abs(self.t1))
            for a in range(0, K, rows):
                grid = self.t0 + T * np.arange(a, min(a + rows, K))
                L = grid.size
                X = np.full((L, n), np.nan)
                valid = np.zeros((L, n), dtype=bool)
                U = np.empty((L, len(self.names) - n))
                for col, name in enumerate(self.names):
                    ts, values = ts_held[col], values_held[col]
                    while ts.size == 0 or ts[-1] <= grid[-1] + eps:  # up to a sample past the chunk (or the end)
                        got = next(reads[col], None)
                        if got is None:
                            break
                        ts, values = np.r_[ts, got[0]], np.r_[values, got[1]]
                    held, fresh, idx = _resample(self.source, self.channel_of[name], ts, values, grid, T, self.t1)
                    ts_held[col], values_held[col] = ts[idx[-1]:], values[idx[-1]:]  # the latest sample carried
                    if col < n:
                        valid[:, col] = fresh
                        X[fresh, col] = held[fresh]
                    else:
                        U[:, col - n] = held
                    stale[name] += int((~fresh).sum())
                yield grid, X, valid, U
        finally:
            mdf.close()
        for col, name in enumerate(self.names):
            self.channels[name]["not_valid" if col < n else "held"] = stale[name]
