"""Vector ASC logs parsed a block of lines at a time with numpy, as python-can's ``ASCReader`` parses them.

:class:`AscBlocks` reads a log's blocks of whole lines in file order. It reads the header as
python-can's reader does (``date``, ``base hex|dec [timestamps absolute|relative]``, comments, up to
and including the first other line, which the reader drops) and carries its number base to the
blocks after it. A block of the body is parsed with numpy when every line in it is a classic data
frame written with hex digits (``0.001000 1  123x  Rx   d 8 01 02 ...``, bytes separated by single
spaces, anything after the bytes ignored), a CAN FD frame as python-can writes it (``0.001000 CANFD   1 Rx
100  1 0 b 20 00 01 ...`` and its trailing fields; no symbolic name), an error frame (``0.002 1 ErrorFrame``), a remote frame
(``... Rx r``) or a line python-can skips (blank lines, comments, ``Begin/End TriggerBlock``,
``Start of measurement``, events and statistics): the same timestamps, ids, payloads and record counts
as python-can's reader. A block holding anything else (a CAN FD frame with a symbolic name, a decimal log, an odd layout, a
line python-can refuses ...) gives None: the caller reads that block with python-can's reader, started
after the header with the same base (:meth:`AscBlocks.fallback_text`), for its frames and refusals.
"""
from __future__ import annotations

import re

import numpy as np

from .candump import HEX_VALUE, hex_digits
from .framedecode import Payloads, Records

__all__ = ["AscBlocks"]

#: a body line: its timestamp, then a classic frame's (error frame, id, extended mark, DLC, bytes, remote mark)
#: or a CAN FD frame's fields (its mark, error frame, id, extended mark, data length, bytes), or any other line
_LINE = re.compile(
    rb"^(?:[ \t]*([0-9]+\.[0-9]+)[ \t]+(?:[0-9]+[ \t]+"
    rb"(?:(ErrorFrame)|([0-9A-Fa-f]{1,8})([xX]?)[ \t]+[RT]x[ \t]+(?:d[ \t]+([0-9A-Fa-f])((?: [0-9A-Fa-f]{2})*)|(r)))"
    rb"(?:[ \t][^\r\n]*)?"
    rb"|(C)ANFD[ \t]+[0-9]+[ \t]+[RT]x[ \t]+"
    rb"(?:(ErrorFrame)(?:[ \t][^\r\n]*)?|([0-9A-Fa-f]{1,8})([xX]?)[ \t]+[01][ \t]+[01][ \t]+[0-9A-Fa-f][ \t]+([0-9]{1,2})"
    rb"((?: [0-9A-Fa-f]{2})*)[ \t]+[^ \t\r\n][^\r\n]*))\r?"
    rb"|([^\n]*))$", re.M)
#: python-can's header lines (what its reader matches at the start of a log)
_DATE = re.compile(r"date\s+\w+\s+(?P<datetime_string>.+)", re.IGNORECASE)
_BASE = re.compile(r"base\s+(?P<base>hex|dec)(?:\s+timestamps\s+(?P<timestamp_format>absolute|relative))?",
                   re.IGNORECASE)
_COMMENT = re.compile(r"//.*")
#: python-can's reader takes this line as the header's last one (so it starts reading frames after it)
_HEADER_END = b"internal events logged\n"


def _message_pattern() -> re.Pattern[str]:
    """python-can's pattern of the lines its ASC reader reads as frames (all others it skips)."""
    from can.io.asc import ASC_MESSAGE_REGEX

    return ASC_MESSAGE_REGEX


