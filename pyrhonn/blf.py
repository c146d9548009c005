"""Vector BLF logs read a container at a time with numpy, giving what python-can's ``BLFReader`` gives.

:func:`blf_records` takes a ``can.BLFReader`` that has read the file's header and reads its objects
itself: each log container decompressed as python-can decompresses it, the objects inside it (and
those continued from the container before) read as python-can reads them: CAN frames (object
types 1 and 86), CAN FD frames (100 and 101) and error frames (73); every other object skipped.
Runs of objects of one layout (a logger writes one object type and size after another) are read
at once from a numpy view; any other object is read alone. The timestamps are python-can's,
``ticks * 10^-5`` or ``ticks * 10^-9`` (by the object's flag) rounded once to a float, plus the
file's start time. A defect raises what python-can raises there (``BLFParseError``, ``struct.error``,
``zlib.error``), after the frames before it.
"""
from __future__ import annotations

import struct
import zlib
from decimal import Decimal
from typing import Any, Iterator

import numpy as np

from .framedecode import Payloads, Records

__all__ = ["blf_records"]

_BASE = struct.Struct("<4sHHLL")  # signature, header size, header version, object size, object type
_V1 = struct.Struct("<LHHQ")  # flags, client index, object version, timestamp
_V2 = struct.Struct("<LBxHQ8x")  # flags, timestamp status, object version, timestamp
_CONTAINER = struct.Struct("<H6xL4x")  # compression method, uncompressed size
_CAN = struct.Struct("<HBBL8s")  # channel, flags, dlc, id, data
_CAN_FD = struct.Struct("<HBBLLBBB5x64s")  # channel, flags, dlc, id, frame length, bit count, FD flags, valid bytes
_CAN_FD_64 = struct.Struct("<BBBBLLLLLLLHBBL")
_ERROR_EXT = struct.Struct("<HHLBBBxLLH2x8s")
_LOG_CONTAINER, _CAN_MESSAGE, _CAN_MESSAGE2, _CAN_ERROR_EXT, _CAN_FD_MESSAGE, _CAN_FD_MESSAGE_64 = 10, 1, 86, 73, 100, 101
_NO_COMPRESSION, _ZLIB = 0, 2
_EXTENDED = 0x80000000
_REMOTE = 0x80
_TEN_MICROS = 1  # the object's time flag: 10 us ticks (else 1 ns)
_EXACT = 1 << 53
#: the layouts read as runs: object type -> the frame record after the object header
_RUNS = {_CAN_MESSAGE: _CAN, _CAN_MESSAGE2: _CAN, _CAN_FD_MESSAGE: _CAN_FD}


def _parse_error(text: str = "") -> Exception:
    from can.io.blf import BLFParseError

    return BLFParseError(text) if text else BLFParseError()


def _seconds(ticks: np.ndarray, ten_micros: np.ndarray, start: float) -> np.ndarray:
    """Object times as python-can computes them: float(Decimal(ticks) * factor) + start."""
    out = np.empty(ticks.size, dtype=np.float64)
    small = ticks < np.uint64(_EXACT)  # exact as a float: one IEEE division rounds as Decimal's float does
    out[small] = ticks[small].astype(np.float64) / np.where(ten_micros[small], 1e5, 1e9)
    for i in np.flatnonzero(~small).tolist():
        out[i] = float(Decimal(int(ticks[i])) * (Decimal("1e-5") if ten_micros[i] else Decimal("1e-9")))
    return out + start


