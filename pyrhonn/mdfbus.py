"""An MDF4 bus log's CAN data frames read as arrays with asammdf, as python-can's ``MF4Reader`` reads them.

python-can's reader takes the channel groups of bus events on a CAN bus that have records (data,
error or remote frames), reads each with asammdf and merges them by time. When the only such group
is one of data frames, :func:`mdf_records` reads its ``CAN_DataFrame`` columns a block of records at a
time instead of a ``can.Message`` per frame: the same timestamps (the record's time plus the file's
start time), identifiers (masked to 29 bits), extended flags and payloads (``DataBytes`` cut to
``DataLength``). Any other layout: None, and the caller reads the log with python-can's reader.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Iterator

import numpy as np

from .framedecode import Payloads, Records

__all__ = ["mdf_records"]

#: records read at once
_BLOCK = 1 << 16


def _frame_groups(mdf: Any) -> list[tuple[int, str]]:
    """The channel groups python-can's reader reads: (group index, "CAN_DataFrame" | "CAN_ErrorFrame" |
    "CAN_RemoteFrame")."""
    from asammdf import Source
    from asammdf.blocks.v4_constants import FLAG_CG_BUS_EVENT

    found: list[tuple[int, str]] = []
    for index, group in enumerate(mdf.groups):
        cg = group.channel_group
        source = cg.acq_source
        if not cg.flags & FLAG_CG_BUS_EVENT or cg.cycles_nr == 0 or source is None:
            continue
        if not source.source_type & Source.SOURCE_BUS or source.bus_type != Source.BUS_TYPE_CAN:
            continue
        names = [channel.name for channel in group.channels]
        kind = next((k for k in ("CAN_DataFrame", "CAN_ErrorFrame", "CAN_RemoteFrame") if k in names), None)
        if kind is not None:
            found.append((index, kind))
    return found


def mdf_records(path: Path) -> Iterator[Records] | None:
    """The data frames of the MDF4 bus log ``path`` a block at a time, or None when its frames are not one
    channel group of data frames (see the module docs). Raises what asammdf raises opening it."""
    from asammdf import MDF

    mdf = MDF(str(path))
    try:
        groups = _frame_groups(mdf)
    except Exception:  # noqa: BLE001 - a layout this reader does not know: python-can's reader reads it
        mdf.close()
        return None
    if len(groups) != 1 or groups[0][1] != "CAN_DataFrame" or not _columns_read(mdf, groups[0][0]):
        mdf.close()
        return None
    return _read(mdf, groups[0][0])


def _columns_read(mdf: Any, index: int) -> bool:
    """Does the group's first record have the columns read here (an id, a length, bytes as a uint8 row)?"""
    try:
        first = mdf.get("CAN_DataFrame", index, record_offset=0, record_count=1, raw=False)
        names = first.samples.dtype.names or ()
        raw = np.asarray(first["CAN_DataFrame.DataBytes"])
    except Exception:  # noqa: BLE001 - python-can's reader says what is wrong with it
        return False
    return ("CAN_DataFrame.ID" in names and "CAN_DataFrame.DataLength" in names and raw.dtype == np.uint8
            and raw.ndim == 2)


def _read(mdf: Any, index: int) -> Iterator[Records]:
    try:
        start = float(mdf.header.start_time.timestamp())
        cycles = int(mdf.groups[index].channel_group.cycles_nr)
        for offset in range(0, cycles, _BLOCK):
            data = mdf.get("CAN_DataFrame", index, record_offset=offset, record_count=_BLOCK, raw=False)
            names = data.samples.dtype.names
            n = len(data)
            t = np.asarray(data.timestamps, dtype=np.float64) + start
            ids = (np.asarray(data["CAN_DataFrame.ID"]).astype(np.int64) & 0x1FFFFFFF)
            extended = (np.asarray(data["CAN_DataFrame.IDE"]) != 0 if "CAN_DataFrame.IDE" in names
                        else np.zeros(n, dtype=bool))
            raw = np.asarray(data["CAN_DataFrame.DataBytes"])
            length = np.minimum(np.asarray(data["CAN_DataFrame.DataLength"]).astype(np.int64), raw.shape[1])
            cols = np.arange(raw.shape[1])
            payload = np.where(cols[None, :] < length[:, None], raw, 0).astype(np.uint8)
            yield Records(n, 0, t, ids, extended, Payloads(np.ascontiguousarray(payload), length))
    finally:
        mdf.close()

