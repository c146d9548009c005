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
  (``UnFinMF``) is refused unless ``partial``.

Every defect raises ``ValueError`` naming the file and channel.
"""
from __future__ import annotations

import difflib
import importlib.util
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from .validation import near_names

__all__ = ["MdfSignals", "mdf_damage", "read_signal_mdf", "require_asammdf"]

_BLOCK = struct.Struct("<4s4xQQ")  # id ("##HD"), reserved, block length, number of links
#: the most blocks followed in one file (a long bus log has one data block per few MiB)
MAX_MDF_BLOCKS = 1 << 20


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
        return {"sample_period": self.period, "sample_period_from": self.period_source, "resampling": METHOD,
                "complete": self.incomplete is None, **({"missing": self.incomplete} if self.incomplete else {}),
                "channels": self.channels}


def read_signal_mdf(path: str | Path, state_names: Sequence[str], input_names: Sequence[str], *,
                    period: float | None = None, channels: Mapping[str, str] | None = None,
                    partial: bool = False, period_option: str = "--sample-period") -> MdfSignals:
    """The states and inputs of the signal MDF4 ``path`` on a grid of ``period`` s (see the module docs)."""
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
    elif ident != b"MDF     ":
        raise ValueError(f"{source}: not an MDF file (it does not start with 'MDF')")
    damage = mdf_damage(p)
    if damage:
        raise ValueError(f"{source}: truncated or damaged MDF4: {damage}; an MDF4 is read whole or not at all")
    names = list(state_names) + list(input_names)
    channels = dict(channels or {})
    try:
        mdf = MDF(str(p))
    except Exception as exc:  # asammdf raises MdfException, struct.error, ... on a damaged file
        text = " ".join(str(exc).split()) or type(exc).__name__
        raise ValueError(f"{source}: cannot read it as MDF ({type(exc).__name__}: {text[:200]})") from None
    try:
        known = [c for c in mdf.channels_db if c not in ("time", "t")]
        got: dict[str, tuple[np.ndarray, np.ndarray, str]] = {}
        for name in names:
            channel = channels.get(name, name)
            if channel not in mdf.channels_db:
                close = difflib.get_close_matches(channel, known, n=1)
                hint = f"; did you mean {close[0]!r}?" if close else ""
                raise ValueError(f"{source}: no channel {channel!r} for {name!r}{hint} (it has: "
                                 f"{', '.join(known[:20])}{' ...' if len(known) > 20 else ''})")
            try:
                sig = mdf.get(channel)
            except Exception as exc:  # several channels of that name, a conversion asammdf cannot apply ...
                raise ValueError(f"{source}: channel {channel!r}: {' '.join(str(exc).split())[:200]}") from None
            values = np.asarray(sig.samples)
            if values.dtype.kind not in "fiub" or values.ndim != 1:
                raise ValueError(f"{source}: channel {channel!r}: expected numbers, got {values.dtype} of shape "
                                 f"{values.shape}")
            ts = np.asarray(sig.timestamps, dtype=np.float64)
            if ts.size < 2 or not np.all(np.isfinite(ts)) or np.any(np.diff(ts) <= 0):
                raise ValueError(f"{source}: channel {channel!r}: its time stamps must be finite and increasing, "
                                 f"at least two")
            got[name] = (ts, values.astype(np.float64), str(sig.unit or ""))
    finally:
        mdf.close()
    first = got[names[0]][0]
    if period is None:
        T = float(np.median(np.diff(first)))
        period_source = f"the median interval of channel {channels.get(names[0], names[0])!r}"
    else:
        T = float(period)
        period_source = period_option
    t0 = max(ts[0] for ts, _, _ in got.values())
    t1 = min(ts[-1] for ts, _, _ in got.values())
    if not t1 > t0:
        raise ValueError(f"{source}: the channels do not overlap in time (from {t0:.6g} to {t1:.6g} s)")
    K = int(np.floor((t1 - t0) / T + 1e-9)) + 1
    if K < 2:
        raise ValueError(f"{source}: the channels overlap for {t1 - t0:.6g} s, less than two periods of {T:.6g} s")
    grid = t0 + T * np.arange(K)
    n, m = len(state_names), len(input_names)
    X = np.full((K, n), np.nan)
    valid = np.zeros((K, n), dtype=bool)
    U = np.empty((K, m))
    report: dict[str, dict[str, Any]] = {}
    for col, name in enumerate(names):
        ts, values, _ = got[name]
        idx = np.searchsorted(ts, grid + 1e-12 * max(1.0, abs(t1)), side="right") - 1  # latest at or before t_k
        held = values[idx]
        fresh = ts[idx] > grid - T * (1 - 1e-9)
        if not np.all(np.isfinite(held)):
            k = int(np.argmax(~np.isfinite(held)))
            raise ValueError(f"{source}: channel {channels.get(name, name)!r}: value at {grid[k]:.6g} s is not finite")
        if col < n:
            valid[:, col] = fresh
            X[fresh, col] = held[fresh]
        else:
            U[:, col - n] = held
        report[name] = {"channel": channels.get(name, name), "samples": int(ts.size),
                        "interval": float(np.median(np.diff(ts))), "unit": got[name][2],
                        **({"not_valid": int((~fresh).sum())} if col < n else {"held": int((~fresh).sum())})}
    units = {name: got[name][2] for name in names if got[name][2]}
    return MdfSignals(t=grid, X=X, valid=valid, U=U, units=units, period=T, period_source=period_source,
                      channels=report, incomplete=incomplete)