class _Acc:
    """Frames gathered from one container's data."""

    def __init__(self) -> None:
        self.records = 0
        self.errors = 0
        self.parts: list[tuple[np.ndarray, np.ndarray, np.ndarray, Payloads]] = []
        self.rows: list[tuple[int, int, int, bytes]] = []  # (ticks, ten micros, id field, payload)

    def flush_rows(self, start: float) -> None:
        if not self.rows:
            return
        ticks = np.array([r[0] for r in self.rows], dtype=np.uint64)
        tens = np.array([r[1] for r in self.rows], dtype=bool)
        ident = np.array([r[2] for r in self.rows], dtype=np.int64)
        self.parts.append((_seconds(ticks, tens, start), ident & 0x1FFFFFFF, (ident & _EXTENDED) != 0,
                           Payloads.of([r[3] for r in self.rows])))
        self.rows = []

    def records_of(self, start: float) -> Records:
        self.flush_rows(start)
        if not self.parts:
            empty = Payloads(np.zeros((0, 0), dtype=np.uint8), np.zeros(0, dtype=np.int64))
            return Records(self.records, self.errors, np.zeros(0), np.zeros(0, dtype=np.int64),
                           np.zeros(0, dtype=bool), empty)
        return Records(self.records, self.errors, np.concatenate([p[0] for p in self.parts]),
                       np.concatenate([p[1] for p in self.parts]), np.concatenate([p[2] for p in self.parts]),
                       Payloads.join([p[3] for p in self.parts]))


def _run(data: bytes, view: np.ndarray, pos: int, size: int, kind: int, header: int, acc: _Acc,
         start: float) -> int:
    """Objects of the same base header as the one at ``pos`` (all of ``size`` bytes, one after the other) read
    at once; returns how many (at least the one at ``pos``)."""
    fits = (len(data) - pos) // size
    rows = view[pos:pos + fits * size].reshape(fits, size)
    same = (rows[:, :_BASE.size] == rows[0, :_BASE.size]).all(axis=1)
    count = fits if same.all() else int(np.argmin(same))
    rows = rows[:count]
    acc.flush_rows(start)
    at = _BASE.size  # both header versions: flags first, the timestamp 8 bytes in
    flags = rows[:, at:at + 4].copy().view("<u4").ravel()
    ticks = rows[:, at + 8:at + 16].copy().view("<u8").ravel().astype(np.uint64)
    body = header  # the frame record starts after the whole object header
    frame_flags = rows[:, body + 2]
    ident = rows[:, body + 4:body + 8].copy().view("<u4").ravel().astype(np.int64)
    if kind == _CAN_FD_MESSAGE:
        length = rows[:, body + 14].astype(np.int64)  # valid bytes
        payload = rows[:, body + 20:body + 84]
    else:
        length = np.minimum(rows[:, body + 3].astype(np.int64), 8)  # dlc; the data field has 8 bytes
        payload = rows[:, body + 8:body + 16]
    length = np.minimum(length, payload.shape[1])
    remote = (frame_flags & _REMOTE) != 0
    keep = ~remote
    cols = np.arange(payload.shape[1])
    data_rows = np.where(cols[None, :] < length[:, None], payload, 0).astype(np.uint8)
    acc.records += count
    acc.errors += int(remote.sum())
    acc.parts.append((_seconds(ticks[keep], (flags[keep] == _TEN_MICROS), start), ident[keep] & 0x1FFFFFFF,
                      (ident[keep] & _EXTENDED) != 0, Payloads(np.ascontiguousarray(data_rows[keep]), length[keep])))
    return count