class AscBlocks:
    """An ASC log's blocks of whole lines parsed in file order (see the module docs); :attr:`base` the number
    base its header set (``"hex"`` unless it says ``dec``)."""

    def __init__(self) -> None:
        self.base = "hex"
        self._header = True

    def parse(self, block: bytes) -> tuple[bytes, Records | None]:
        """The part of ``block`` (whole lines, each ending in a newline) after the header, and its records, or
        None when the caller is to read that part with python-can's reader (:meth:`fallback_text`). Raises
        python-can's ValueError for a header whose base is neither hex nor dec."""
        if self._header:
            block = self._skip_header(block)
        if not block or self._header:
            return b"", _empty()
        if self.base != "hex" or not block.isascii() or not block.endswith(b"\n"):
            return block, None
        return block, _body(block)

    def fallback_text(self, body: bytes) -> bytes:
        """``body`` as python-can's reader (given :attr:`base`) reads it after the header: behind a line that
        ends its header, so that it reads every line of ``body`` as it reads the body of a log."""
        return _HEADER_END + body

    def _skip_header(self, block: bytes) -> bytes:
        """``block`` without the header lines it holds (all of them while the header goes on)."""
        pos = 0
        while pos < len(block):
            end = block.find(b"\n", pos)
            end = len(block) if end < 0 else end + 1
            line = block[pos:end].decode("utf-8", errors="replace").strip()
            pos = end
            if _DATE.match(line) or _COMMENT.match(line):
                continue
            based = _BASE.match(line)
            if based:
                if based.group("base") not in ("hex", "dec"):
                    raise ValueError('base should be either "hex" or "dec"')
                self.base = based.group("base")
                continue
            self._header = False  # the events line or any other ends the header (and is dropped)
            break
        return block[pos:]


def _empty() -> Records:
    return Records(records=0, errors=0, t=np.zeros(0), ids=np.zeros(0, dtype=np.int64),
                   extended=np.zeros(0, dtype=bool), data=Payloads(np.zeros((0, 0), dtype=np.uint8),
                                                                   np.zeros(0, dtype=np.int64)))


def _body(block: bytes) -> Records | None:
    """The records of a body block (ASCII whole lines, hex base), or None (see the module docs)."""
    found = _LINE.findall(block)
    if found and block.endswith(b"\n"):
        found.pop()  # the empty "line" after the last newline
    if not found:
        return _empty()
    (stamps, error, ids, ext, dlc, data, remote, fd_mark, fd_error, fd_ids, fd_ext, fd_length, fd_data,
     other) = (np.array(c) for c in zip(*found))
    fd = fd_mark != b""
    classic = (stamps != b"") & ~fd
    pattern = None
    for i in np.flatnonzero(~(classic | fd)).tolist():
        pattern = pattern or _message_pattern()
        if pattern.match(bytes(other[i]).decode("ascii").strip()):
            return None  # a frame python-can reads and this module does not
    is_record = classic | fd
    length = np.zeros(fd.size, dtype=np.int64)
    fd_data_frame = fd & (fd_error == b"")
    length[fd_data_frame] = np.fromiter(map(int, fd_length[fd_data_frame].tolist()), dtype=np.int64,
                                        count=int(fd_data_frame.sum()))
    # error frames; remote frames (a CAN FD frame of data length 0 is one)
    frame = (classic & (error == b"") & (remote == b"")) | (fd_data_frame & (length > 0))
    stamps = stamps[frame]
    ids, ext, data = (np.where(fd, y, x)[frame] for x, y in ((ids, fd_ids), (ext, fd_ext), (data, fd_data)))
    n = int(frame.sum())
    t = np.fromiter(map(float, stamps.tolist()), dtype=np.float64, count=n)
    id_len = np.char.str_len(ids) if n else np.zeros(0, dtype=np.int64)
    id_digits = hex_digits(ids.tolist(), 8).astype(np.uint64)
    raw_id = np.zeros(n, dtype=np.uint64)
    for j in range(8):
        raw_id = np.where(j < id_len, (raw_id << np.uint64(4)) | id_digits[:, j], raw_id)
    dlc_value = HEX_VALUE[np.array(dlc[frame], dtype="S1").view(np.uint8)].astype(np.int64)
    # python-can takes at most 8 bytes of a classic frame (DLC 9-15 included), data length bytes of a CAN FD one
    size = np.where(fd[frame], length[frame], np.minimum(dlc_value, 8))
    tokens = (np.char.str_len(data) // 3) if n else np.zeros(0, dtype=np.int64)
    if (tokens < size).any() or (size > 64).any():
        return None  # fewer bytes written than the frame has, or bytes laid out otherwise
    width = int(size.max()) if n else 0
    chars = hex_digits(data.tolist(), 3 * width)
    payload = ((chars[:, 1::3] << 4) | chars[:, 2::3]).astype(np.uint8)
    payload = np.where(np.arange(width) < size[:, None], payload, 0).astype(np.uint8)
    return Records(records=int(is_record.sum()), errors=int(is_record.sum()) - n, t=t,
                   ids=raw_id.astype(np.int64), extended=ext != b"", data=Payloads(np.ascontiguousarray(payload), size))
