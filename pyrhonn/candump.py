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

__all__ = ["HEX_VALUE", "hex_digits", "parse_block"]

_RECORD = re.compile(rb"^\(([0-9]+\.[0-9]+)\) [!-~]+ ([0-9A-Fa-f]{3}|[0-9A-Fa-f]{8})#(?:#[0-9])?((?:[0-9A-Fa-f]{2})*)"
                     rb"(?: [RrTt])?\r?$", re.M)
_BLANK = re.compile(rb"^[ \t\r\f\v]*$", re.M)
_CAN_ERR_FLAG = 0x20000000
_CAN_ERR_BUSERROR = 0x80
#: each ASCII byte's value as a hex digit (0 for the others, which the pattern never lets through)
HEX_VALUE = np.zeros(256, dtype=np.uint8)
for _i, _c in enumerate(b"0123456789abcdef"):
    HEX_VALUE[_c] = _i
for _i, _c in enumerate(b"ABCDEF"):
    HEX_VALUE[_c] = 10 + _i


def hex_digits(texts: list[bytes], width: int) -> np.ndarray:
    """(len(texts), width) the hex digits of each text, left-aligned, 0 after its end."""
    chars = np.array(texts, dtype=f"S{max(width, 1)}").view(np.uint8).reshape(len(texts), max(width, 1))
    return HEX_VALUE[chars[:, :width]]


_DIGIT = np.zeros(256, dtype=bool)
_DIGIT[list(b"0123456789")] = True
_HEXDIGIT = np.zeros(256, dtype=bool)
_HEXDIGIT[list(b"0123456789abcdefABCDEF")] = True
_PRINTABLE = np.zeros(256, dtype=bool)
_PRINTABLE[0x21:0x7F] = True


def _columns(block: bytes) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """A block's records by columns, when the lines of each length are laid out alike (as a logger writes
    them: the same channel, id length and payload length): every line is matched against the first of its
    length column by column (the same characters where it has the pattern's fixed ones, digits, hex digits
    or a channel name's characters where it has them), so each line matches the pattern with the same
    fields. (timestamps, raw ids, id lengths, payload lengths, payload rows) or None (a blank line, a line
    unlike the first of its length, or one the pattern refuses)."""
    text = np.frombuffer(block, dtype=np.uint8)
    ends = np.flatnonzero(text == 10)
    if not ends.size or ends[-1] != text.size - 1:
        return None
    starts = np.r_[0, ends[:-1] + 1]
    lengths = ends - starts  # without the newline
    lines = ends.size
    t = np.zeros(lines)
    raw_id = np.zeros(lines, dtype=np.uint64)
    id_len = np.zeros(lines, dtype=np.int64)
    size = np.zeros(lines, dtype=np.int64)
    groups = []
    for width in np.unique(lengths).tolist():
        at = np.flatnonzero(lengths == width)
        first = int(starts[at[0]])
        found = _RECORD.match(block, first, first + width)
        if found is None or found.end() != first + width:
            return None
        rows = text[starts[at][:, None] + np.arange(width)]
        (a, b), (c, d), (e, f) = (((x - first), (y - first)) for x, y in (found.span(k) for k in (1, 2, 3)))
        kind = np.zeros(width, dtype=np.int8)  # 0 fixed, 1 digit, 2 hex digit, 3 a channel's character
        kind[a:b] = 1
        kind[a + bytes(rows[0, a:b]).index(b".")] = 0
        kind[b + 2:c - 1] = 3
        kind[c:d] = 2
        kind[e:f] = 2
        fixed = kind == 0
        if not ((rows[:, fixed] == rows[0, fixed]).all() and _DIGIT[rows[:, kind == 1]].all()
                and _HEXDIGIT[rows[:, kind == 2]].all() and _PRINTABLE[rows[:, kind == 3]].all()):
            return None
        digits = rows[:, a:b][:, kind[a:b] == 1].astype(np.int64) - 48
        point = a + bytes(rows[0, a:b]).index(b".")
        places = b - point - 1
        if digits.shape[1] > 18 or places > 22:  # beyond int64 or an exact power of ten: Python's float
            stamps = np.array([float(bytes(r[a:b])) for r in rows])
        else:
            whole = np.zeros(at.size, dtype=np.int64)
            for j in range(digits.shape[1]):
                whole = whole * 10 + digits[:, j]
            stamps = whole.astype(np.float64) / 10.0 ** places  # exact operands: rounded once, as float(text)
            big = whole >= (1 << 53)
            for i in np.flatnonzero(big).tolist():
                stamps[i] = float(bytes(rows[i, a:b]))
        t[at] = stamps
        value = np.zeros(at.size, dtype=np.uint64)
        for j in range(c, d):
            value = (value << np.uint64(4)) | HEX_VALUE[rows[:, j]].astype(np.uint64)
        raw_id[at] = value
        id_len[at] = d - c
        size[at] = (f - e) // 2
        groups.append((at, rows[:, e:f]))
    payload = np.zeros((lines, int(size.max())), dtype=np.uint8)
    for at, hexes in groups:
        nibbles = HEX_VALUE[hexes]
        payload[at, :nibbles.shape[1] // 2] = (nibbles[:, 0::2] << 4) | nibbles[:, 1::2]
    return t, raw_id, id_len, size, payload


def parse_block(block: bytes) -> Records | None:
    """The frames of ``block`` (whole lines, each ending in a newline), or None if a line that is not blank is
    not a plain frame record (see the module docs)."""
    columns = _columns(block)
    if columns is not None:
        return _records(*columns)
    found = _RECORD.findall(block)
    lines = block.count(b"\n")
    # every line a record or blank (the pattern finds one more blank "line" after the last newline)
    if len(found) != lines and len(found) != lines - (len(_BLANK.findall(block)) - 1):
        return None
    n = len(found)
    stamps, ids, data = zip(*found) if n else ((), (), ())
    t = np.fromiter(map(float, stamps), dtype=np.float64, count=n)
    id_digits = hex_digits(list(ids), 8).astype(np.uint64)
    id_len = np.fromiter(map(len, ids), dtype=np.int64, count=n)
    raw_id = np.zeros(n, dtype=np.uint64)
    for j in range(8):
        raw_id = np.where(j < id_len, (raw_id << np.uint64(4)) | id_digits[:, j], raw_id)
    size = np.fromiter(map(len, data), dtype=np.int64, count=n) // 2
    width = int(size.max()) if n else 0
    digits = hex_digits(list(data), 2 * width)
    return _records(t, raw_id, id_len, size, (digits[:, 0::2] << 4) | digits[:, 1::2])


def _records(t: np.ndarray, raw_id: np.ndarray, id_len: np.ndarray, size: np.ndarray,
             payload: np.ndarray) -> Records:
    """The records parsed: error frames told apart (and left out) as python-can tells them."""
    error = ((raw_id & np.uint64(_CAN_ERR_FLAG)) != 0) & ((raw_id & np.uint64(_CAN_ERR_BUSERROR)) != 0)
    keep = ~error
    return Records(records=int(t.size), errors=int(error.sum()), t=t[keep],
                   ids=(raw_id[keep] & np.uint64(0x1FFFFFFF)).astype(np.int64), extended=(id_len[keep] > 3),
                   data=Payloads(np.ascontiguousarray(payload[keep].astype(np.uint8)), size[keep]))
