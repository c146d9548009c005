"""A DBC message's frames decoded all at once: each signal of a stack of payloads with numpy.

:func:`decode_frames` gives, for the frames of one message, what cantools' ``msg.decode(payload,
decode_choices=False, scaling=True)`` gives frame by frame, as arrays: the same values (bit for bit,
as floats) and the same frames refused. A frame decodes when its payload has at least the
message's length in bytes (a longer one is cut to it, as cantools cuts it); its signals are read
from the payload as one integer: Intel (little-endian) signals from the payload read
least-significant byte first, Motorola (big-endian) ones from the payload read most-significant
byte first, any start bit and any length up to 64 bits, signed (two's complement) or unsigned, or
an IEEE half, single or double float; then ``raw * scale + offset`` as cantools computes it (exact
integer arithmetic when scale and offset are integers, floating point otherwise).

What it does not decode itself it hands to cantools frame by frame (:func:`decode_each`): a
multiplexed message, a container, a float signal of another length, signals that overlap or lie
outside the message. :func:`vectorised` says which a message is.

The payloads come as a :class:`Payloads` stack (frames x bytes, each frame's length beside it).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

__all__ = ["Decoded", "Payloads", "Records", "decode_each", "decode_frames", "unsigned_raw", "vectorised"]

#: integers below this in magnitude are exact as float64
_EXACT = float(1 << 53)
_FLOATS = {16: np.float16, 32: np.float32, 64: np.float64}


@dataclass(frozen=True)
class Payloads:
    """Frames' payloads: ``data`` (frames, width) uint8, each row's first ``length[i]`` bytes the frame's
    (the rest zero), ``length`` (frames,) int64."""

    data: np.ndarray
    length: np.ndarray

    def __post_init__(self) -> None:
        if not isinstance(self.data, np.ndarray) or self.data.dtype != np.uint8 or self.data.ndim != 2:
            raise ValueError("Payloads.data: expected a (frames, bytes) uint8 array")
        if (not isinstance(self.length, np.ndarray) or self.length.dtype != np.int64
                or self.length.shape != (self.data.shape[0],)):
            raise ValueError(f"Payloads.length: expected ({self.data.shape[0]},) int64, one length per frame")
        if self.length.size and (int(self.length.min()) < 0 or int(self.length.max()) > self.data.shape[1]):
            raise ValueError(f"Payloads.length: each must be in 0..{self.data.shape[1]} (the width of data)")

    @classmethod
    def of(cls, payloads: Sequence[bytes], width: int = 0) -> Payloads:
        """The stack of ``payloads`` (at least ``width`` bytes wide)."""
        length = np.fromiter((len(p) for p in payloads), dtype=np.int64, count=len(payloads))
        wide = max(int(length.max()) if length.size else 0, width)
        data = np.zeros((len(payloads), wide), dtype=np.uint8)
        for size in np.unique(length).tolist():
            if not size:
                continue
            rows = np.flatnonzero(length == size)
            joined = b"".join([payloads[i] for i in rows.tolist()])
            data[rows, :size] = np.frombuffer(joined, dtype=np.uint8).reshape(rows.size, size)
        return cls(data, length)

    @classmethod
    def join(cls, parts: Sequence[Payloads]) -> Payloads:
        """The frames of ``parts`` one after the other."""
        wide = max((p.data.shape[1] for p in parts), default=0)
        data = np.zeros((sum(len(p) for p in parts), wide), dtype=np.uint8)
        at = 0
        for p in parts:
            data[at:at + len(p), :p.data.shape[1]] = p.data
            at += len(p)
        return cls(data, np.concatenate([p.length for p in parts]) if parts else np.zeros(0, dtype=np.int64))

    def __len__(self) -> int:
        return int(self.length.size)

    def take(self, rows: np.ndarray) -> Payloads:
        """The frames ``rows`` (indices or a mask)."""
        return Payloads(self.data[rows], self.length[rows])

    def row(self, i: int) -> bytes:
        """Frame ``i``'s payload."""
        return self.data[i, :int(self.length[i])].tobytes()

    def rows(self) -> list[bytes]:
        """Every frame's payload, in order."""
        return [self.row(i) for i in range(len(self))]


@dataclass(frozen=True)
class Records:
    """A stretch of a log's records as a fast reader gives them: ``records`` in all, ``errors`` of them error
    or remote frames (left out); the data frames' ``t`` (s), ``ids`` (arbitration ids), ``extended``,
    ``data``."""

    records: int
    errors: int
    t: np.ndarray
    ids: np.ndarray
    extended: np.ndarray
    data: Payloads