class _Objects:
    """The objects inside a BLF file's containers, read across containers as python-can reads them."""

    def __init__(self, start: float) -> None:
        self.start = start
        self.tail = b""

    def container(self, data: bytes) -> tuple[Records, Exception | None]:
        """The frames of one container's data (after what the container before left), and the error that
        stopped them (None: read to its end or to an object continued in the next container)."""
        if self.tail:
            data = b"".join((self.tail, data))
        acc = _Acc()
        try:
            self.tail = data[self._parse(data, acc):]
        except Exception as exc:  # noqa: BLE001 - BLFParseError: raised after the frames before it
            return acc.records_of(self.start), exc
        return acc.records_of(self.start), None

    def _parse(self, data: bytes, acc: _Acc) -> int:
        view = np.frombuffer(data, dtype=np.uint8)
        max_pos = len(data)
        pos = 0
        start = self.start
        while True:
            here = pos
            try:
                pos = data.index(b"LOBJ", pos, pos + 8)
            except ValueError:
                if pos + 8 > max_pos:
                    return here  # not enough data in this container
                raise _parse_error("Could not find next object") from None
            try:
                signature, header_size, version, size, kind = _BASE.unpack_from(data, pos)
            except struct.error:
                return here
            if signature != b"LOBJ":
                raise _parse_error()
            if size < _BASE.size:  # python-can's reader would read this object again and again
                raise _parse_error(f"Object of {size} bytes, shorter than its header")
            next_pos = pos + size
            if next_pos > max_pos:
                return here  # this object continues in the next container
            if version not in (1, 2):
                pos = next_pos  # an unknown object header version: skipped
                continue
            header = _BASE.size + (_V1.size if version == 1 else _V2.size)
            frame = _RUNS.get(kind)
            if frame is not None and size % 4 == 0 and size >= header + frame.size and header_size == header:
                pos += size * _run(data, view, pos, size, kind, header, acc, start)
                continue
            try:
                self._one(data, pos, kind, version, size, header_size, acc)
            except struct.error:
                return here
            pos = next_pos

    def _one(self, data: bytes, pos: int, kind: int, version: int, size: int, header_size: int,
             acc: _Acc) -> None:
        """The object at ``pos`` read alone (an object of another type: skipped)."""
        at = pos + _BASE.size
        if version == 1:
            flags, _, _, ticks = _V1.unpack_from(data, at)
            at += _V1.size
        else:
            flags, _, _, ticks = _V2.unpack_from(data, at)
            at += _V2.size
        frame: tuple[int, bytes] | None = None  # (id field, payload); None: an error or remote frame
        if kind in (_CAN_MESSAGE, _CAN_MESSAGE2):
            _, fflags, dlc, ident, payload = _CAN.unpack_from(data, at)
            frame = None if fflags & _REMOTE else (ident, payload[:dlc])
        elif kind == _CAN_ERROR_EXT:
            _ERROR_EXT.unpack_from(data, at)
        elif kind == _CAN_FD_MESSAGE:
            _, fflags, _, ident, _, _, _, valid, payload = _CAN_FD.unpack_from(data, at)
            frame = None if fflags & _REMOTE else (ident, payload[:valid])
        elif kind == _CAN_FD_MESSAGE_64:
            fields = _CAN_FD_64.unpack_from(data, at)
            valid, ident, fd_flags, ext_offset = fields[2], fields[4], fields[6], fields[13]
            length = min(valid, (ext_offset or size) - header_size - _CAN_FD_64.size)
            start = at + _CAN_FD_64.size
            frame = None if fd_flags & 0x0010 else (ident, data[start:start + length].ljust(valid, b"\x00"))
        else:
            return
        acc.records += 1
        if frame is None:
            acc.errors += 1
        else:
            acc.rows.append((ticks, flags == _TEN_MICROS, *frame))


def blf_records(reader: Any) -> Iterator[Records]:
    """The records of the BLF file ``reader`` (a ``can.BLFReader`` that has read the header), a container at a
    time; raises python-can's errors where python-can's reader raises them."""
    fh = reader.file
    objects = _Objects(float(reader.start_timestamp))
    while True:
        head = fh.read(_BASE.size)
        if not head:
            return
        signature, _, _, size, kind = _BASE.unpack(head)
        if signature != b"LOBJ":
            raise _parse_error()
        body = fh.read(size - _BASE.size)
        fh.read(size % 4)
        if kind != _LOG_CONTAINER:
            continue
        method, _ = _CONTAINER.unpack_from(body)
        packed = body[_CONTAINER.size:]
        if method == _NO_COMPRESSION:
            data = packed
        elif method == _ZLIB:
            data = zlib.decompressobj().decompress(packed)
        else:
            continue  # an unknown compression method: python-can skips the container
        records, failure = objects.container(data)
        yield records
        if failure is not None:
            raise failure
