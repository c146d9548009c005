"""candump ``-l`` logs parsed a block of lines at a time with numpy, as python-can's reader parses them.

:func:`parse_block` reads a block of whole lines when every one that is not blank is a plain frame
record, ``(TIMESTAMP) CHANNEL ID#DATA`` (CAN FD: ``ID##FDATA``; a trailing ``R`` or ``T``
direction allowed; the FD flags digit does not change a frame's payload) with a 3-digit (standard) or 8-digit (extended) hex id and whole data bytes;
it gives the same frames python-can's ``CanutilsLogReader`` gives (the same timestamps, ids,
payloads, and error frames told apart the same way). A block holding anything else (a remote
frame, an odd digit, a line python-can refuses ...) gives None: the caller reads that block with
python-can's reader, its frames and its refusals.
"""
from __future__ import annotations

import re
import numpy as np

from .framedecode import Payloads, Records

__all__ = ["parse_block"]

_RECORD = re.compile(rb"^\(([0-9]+\.[0-9]+)\) [!-~]+ ([0-9A-Fa-f]{3}|[0-9A-Fa-f]{8})#(?:#[0-9])?((?:[0-9A-Fa-f]{2})*)"
                     rb"(?: [RrTt])?\r?$", re.M)
_BLANK = re.compile(rb"^[ \t\r\f\v]*$", re.M)
_CAN_ERR_FLAG = 0x20000000
_CAN_ERR_BUSERROR = 0x80
#: each ASCII byte's value as a hex digit (0 for the others, which the pattern never lets through)
_HEX = np.zeros(256, dtype=np.uint8)
for _i, _c in enumerate(b"0123456789abcdef"):
    _HEX[_c] = _i
for _i, _c in enumerate(b"ABCDEF"):
    _HEX[_c] = 10 + _i


def _hex_digits(texts: list[bytes], width: int) -> np.ndarray:
    """(len(texts), width) the hex digits of each text, left-aligned, 0 after its end."""
    chars = np.array(texts, dtype=f"S{max(width, 1)}").view(np.uint8).reshape(len(texts), max(width, 1))
    return _HEX[chars[:, :width]]


def parse_block(block: bytes) -> Records | None:
    """The frames of ``block`` (whole lines, each ending in a newline), or None if a line that is not blank is
    not a plain frame record (see the module docs)."""
    found = _RECORD.findall(block)
    lines = block.count(b"\n")
    # every line a record or blank (the pattern finds one more blank "line" after the last newline)
    if len(found) != lines and len(found) != lines - (len(_BLANK.findall(block)) - 1):
        return None
    n = len(found)
    stamps, ids, data = zip(*found) if n else ((), (), ())
    t = np.fromiter(map(float, stamps), dtype=np.float64, count=n)
    id_digits = _hex_digits(list(ids), 8).astype(np.uint64)
    id_len = np.fromiter(map(len, ids), dtype=np.int64, count=n)
    raw_id = np.zeros(n, dtype=np.uint64)
    for j in range(8):
        raw_id = np.where(j < id_len, (raw_id << np.uint64(4)) | id_digits[:, j], raw_id)
    size = np.fromiter(map(len, data), dtype=np.int64, count=n) // 2
    width = int(size.max()) if n else 0
    digits = _hex_digits(list(data), 2 * width)
    payload = (digits[:, 0::2] << 4) | digits[:, 1::2]
    error = ((raw_id & np.uint64(_CAN_ERR_FLAG)) != 0) & ((raw_id & np.uint64(_CAN_ERR_BUSERROR)) != 0)
    keep = ~error
    return Records(records=n, errors=int(error.sum()), t=t[keep],
                 ids=(raw_id[keep] & np.uint64(0x1FFFFFFF)).astype(np.int64), extended=(id_len[keep] > 3),
                 data=Payloads(np.ascontiguousarray(payload[keep]), size[keep]))