def _bits(sig: Any) -> tuple[int, int]:
    """The signal's lowest bit and its length, numbered in the payload read as one integer the signal's way:
    Intel signals least-significant byte first (bit = start), Motorola ones most-significant byte first."""
    if sig.byte_order == "little_endian":
        return int(sig.start), int(sig.length)
    network = 8 * (int(sig.start) // 8) + 7 - int(sig.start) % 8  # the MSB, counted from the first byte's MSB
    return network, int(sig.length)


def _layout_ok(msg: Any) -> bool:
    """Every signal inside the message's bytes and none overlapping another (what cantools' codec assumes)."""
    size = 8 * int(msg.length)
    used = np.zeros(size, dtype=bool)
    for sig in msg.signals:
        start, n = _bits(sig)
        if n < 1 or n > 64:
            return False
        if sig.byte_order == "little_endian":
            bits = np.arange(start, start + n)
            if start < 0 or start + n > size:
                return False
            bits = (bits // 8) * 8 + bits % 8  # byte, bit within it
        else:
            if start < 0 or start + n > size:
                return False
            net = np.arange(start, start + n)
            bits = (net // 8) * 8 + 7 - net % 8
        if used[bits].any():
            return False
        used[bits] = True
    return True


def vectorised(msg: Any) -> bool:
    """Does :func:`decode_frames` decode ``msg`` itself (not a multiplexed message, a container, a float
    signal of a length other than 16, 32 or 64 bits, or overlapping signals)?"""
    if getattr(msg, "is_container", False) or msg.is_multiplexed():
        return False
    if any(sig.is_float and int(sig.length) not in _FLOATS for sig in msg.signals):
        return False
    return _layout_ok(msg)


def _raw_bits(data: np.ndarray, sig: Any) -> np.ndarray:
    """The signal's raw bits (frames,) uint64 from payloads ``data`` (frames, message length)."""
    width = data.shape[1]
    start, n = _bits(sig)
    if sig.byte_order == "little_endian":
        first, last = start // 8, (start + n - 1) // 8
        order = list(range(first, last + 1))  # least significant first
        shift = start % 8
    else:
        first, last = start // 8, (start + n - 1) // 8
        order = list(range(last, first - 1, -1))
        shift = 8 * (last + 1) - (start + n)
    assert last < width
    value = np.zeros(data.shape[0], dtype=np.uint64)
    for j, b in enumerate(order[:8]):
        value |= data[:, b].astype(np.uint64) << np.uint64(8 * j)
    value >>= np.uint64(shift)
    if len(order) == 9:  # a 64-bit signal not on a byte boundary: its top bits in a ninth byte
        value |= data[:, order[8]].astype(np.uint64) << np.uint64(64 - shift)
    if n < 64:
        value &= np.uint64((1 << n) - 1)
    return value


def _conversion(sig: Any) -> tuple[str, Any, Any]:
    """How cantools scales ``sig`` (its conversion factory's choice, choices aside): ("identity" | "integer" |
    "linear", scale, offset)."""
    scale, offset = sig.scale, sig.offset
    if scale == 1 and offset == 0:
        return "identity", scale, offset

    def integral(v: Any) -> bool:
        return isinstance(v, int) or (hasattr(v, "is_integer") and bool(v.is_integer()))

    if integral(scale) and integral(offset) and not sig.is_float:
        return "integer", int(scale), int(offset)
    return "linear", scale, offset


def _scaled(sig: Any, raw: np.ndarray) -> np.ndarray:
    """``raw`` (uint64 bits) as cantools' scaled value, float64."""
    n = int(sig.length)
    if sig.is_float:
        value = raw.astype(np.uint64 if n == 64 else np.uint32 if n == 32 else np.uint16)
        with np.errstate(invalid="ignore"):  # a NaN payload stays NaN
            floats = value.view(_FLOATS[n]).astype(np.float64)
        kind, scale, offset = _conversion(sig)
        if kind == "identity":
            return floats
        with np.errstate(over="ignore", invalid="ignore"):
            return floats * float(scale) + float(offset)
    if sig.is_signed:
        ints: np.ndarray = raw.view(np.int64).copy()
        if n < 64:  # two's complement of n bits: the sign bit copied into the bits above it
            negative = ((raw >> np.uint64(n - 1)) & np.uint64(1)) == 1
            ints[negative] = (raw[negative] | np.uint64(((1 << 64) - 1) ^ ((1 << n) - 1))).view(np.int64)
        lo, hi = (-(2.0 ** (n - 1)), 2.0 ** (n - 1))
    else:
        ints = raw
        lo, hi = 0.0, 2.0 ** n
    kind, scale, offset = _conversion(sig)
    if kind == "identity":
        return ints.astype(np.float64)  # int to float64: rounded to nearest once, as Python's float(int)
    if kind == "linear" and max(abs(lo), abs(hi)) < _EXACT and not (isinstance(scale, int) and abs(scale) >= _EXACT):
        # float(raw) is exact: raw * scale rounds once in both (an integer scale to the exact product's float)
        with np.errstate(over="ignore", invalid="ignore"):
            return ints.astype(np.float64) * float(scale) + float(offset)
    if kind == "integer" and max(abs(lo), abs(hi)) * abs(scale) + abs(offset) < _EXACT:
        return ints.astype(np.float64) * float(scale) + float(offset)  # every step exact
    # Python's arithmetic on Python ints, element by element: exact where floats would round twice
    exact = ints.astype(object) * scale + offset
    return np.array([_float(v) for v in exact.tolist()], dtype=np.float64)


def _float(v: Any) -> float:
    """``float(v)``, and an integer beyond the float range as an infinity (not an OverflowError)."""
    try:
        return float(v)
    except OverflowError:
        return math.inf if v > 0 else -math.inf


@dataclass(frozen=True)
class Decoded:
    """Frames of one message decoded: ``ok`` (frames,) whether each decoded; per signal name, ``values``
    float64 and ``carried`` whether the frame carries it (it decoded, and a multiplexed signal's
    multiplexer selects it); a value not carried is NaN."""

    ok: np.ndarray
    values: dict[str, np.ndarray]
    carried: dict[str, np.ndarray]


def decode_each(msg: Any, payloads: Payloads, signals: Sequence[str]) -> Decoded:
    """Frames of ``msg`` decoded by cantools one at a time into ``signals``."""
    ok = np.ones(len(payloads), dtype=bool)
    names = list(dict.fromkeys(signals))
    values = {name: np.full(len(payloads), np.nan) for name in names}
    carried = {name: np.zeros(len(payloads), dtype=bool) for name in names}
    for r in range(len(payloads)):
        try:
            v = msg.decode(payloads.row(r), decode_choices=False, scaling=True)
        except Exception:  # cantools: DecodeError, a wrong length, an unknown multiplexer value, ...
            ok[r] = False
            continue
        for name in names:
            if name in v:
                values[name][r] = _float(v[name])
                carried[name][r] = True
    return Decoded(ok, values, carried)


def decode_frames(msg: Any, payloads: Payloads, signals: Sequence[str]) -> Decoded:
    """Frames of ``msg`` decoded into ``signals`` at once (see the module docs; cantools refuses a payload
    shorter than the message). A message :func:`vectorised` refuses is decoded by :func:`decode_each`."""
    by_name = {sig.name: sig for sig in msg.signals}
    missing = [name for name in signals if name not in by_name]
    if missing:
        raise ValueError(f"signals: message {msg.name} has no signal {missing[0]!r}")
    if not vectorised(msg):
        return decode_each(msg, payloads, signals)
    size = int(msg.length)
    ok = payloads.length >= size
    data = payloads.data[:, :size]
    if data.shape[1] < size:
        data = np.zeros((data.shape[0], size), dtype=np.uint8)  # no frame is long enough: none decodes
    values: dict[str, np.ndarray] = {}
    for name in dict.fromkeys(signals):
        value = _scaled(by_name[name], _raw_bits(data, by_name[name]))
        value[~ok] = math.nan
        values[name] = value
    return Decoded(ok, values, {name: ok for name in values})


def unsigned_raw(msg: Any, payloads: Payloads, name: str) -> tuple[np.ndarray, np.ndarray]:
    """The unsigned integer signal ``name`` of ``msg`` unscaled (a counter): whether each frame decoded and
    carries it, and its raw value (frames,) uint64 (0 where not)."""
    sig = next((s for s in msg.signals if s.name == name), None)
    if sig is None or sig.is_float or sig.is_signed:
        raise ValueError(f"signals: message {msg.name} has no unsigned integer signal {name!r}")
    if vectorised(msg):
        size = int(msg.length)
        ok = payloads.length >= size
        raw = np.zeros(len(payloads), dtype=np.uint64)
        if size <= payloads.data.shape[1]:
            raw[ok] = _raw_bits(payloads.data[ok, :size], sig)
        return ok, raw
    ok = np.zeros(len(payloads), dtype=bool)
    raw = np.zeros(len(payloads), dtype=np.uint64)
    for r in range(len(payloads)):
        try:
            raw[r] = int(msg.decode(payloads.row(r), decode_choices=False, scaling=False)[name])
        except Exception:  # noqa: BLE001 - any frame that does not decode (or does not carry it)
            continue
        ok[r] = True
    return ok, raw
