"""Bus recordings: decode a CAN log with a DBC and align its signals on a sample clock.

Read by ``pyrhonn identify --can-log RUN --dbc FILE``; the result is the same
arrays a CSV file gives (:class:`pyrhonn.datafile.Data`): states with a
validity mask, inputs, times. :func:`read_bus_log` holds the log and its
samples whole; :mod:`pyrhonn.buslogstream` gives the same samples a chunk of
frames at a time, with the same helpers (:func:`_plan`, :func:`_decode`,
:func:`_gather`, the clock's :func:`_tick_on` and :func:`_count_on`).

The binding (:class:`BusMap`, the ``[bus]`` table of a config file)
----------------------------------------------------------------------
Every state and input names one DBC signal as ``"Message.Signal"``::

    [bus]
    sample_period = 0.01          # s; default: the clock message's cycle time in the DBC
    clock = "Sensors"             # the message whose frames are the samples; default: the first state's
    counter = "Sensors.Seq"       # optional: the clock frames' sequence counter (unsigned, +1 a sample)
    window_start = -0.5           # in sample periods, -1..0 (default -0.5, see below)

    [bus.signals]                 # every state and input of the config
    x1 = "Sensors.Position"
    u = "Command.Voltage"

    [bus.valid]                   # optional: a state's "measurement updated" flag, in the same frame
    x1 = "Sensors.PositionValid"

The sample clock
----------------
- Each frame of the clock message is one sample, at its timestamp tau_k; the
  clock follows the sender's own oscillator, so a sender whose clock drifts
  against the logger's does not walk off a fixed grid.
- Without a ``counter``: two consecutive clock frames D apart with
  round(D / T) = n > 1 mean n - 1 lost clock frames, and n - 1 samples are
  inserted, evenly spaced between them. A clock frame less than T/2 after
  the previous one (n = 0) is a repeat of the same sample.
- With a ``counter`` (a sequence number the sender adds 1 to each sample,
  wrapping at 2^bits), a frame's sample is its counter, unwrapped: lost
  frames are the numbers skipped, and a sender that stalls and then sends
  its backlog in a burst keeps every sample in place. Use one when the log
  has one.
- The clock message's own signals come from the sample's own frame. Any
  other message's frames count for sample k if received in
  ``[tau_k + a T, tau_{k+1} + a T)`` (a = ``window_start``); these windows
  tile the log. The default a = -1/2 centres them on the clock frames, so
  messages sent up to half a period before or after the clock message,
  each cycle, count for that cycle. Frames before the first window or
  after the last are not used.

Missing and late messages
-------------------------
A signal's value at sample k is the one decoded from the latest frame
carrying it in sample k's window. Nothing else is ever used:

- No frame in the window (lost, not sent, or late: arrived in a later
  window): the state is **not valid** at k. The identifier neither learns
  from it nor feeds it back (it uses its own prediction,
  :meth:`pyrhonn.Identifier.run`); no value is held or interpolated.
- A late frame that lands in the next sample's window is taken for that
  sample if it is the latest there; an earlier frame in a window is
  superseded (counted). A log carries no sample index: a frame late by
  more than a period cannot be told from the next sample's.
- A frame whose data does not decode (a length the DBC does not give, an
  unknown multiplexer value), a non-finite value, or a ``[bus.valid]`` flag
  of 0: not valid at k, counted per signal.
- Inputs have no validity: u(k) is needed to step. Samples at the start
  and end of the log without every input are cut off (said so). A sample
  inside the run without every input (its frame lost, a lost clock frame
  that carried them) is a **lost sample**, never filled in: the record is
  split there into segments as the firmware does (:mod:`pyrhonn.gaps`:
  the sample after the gap is not stepped, the identifier restarts on the
  next, and every gap is counted and reported per segment).

A multiplexed signal counts only in the frames whose multiplexer selects it.
A ``[bus.valid]`` flag must be carried by every frame that carries its
value (same message, and not under another multiplexer value).

Supported logs: ``.blf`` and ``.asc`` (Vector; python-can's ``can.Logger``
writes both), ``.log`` (candump ``-l``), ``.mf4`` (an ASAM MDF4 bus log of
CAN frames, read with asammdf). Candump, BLF and MDF4 logs are read a block of frames at a time
into arrays (:mod:`pyrhonn.candump`, :mod:`pyrhonn.blf`, :mod:`pyrhonn.mdfbus`), ASC logs and what
those do not read by python-can's readers, with the same frames; each message's frames are decoded
at once (:mod:`pyrhonn.framedecode`, cantools' values). A log cut short (an ASC without its
``End TriggerBlock``, a BLF shorter than its header records, cut inside an
object or whose header was never completed, a text log whose last line is
cut) is refused naming what is missing, or with ``partial``
(``--partial-log``) its complete part is read and the report says what is
missing. Frames of every channel count;
error and remote frames are skipped. Every defect raises ``ValueError``
naming the file, option, key or signal (and the frame, or the line of a
candump log).
"""
from __future__ import annotations

import difflib
import io
import math
import re
import struct
import weakref
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator, Mapping, Sequence

import numpy as np

from .asc import AscBlocks
from .blf import blf_records
from .candump import parse_block
from .framedecode import Payloads, decode_frames, unsigned_raw
from .mdfbus import mdf_records
from .mdfsignals import cut_read, is_mdf, require_asammdf
from .validation import near_names

__all__ = ["Aligned", "AlignedSummary", "BusMap", "LOG_SUFFIXES", "SignalRef", "SignalStats", "align", "load_dbc", "read_bus_log",
           "read_frames"]

#: the log formats read, by file name suffix
LOG_SUFFIXES = (".blf", ".asc", ".log", ".mf4")
_REF = re.compile(r"([A-Za-z_][A-Za-z0-9_]*)\.([A-Za-z_][A-Za-z0-9_]*)\Z")
_KEYS = ("sample_period", "clock", "counter", "window_start", "signals", "valid")
_WINDOW_RANGE = (-1.0, 0.0)
#: clock frames whose samples are computed at once (up to a repeated one)
_TICK_STRETCH = 1 << 14
#: the clock frames' median interval may differ from the sample period by this fraction
PERIOD_TOLERANCE = 0.25


@dataclass(frozen=True)
class SignalRef:
    """A DBC signal ``message.signal``; ``origin`` names where it was given
    (a config key or a command-line option), for error messages."""

    message: str
    signal: str
    origin: str = field(default="", compare=False)

    @classmethod
    def parse(cls, text: object, origin: str) -> SignalRef:
        if not isinstance(text, str):
            raise ValueError(f"{origin}: expected a string \"Message.Signal\", got {type(text).__name__}")
        found = _REF.match(text.strip())
        if not found or text != text.strip():
            raise ValueError(f"{origin}: expected \"Message.Signal\" (a DBC message name, a dot, one of its "
                             f"signals), got {text!r}")
        return cls(found.group(1), found.group(2), origin)

    def __str__(self) -> str:
        return f"{self.message}.{self.signal}"


def _real(path: str, value: object, lo: float | None = None, hi: float | None = None,
          positive: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"{path}: expected a number, got {type(value).__name__}")
    v = float(value)
    if not math.isfinite(v):
        raise ValueError(f"{path}: expected a finite number, got {value!r}")
    if positive and not v > 0:
        raise ValueError(f"{path}: must be > 0, got {value!r}")
    if (lo is not None and v < lo) or (hi is not None and v > hi):
        raise ValueError(f"{path}: must be in {lo}..{hi}, got {value!r}")
    return v


@dataclass(frozen=True)
class BusMap:
    """Which DBC signal carries each state and input, and the sample clock
    (see the module docs). ``signals`` and ``valid`` map config names to
    :class:`SignalRef`; ``sample_period`` (s) and ``clock`` (a message name)
    may be None (then the DBC's cycle time and the first state's message)."""

    signals: Mapping[str, SignalRef] = field(default_factory=dict)
    valid: Mapping[str, SignalRef] = field(default_factory=dict)
    sample_period: float | None = None
    clock: str | None = None
    window_start: float = -0.5
    counter: SignalRef | None = None

    def __post_init__(self) -> None:
        for key in ("signals", "valid"):
            table = getattr(self, key)
            if not isinstance(table, Mapping):
                raise ValueError(f"bus.{key}: expected a mapping of names to SignalRef, got {type(table).__name__}")
            for name, ref in table.items():
                if not isinstance(ref, SignalRef):
                    raise ValueError(f"bus.{key}.{name}: expected a SignalRef, got {type(ref).__name__}")
        if self.sample_period is not None:
            _real("bus.sample_period", self.sample_period, positive=True)
        if self.clock is not None and (not isinstance(self.clock, str) or not self.clock):
            raise ValueError(f"bus.clock: expected a message name, got {self.clock!r}")
        _real("bus.window_start", self.window_start, *_WINDOW_RANGE)
        if self.counter is not None and not isinstance(self.counter, SignalRef):
            raise ValueError(f"bus.counter: expected a SignalRef, got {type(self.counter).__name__}")
        for name in self.valid:
            if name not in self.signals:
                raise ValueError(f"bus.valid.{name}: a validity flag for {name!r}, which bus.signals does not "
                                 "map to a signal")

    @classmethod
    def from_table(cls, table: object, state_names: Sequence[str], input_names: Sequence[str],
                   path: str = "bus") -> BusMap:
        """The ``[bus]`` table of a config file (a dict from TOML), checked
        against the config's names; errors name the key (``bus.signals.x9``)."""
        if not isinstance(table, dict):
            raise ValueError(f"{path}: expected a table, got {type(table).__name__}")
        for key in table:
            if key not in _KEYS:
                close = difflib.get_close_matches(key, _KEYS, n=1)
                hint = f"; did you mean {close[0]!r}?" if close else ""
                raise ValueError(f"{path}.{key}: unknown key{hint} (allowed here: {', '.join(_KEYS)})")
        names = list(state_names) + list(input_names)
        tables: dict[str, dict[str, SignalRef]] = {}
        for key, allowed in (("signals", names), ("valid", list(state_names))):
            raw = table.get(key, {})
            if not isinstance(raw, dict):
                raise ValueError(f"{path}.{key}: expected a table of name = \"Message.Signal\", got "
                                 f"{type(raw).__name__}")
            refs: dict[str, SignalRef] = {}
            for name, text in raw.items():
                where = f"{path}.{key}.{name}"
                if name not in allowed:
                    close = difflib.get_close_matches(name, allowed, n=1)
                    hint = f"; did you mean {close[0]!r}?" if close else ""
                    what = "states and inputs" if key == "signals" else "states"
                    raise ValueError(f"{where}: {name!r} is not one of the config's {what}{hint} "
                                     f"({', '.join(allowed)})")
                refs[name] = SignalRef.parse(text, where)
            tables[key] = refs
        period = table.get("sample_period")
        clock = table.get("clock")
        if clock is not None and (not isinstance(clock, str) or not _REF.match(f"{clock}.x")):
            raise ValueError(f"{path}.clock: expected a DBC message name, got {clock!r}")
        return cls(signals=tables["signals"], valid=tables["valid"],
                   sample_period=None if period is None else _real(f"{path}.sample_period", period, positive=True),
                   clock=clock,
                   counter=None if table.get("counter") is None else SignalRef.parse(table["counter"], f"{path}.counter"),
                   window_start=_real(f"{path}.window_start", table.get("window_start", -0.5), *_WINDOW_RANGE))

    def to_table(self) -> dict[str, Any]:
        """The ``[bus]`` table, as :meth:`from_table` reads it."""
        out: dict[str, Any] = {}
        if self.sample_period is not None:
            out["sample_period"] = float(self.sample_period)
        if self.clock is not None:
            out["clock"] = self.clock
        if self.counter is not None:
            out["counter"] = str(self.counter)
        if self.window_start != -0.5:
            out["window_start"] = float(self.window_start)
        out["signals"] = {name: str(ref) for name, ref in self.signals.items()}
        if self.valid:
            out["valid"] = {name: str(ref) for name, ref in self.valid.items()}
        return out


# -- the DBC ------------------------------------------------------------------------------------------


def load_dbc(path: str | Path, option: str = "--dbc") -> Any:
    """The cantools database of the DBC file ``path``; a ValueError naming
    ``option`` and the file (with cantools' line and column) if it does not parse."""
    import cantools

    p = Path(path)
    if not p.is_file():
        raise ValueError(f"{option} {path}: no such file{near_names(p)}")
    try:
        return cantools.database.load_file(str(p), database_format="dbc", strict=True)
    except UnicodeDecodeError as exc:
        raise ValueError(f"{option} {path}: not a DBC file (not text: byte {exc.start})") from None
    except Exception as exc:  # cantools raises its ParseError, ValueError, KeyError ... on a bad DBC
        text = " ".join(str(exc).split()) or type(exc).__name__
        raise ValueError(f"{option} {path}: not a DBC file cantools can parse: {text[:300]}") from None


def _message(db: Any, name: str, origin: str, dbc: str) -> Any:
    try:
        return db.get_message_by_name(name)
    except KeyError:
        names = [m.name for m in db.messages]
        close = difflib.get_close_matches(name, names, n=1)
        hint = f"; did you mean {close[0]!r}?" if close else ""
        raise ValueError(f"{origin}: no message {name!r} in {dbc}{hint} (it has: "
                         f"{', '.join(names[:20])}{' ...' if len(names) > 20 else ''})") from None


def _signal(db: Any, ref: SignalRef, dbc: str) -> tuple[Any, Any]:
    msg = _message(db, ref.message, f"{ref.origin}: {str(ref)!r}", dbc)
    for sig in msg.signals:
        if sig.name == ref.signal:
            return msg, sig
    names = [s.name for s in msg.signals]
    close = difflib.get_close_matches(ref.signal, names, n=1)
    hint = f"; did you mean {close[0]!r}?" if close else ""
    raise ValueError(f"{ref.origin}: {str(ref)!r}: message {ref.message} has no signal {ref.signal!r}{hint} "
                     f"(its signals: {', '.join(names)})")


def _mux_values(msg: Any, sig: Any) -> frozenset[int] | None:
    """The multiplexer values under which ``sig`` is sent (None: in every frame)."""
    ids = getattr(sig, "multiplexer_ids", None)
    return None if not ids else frozenset(int(i) for i in ids)


# -- reading logs -------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Frames:
    """The data frames of a log in time order: ``t`` (N,) log timestamps in
    s, ``ids`` (N,) arbitration ids, ``extended`` (N,) bool, ``data`` the
    payloads (:class:`pyrhonn.framedecode.Payloads`); ``skipped`` error and remote frames; ``incomplete`` what a
    log read with ``partial`` misses (None: the log is complete)."""

    t: np.ndarray
    ids: np.ndarray
    extended: np.ndarray
    data: Payloads
    skipped: int
    incomplete: str | None = None


def _candump_line(path: Path, frame: int) -> int:
    """The line of a candump log holding its ``frame``-th record (0-based; the reader skips blank lines)."""
    seen = -1
    with open(path, "rb") as fh:
        for line_no, line in enumerate(fh, start=1):
            if line.strip():
                seen += 1
                if seen == frame:
                    return line_no
    return line_no + 1 if seen >= 0 else 1


#: the most bytes of a log read (a text log is held whole while it is checked)
MAX_LOG_BYTES = 1 << 31
_BLF_OBJ = struct.Struct("<4sHHII")  # signature, header size, header version, object size, object type
_BLF_CONTAINER = struct.Struct("<H6xL4x")  # compression method, uncompressed size
_BLF_LOG_CONTAINER = 10
#: the largest uncompressed container read (loggers write 128 KiB; a larger one is a damaged size field)
MAX_BLF_CONTAINER = 1 << 26
_PARTIAL_HINT = "; read what is there with --partial-log"


def _blf_completeness(p: Path, declared_size: int, declared_objects: int, where: str) -> str | None:
    """What a BLF file misses, from its header and its objects' sizes (None: complete). Walks the
    object headers without decompressing: the last one must end inside the file. A container that
    declares more than :data:`MAX_BLF_CONTAINER` bytes uncompressed is refused (``where`` names the
    file) before anything is decompressed."""
    actual = p.stat().st_size
    found: list[str] = []
    if declared_size > actual:  # the header, written when the logger stopped, says how long the file was
        found.append(f"its BLF header records {declared_size:,} bytes, the file has {actual:,} "
                     f"({100.0 * (declared_size - actual) / declared_size:.1f} % missing)")
    count = 0
    with open(p, "rb") as fh:
        head = fh.read(8)
        pos = int.from_bytes(head[4:8], "little") if len(head) == 8 else actual
        while pos < actual:
            fh.seek(pos)
            raw = fh.read(_BLF_OBJ.size)
            if len(raw) < _BLF_OBJ.size:
                found.append(f"cut inside an object header at byte {pos:,} of {actual:,}")
                break
            sig, _, _, size, kind = _BLF_OBJ.unpack(raw)
            if kind == _BLF_LOG_CONTAINER and size >= _BLF_OBJ.size + _BLF_CONTAINER.size:
                _, inflated = _BLF_CONTAINER.unpack(fh.read(_BLF_CONTAINER.size))
                if inflated > MAX_BLF_CONTAINER:
                    raise ValueError(f"{where}: object {count + 1} (a container, at byte {pos:,}) declares "
                                     f"{inflated:,} bytes uncompressed, more than the {MAX_BLF_CONTAINER:,} read; "
                                     "the file is damaged there")
            if sig != b"LOBJ" or size < _BLF_OBJ.size:
                found.append(f"no object where one should start, at byte {pos:,} (the file is damaged there)")
                break
            if pos + size > actual:
                found.append(f"cut inside its object {count + 1} (a container) at byte {pos:,}: it declares "
                             f"{size:,} bytes, {actual - pos:,} are there")
                break
            pos += size + size % 4
            count += 1
    if declared_objects == 0 and count:
        found.append("its header was never completed (0 objects, written when the logger stops): the logger did "
                     "not finish the file")
    return "; ".join(found) or None


class _WholeLines:
    """A text log's lines up to byte ``end`` (its last whole line), decoded as a reader iterates them:
    the file is never held whole."""

    def __init__(self, path: Path, end: int) -> None:
        self._fh = open(path, "rb")
        self._end = end
        self._pos = 0  # bytes read (a reader may iterate the lines twice: its header, then its frames)

    def __iter__(self) -> Iterator[str]:
        for raw in self._fh:
            self._pos += len(raw)
            if self._pos > self._end:
                return
            yield raw.decode("utf-8", errors="replace")

    def blocks(self, size: int = 1 << 20) -> Iterator[bytes]:
        """The lines as blocks of about ``size`` bytes, each of whole lines (not decoded); then the file closed."""
        try:
            pos, carry = 0, b""
            while pos < self._end:
                raw = self._fh.read(min(size, self._end - pos))
                if not raw:
                    break
                pos += len(raw)
                text = carry + raw
                cut = text.rfind(b"\n") + 1
                if cut:
                    yield text[:cut]
                carry = text[cut:]
            if carry:
                yield carry
        finally:
            self._fh.close()

    def close(self) -> None:
        self._fh.close()


def _text_completeness(p: Path, suffix: str) -> tuple[str | None, int]:
    """What a text log misses (None: complete) and how many of its bytes to read: up to its last whole
    line. Reads its end (and counts its lines only when the last one is cut)."""
    size = p.stat().st_size
    with open(p, "rb") as fh:
        back = 4096
        while True:  # the tail back to a line end (or the whole file)
            fh.seek(max(size - back, 0))
            tail = fh.read()
            if b"\n" in tail[:-1] or back >= size:
                break
            back *= 4
        cut = not tail.endswith(b"\n")
        end = size - (len(tail) - tail.rfind(b"\n") - 1) if cut else size
        missing: list[str] = []
        if cut:
            fh.seek(0)
            lines = sum(chunk.count(b"\n") for chunk in iter(lambda: fh.read(1 << 20), b""))
            missing.append(f"its last line ({lines + 1}) is cut short (no end of line)")
    if suffix == ".asc":
        whole = [ln.strip() for ln in tail[:len(tail) - (size - end)].splitlines() if ln.strip()]
        if not whole or whole[-1] != b"End TriggerBlock":
            missing.append("it does not end with 'End TriggerBlock' (written when the logger stops): the rest "
                           "of the recording is missing")
    return ("; ".join(missing) or None), end


#: records a python-can reader gives before they are stacked into a block
_PART = 1 << 12


@dataclass(frozen=True)
class FrameBlock:
    """Data frames in file order: ``t`` (s), ``ids`` arbitration ids, ``extended``, ``data`` their payloads."""

    t: np.ndarray
    ids: np.ndarray
    extended: np.ndarray
    data: Payloads

    @classmethod
    def of(cls, rows: Sequence[tuple[float, int, bool, bytes]]) -> FrameBlock:
        """The block of records (timestamp, arbitration id, extended, payload)."""
        return cls(np.fromiter((r[0] for r in rows), dtype=np.float64, count=len(rows)),
                   np.fromiter((r[1] for r in rows), dtype=np.int64, count=len(rows)),
                   np.fromiter((r[2] for r in rows), dtype=bool, count=len(rows)),
                   Payloads.of([r[3] for r in rows]))

    @classmethod
    def join(cls, blocks: Sequence[FrameBlock]) -> FrameBlock:
        if len(blocks) == 1:
            return blocks[0]
        return cls(np.concatenate([b.t for b in blocks]), np.concatenate([b.ids for b in blocks]),
                   np.concatenate([b.extended for b in blocks]), Payloads.join([b.data for b in blocks]))

    def take(self, rows: np.ndarray) -> FrameBlock:
        return FrameBlock(self.t[rows], self.ids[rows], self.extended[rows], self.data.take(rows))

    def __len__(self) -> int:
        return int(self.t.size)


def latest(t: np.ndarray) -> float:
    """The latest of timestamps ``t`` (not empty) as Python's ``max`` finds it in file order (a NaN first
    stays, one later never wins)."""
    return float(t.max()) if not np.isnan(t).any() else float(max(t.tolist()))


class _Lines:
    """Lines of a text log (bytes, whole lines) as a python-can reader reads them, decoded."""

    def __init__(self, block: bytes) -> None:
        self._block = block

    def __iter__(self) -> Iterator[str]:
        for raw in io.BytesIO(self._block):  # split at newlines only, as a file is
            yield raw.decode("utf-8", errors="replace")

    def close(self) -> None:
        pass


class _Log:
    """A bus log checked up front (its format, size, and what a truncated one misses) and read record by
    record by :meth:`records`, as :func:`read_frames` and the streamed reader
    (:mod:`pyrhonn.buslogstream`) both read it: the same checks, the same messages."""

    def __init__(self, path: str | Path, option: str, partial: bool) -> None:
        p = Path(path)
        suffix = p.suffix.lower()
        if suffix not in LOG_SUFFIXES:
            raise ValueError(f"{option} {path}: unsupported log format {p.suffix or '(no suffix)'!r}; expected one of "
                             f"{', '.join(LOG_SUFFIXES)} (Vector BLF and ASC, as python-can's can.Logger writes them, "
                             "a candump -l log, or an MDF4 bus log as python-can's can.Logger writes it)")
        if not p.is_file():
            raise ValueError(f"{option} {path}: no such file{near_names(p)}")
        size = p.stat().st_size
        if size == 0:
            raise ValueError(f"{option} {path}: empty file (not a {suffix[1:].upper()} log)")
        if size > MAX_LOG_BYTES:
            raise ValueError(f"{option} {path}: {size:,} bytes, more than the {MAX_LOG_BYTES:,} read at once; cut the "
                             "recording into parts")
        self.path, self.p, self.suffix, self.option, self.partial = path, p, suffix, option, partial
        self.kind = {".blf": "a BLF", ".asc": "an ASC", ".log": "a candump", ".mf4": "an MDF4 bus"}[suffix]
        self.incomplete: str | None = None
        self.count = 0  # records read
        self.skipped = 0  # error and remote frames
        self.source: Any = str(p)
        if suffix == ".mf4":
            require_asammdf(f"{option} {path}")
            with open(p, "rb") as fh:
                ident = fh.read(64)
            if ident[:8] == b"UnFinMF ":
                self.incomplete = ("its identification block says 'UnFinMF' (not finalised: the logger did not "
                                   "finish the file)")
            elif not is_mdf(ident[:8]):
                raise ValueError(f"{option} {path}: not an MDF file (it does not start with 'MDF')")
            cut = cut_read(p, f"{option} {path}", partial, self.incomplete)
            if cut is not None:  # cut short, read ``partial``: from a repaired copy, removed with this log
                self.source = str(cut[0])
                weakref.finalize(self, cut[0].unlink, missing_ok=True)
                self.incomplete = f"{self.incomplete}; {cut[1]}" if self.incomplete else cut[1]
        elif suffix != ".blf":
            with open(p, "rb") as fh:
                head = fh.read(4096)
            if b"\0" in head:
                raise ValueError(f"{option} {path}: binary data, not {self.kind} log (text); a BLF file must be named "
                                 ".blf")
            self.incomplete, end = _text_completeness(p, suffix)
            self.source = _WholeLines(p, end)

    def records(self) -> Iterator[tuple[float, int, bool, bytes]]:
        """Every data frame in file order as (timestamp, arbitration id, extended, payload); a reader's failure
        raises the ValueError naming the frame (or candump line), unless the log is known incomplete and read
        ``partial``: then the frames before it are all."""
        with self._failures():
            yield from self._read(self.source)

    def _read(self, source: Any, **options: str) -> Iterator[tuple[float, int, bool, bytes]]:
        """The data frames python-can's reader (given ``options``) gives from ``source`` (counted in
        :attr:`count`)."""
        import can

        readers = {".blf": can.BLFReader, ".asc": can.ASCReader, ".log": can.CanutilsLogReader,
                   ".mf4": can.MF4Reader}
        with readers[self.suffix](source, **options) as reader:
            if self.suffix == ".blf":
                self._blf_checked(reader)
            for msg in reader:
                self.count += 1
                if msg.is_error_frame or msg.is_remote_frame:
                    self.skipped += 1
                    continue
                yield float(msg.timestamp), int(msg.arbitration_id), bool(msg.is_extended_id), bytes(msg.data)

    @contextmanager
    def _failures(self) -> Iterator[None]:
        """A reader's failure as the ValueError naming the frame (or candump line), or (a log known incomplete,
        read ``partial``) the end of its frames."""
        p, option, path = self.p, self.option, self.path
        try:
            yield
        except Exception as exc:  # python-can's readers raise struct.error, ValueError, BLFParseError, zlib.error ...
            if isinstance(exc, ValueError) and str(exc).startswith(f"{option} {path}: "):
                raise  # a size this module refused, already named
            if not (self.partial and self.incomplete):
                where = f"line {_candump_line(p, self.count)}" if self.suffix == ".log" else f"after frame {self.count}"
                text = " ".join(str(exc).split()) or type(exc).__name__
                why = f" ({self.incomplete})" if self.incomplete else ""
                raise ValueError(f"{option} {path}: {where}: cannot read it as {self.kind} log ({type(exc).__name__}: "
                                 f"{text[:200]}){why}") from None

    def _parts(self) -> Iterator[FrameBlock]:
        """The data frames in file order, in blocks of any size."""
        if self.suffix == ".log":
            yield from self._candump_parts()
            return
        if self.suffix == ".blf":
            yield from self._blf_parts()
            return
        if self.suffix == ".asc":
            yield from self._asc_parts()
            return
        if self.suffix == ".mf4":
            found = None
            with self._failures():
                found = mdf_records(Path(self.source))  # a cut log: its repaired copy
                for records in found or ():
                    self.count += records.records
                    yield FrameBlock(records.t, records.ids, records.extended, records.data)
            if found is not None:
                return
        rows: list[tuple[float, int, bool, bytes]] = []
        for record in self.records():
            rows.append(record)
            if len(rows) == _PART:
                yield FrameBlock.of(rows)
                rows = []
        yield FrameBlock.of(rows)

    def _candump_parts(self) -> Iterator[FrameBlock]:
        """A candump log a block of lines at a time (:func:`pyrhonn.candump.parse_block`); a block it does not
        parse is read by python-can's reader, as every line was before."""
        assert isinstance(self.source, _WholeLines)
        with self._failures():
            for lines in self.source.blocks():
                block = parse_block(lines)
                if block is None:
                    rows = list(self._read(_Lines(lines)))
                    yield FrameBlock.of(rows)
                    continue
                self.count += block.records
                self.skipped += block.errors
                yield FrameBlock(block.t, block.ids, block.extended, block.data)

    def _asc_parts(self) -> Iterator[FrameBlock]:
        """An ASC log a block of lines at a time (:class:`pyrhonn.asc.AscBlocks`); a block it does not parse is
        read by python-can's reader (with the header's base), as every line was before."""
        assert isinstance(self.source, _WholeLines)
        blocks = AscBlocks()
        with self._failures():
            for lines in self.source.blocks():
                body, block = blocks.parse(lines)
                if block is None:
                    yield FrameBlock.of(list(self._read(_Lines(blocks.fallback_text(body)), base=blocks.base)))
                    continue
                self.count += block.records
                self.skipped += block.errors
                yield FrameBlock(block.t, block.ids, block.extended, block.data)

    def _blf_parts(self) -> Iterator[FrameBlock]:
        """A BLF log a container at a time (:func:`pyrhonn.blf.blf_records`)."""
        import can

        with self._failures():
            with can.BLFReader(self.source) as reader:
                self._blf_checked(reader)
                for records in blf_records(reader):
                    self.count += records.records
                    self.skipped += records.errors
                    yield FrameBlock(records.t, records.ids, records.extended, records.data)

    def _blf_checked(self, reader: Any) -> None:
        """What a BLF log misses, from its header (read by ``reader``) and its objects' sizes."""
        self.incomplete = _blf_completeness(self.p, int(getattr(reader, "file_size", 0) or 0),
                                            int(getattr(reader, "object_count", 0) or 0),
                                            f"{self.option} {self.path}")

    def blocks(self, size: int) -> Iterator[FrameBlock]:
        """The data frames in file order, ``size`` at a time (the last block fewer; none for a log without
        frames), with :meth:`records`' refusals."""
        held: list[FrameBlock] = []
        count = 0
        for part in self._parts():
            held.append(part)
            count += len(part)
            while count >= size:
                joined = FrameBlock.join(held)
                yield joined.take(np.arange(size))
                rest = joined.take(np.arange(size, count))
                held, count = [rest], len(rest)
        if count:
            yield FrameBlock.join(held)

    def check_read(self, frames: int, latest: float) -> None:
        """After every record was read (``frames`` data frames, the latest at log time ``latest``): a truncated
        log refused unless ``partial``, a log without data frames refused."""
        if self.incomplete and not self.partial:
            upto = f", up to log time {latest:.6f}" if frames else ""
            raise ValueError(f"{self.option} {self.path}: truncated: {self.incomplete}; {self.count:,} frames are "
                             f"complete{upto}{_PARTIAL_HINT}")
        if not frames:
            raise ValueError(f"{self.option} {self.path}: no data frames in it ({self.count} records read, "
                             f"{self.skipped} error or remote frames); is it {self.kind} log?"
                             + (" (an MDF4 of named signal channels is not a bus log)" if self.suffix == ".mf4"
                                else ""))

    def missing(self, latest: float) -> str | None:
        """What a log read ``partial`` misses, with how much was read (None: complete)."""
        return None if not self.incomplete else (f"{self.incomplete}; {self.count:,} frames read, up to log time "
                                                 f"{latest:.6f}")


def read_frames(path: str | Path, option: str = "--can-log", partial: bool = False) -> Frames:
    """Every data frame of a ``.blf``, ``.asc`` or candump ``.log`` file;
    a ValueError naming ``option``, the file and the frame (or candump line)
    for a log that cannot be read. A log that is not complete (an ASC without
    its ``End TriggerBlock``, a BLF shorter than its header records or cut
    inside an object, a text log whose last line is cut) is refused, naming
    what is missing, unless ``partial``: then its complete frames are read and
    ``Frames.incomplete`` says what is missing."""
    log = _Log(path, option, partial)
    parts = list(log.blocks(_PART))
    block = FrameBlock.join(parts) if parts else FrameBlock.of([])
    ts = block.t
    log.check_read(ts.size, latest(ts) if ts.size else 0.0)
    if not np.isfinite(ts).all():
        k = int(np.argwhere(~np.isfinite(ts))[0, 0])
        raise ValueError(f"{option} {path}: frame {k + 1}: timestamp {ts[k]!r} is not finite")
    order = np.argsort(ts, kind="stable")  # logs of several channels may interleave slightly out of order
    return Frames(t=ts[order], ids=block.ids[order], extended=block.extended[order], data=block.data.take(order),
                  skipped=log.skipped, incomplete=log.missing(float(ts.max())))


# -- alignment ----------------------------------------------------------------------------------------


@dataclass(frozen=True)
class SignalStats:
    """Per state or input: ``frames`` of its message in the run's windows
    that carry it, ``used`` samples it gave a value to, ``missing`` samples
    without one (no frame in the window), ``superseded`` frames replaced by
    a later one in the same window, ``undecodable`` frames of its message
    that did not decode, ``flagged`` samples whose validity flag was 0,
    ``nonfinite`` decoded values that are NaN or infinite."""

    signal: str
    frames: int
    used: int
    missing: int
    superseded: int
    undecodable: int
    flagged: int
    nonfinite: int

    def as_dict(self) -> dict[str, Any]:
        return {"signal": self.signal, "frames": self.frames, "used": self.used, "missing": self.missing,
                "superseded": self.superseded, "undecodable": self.undecodable, "flagged_invalid": self.flagged,
                "nonfinite": self.nonfinite}


@dataclass(frozen=True)
class AlignedSummary:
    """How a bus log's ``n_samples`` samples were made (see :class:`Aligned`, which adds the samples):
    what a streamed read (:mod:`pyrhonn.buslogstream`) knows once the log is read to its end."""

    start: float
    clock: str
    sample_period: float
    period_source: str
    window_start: float
    clock_frames: int
    clock_missing: int
    cut_start: int
    cut_end: int
    stats: Mapping[str, SignalStats]
    n_samples: int
    incomplete: str | None


@dataclass(frozen=True)
class Aligned(AlignedSummary):
    """A bus log on the sample clock: K samples.

    ``t`` (K,) s since the log's first clock frame, ``start`` the log
    timestamp of that frame, ``X`` (K, n) with NaN where not valid,
    ``valid`` (K, n), ``U`` (K, m); ``clock`` the clock message,
    ``sample_period`` (s) and where it came from (``period_source``),
    ``clock_frames`` in the log, ``clock_missing`` samples inserted for lost
    clock frames, ``cut_start``/``cut_end`` samples cut off before and after
    the run (``--start``/``--stop``, or no value for an input), ``stats`` per
    state and input name, over the samples kept; ``lost`` (K,) bool the
    samples inside the run without every input (NaN in ``U``);
    ``incomplete`` what a log read partially misses (None: complete).
    """

    t: np.ndarray
    X: np.ndarray
    valid: np.ndarray
    U: np.ndarray
    lost: np.ndarray


def _tick_on(tc: np.ndarray, T: float, last: float) -> tuple[list[float], np.ndarray, int]:
    """Samples from clock frames at times ``tc`` after a sample at ``last``: (the new samples' instants, the
    sample of each frame counted from ``last``'s, samples inserted). A frame round(D / T) = n > 1 periods
    after the latest sample means n - 1 lost frames, evenly spaced; n = 0 is a repeat of the same sample.
    Computed a stretch of frames at a time up to the next repeat (the latest sample is then not the frame
    before), with the arithmetic of ``base + j * gap / n`` per inserted instant."""
    parts: list[np.ndarray] = []
    sample = np.zeros(tc.size, dtype=np.int64)
    inserted = 0
    count = 0  # samples so far
    base = last
    i = 0
    while i < tc.size:
        seg = tc[i:i + _TICK_STRETCH]
        gap = seg - np.r_[base, seg[:-1]]  # from the frame before: the latest sample while none repeats
        n = np.rint(gap / T)
        repeat = np.flatnonzero(n <= 0)
        stop = int(repeat[0]) if repeat.size else seg.size
        if stop:
            steps = n[:stop].astype(np.int64)
            ends = np.cumsum(steps)
            owner = np.repeat(np.arange(stop), steps)
            j = np.arange(int(ends[-1])) - np.repeat(ends - steps, steps) + 1  # 1..n within each frame's
            g, k = gap[:stop][owner], steps[owner]
            starts = np.r_[base, seg[:stop - 1]][owner]
            parts.append(np.where(j == k, seg[:stop][owner], starts + j * g / k))
            sample[i:i + stop] = count + ends
            count += int(ends[-1])
            inserted += int(ends[-1]) - stop
            base = float(seg[stop - 1])
        if stop < seg.size:  # a repeat of the latest sample
            sample[i + stop] = count
            stop += 1
        i += stop
    return (np.concatenate(parts).tolist() if parts else []), sample, inserted


def _ticks(tc: np.ndarray, T: float) -> tuple[np.ndarray, np.ndarray, int]:
    """Samples from the clock frames' times ``tc``: (tau, the sample of each frame, samples inserted)."""
    tau, sample, inserted = _tick_on(tc[1:], T, float(tc[0]))
    return np.asarray([float(tc[0]), *tau]), np.r_[np.int64(0), sample], inserted


def _count_on(tc: np.ndarray, counts: np.ndarray, modulus: int, last: tuple[int, int, float]
              ) -> tuple[np.ndarray, np.ndarray, int, tuple[int, int, float]]:
    """Samples from clock frames' counter values after ``last`` = (the latest frame's counter, its sample, the
    instant of that sample's first frame): (the new samples' instants, the sample of each frame, samples
    inserted, the new ``last``). A repeated counter is the same sample; the instants of samples without a
    frame are interpolated between their neighbours'."""
    step = np.diff(np.r_[np.int64(last[0]), counts]) % modulus
    sample = (last[1] + np.cumsum(step)).astype(np.int64)
    first = step != 0
    top = int(sample[-1]) if sample.size else last[1]
    xs, ys = np.r_[np.int64(last[1]), sample[first]], np.r_[last[2], tc[first]]
    tau = np.interp(np.arange(last[1] + 1, top + 1), xs, ys)
    new_last = (int(counts[-1]), top, float(ys[-1])) if counts.size else last
    return tau, sample, top - last[1] - int(first.sum()), new_last


def _counted(tc: np.ndarray, counts: np.ndarray, modulus: int) -> tuple[np.ndarray, np.ndarray, int]:
    """Samples from the clock frames' counter values: (tau, the sample of each frame, samples inserted).
    A frame's sample is its counter, unwrapped, less the first's; a repeated counter is the same sample;
    the instants of samples without a frame are interpolated between their neighbours'."""
    tau, sample, inserted, _ = _count_on(tc[1:], counts[1:], modulus, (int(counts[0]), 0, float(tc[0])))
    return np.r_[float(tc[0]), tau], np.r_[np.int64(0), sample], inserted


def _given_period(clock_msg: Any, bus: BusMap, period_option: str, dbc: str) -> tuple[float, str] | None:
    """The sample period and where it was given (None: neither in ``bus`` nor as the clock's DBC cycle time)."""
    if bus.sample_period is not None:
        return float(bus.sample_period), period_option
    if getattr(clock_msg, "cycle_time", None):
        return float(clock_msg.cycle_time) / 1e3, f"the cycle time of {clock_msg.name} in {dbc}"
    return None


def _period(db: Any, clock_msg: Any, bus: BusMap, tc: np.ndarray, period_option: str,
            dbc: str) -> tuple[float, str]:
    """The sample period and where it was given; ValueError if the clock frames disagree with it."""
    given = _given_period(clock_msg, bus, period_option, dbc)
    if given is None:
        hint = f"; its frames come every {float(np.median(np.diff(tc))):.6g} s (median)" if tc.size > 1 else ""
        raise ValueError(f"{period_option}: not given, and the clock message {clock_msg.name} has no cycle time "
                         f"(GenMsgCycleTime) in {dbc}{hint}: give the sample period in seconds")
    T, where = given
    if tc.size > 1:
        med = float(np.median(np.diff(tc)))
        if abs(med - T) > PERIOD_TOLERANCE * T:
            raise ValueError(f"{where}: sample period {T:.6g} s, but the clock message {clock_msg.name}'s frames come "
                             f"every {med:.6g} s (median of {tc.size - 1} intervals); give the period its frames "
                             "are sent at, or choose another clock message")
    return T, where


def _counter_signal(db: Any, ref: SignalRef, clock_msg: Any, dbc: str) -> tuple[Any, Any]:
    """The clock message's counter signal ``ref`` (message, signal); ValueError if it is not one."""
    msg, sig = _signal(db, ref, dbc)
    if msg.name != clock_msg.name:
        raise ValueError(f"{ref.origin}: {str(ref)!r} is in message {msg.name}, not in the clock message "
                         f"{clock_msg.name}: the counter numbers the clock's frames")
    if sig.is_signed or sig.is_float or sig.scale != 1 or sig.offset != 0 or _mux_values(msg, sig) is not None:
        raise ValueError(f"{ref.origin}: {str(ref)!r} is not a counter: expected an unsigned integer signal in every "
                         "frame, without scale or offset")
    return msg, sig


def _counter_values(ref: SignalRef, msg: Any, sig: Any, t: np.ndarray, data: Payloads,
                    source: str) -> np.ndarray:
    """The counter of each clock frame (times ``t``, payloads ``data``); ValueError at one that does not decode."""
    ok, raw = unsigned_raw(msg, data, sig.name)
    ok &= raw < np.uint64(1 << 63)  # a counter beyond int64 cannot be counted
    counts = raw.astype(np.int64)
    if not ok.all():
        n = int(np.argmin(ok))
        raise ValueError(f"{ref.origin}: {source}: the clock frame at log time {t[n]:.6f} does not decode, "
                         "so its counter is unknown")
    return counts


def _counter_samples(db: Any, ref: SignalRef, clock_msg: Any, frames: Frames, idx: np.ndarray, dbc: str,
                     source: str) -> tuple[np.ndarray, np.ndarray, int]:
    """:func:`_counted` on the clock frames' counter signal ``ref``."""
    msg, sig = _counter_signal(db, ref, clock_msg, dbc)
    counts = _counter_values(ref, msg, sig, frames.t[idx], frames.data.take(idx), source)
    return _counted(frames.t[idx], counts, 1 << int(sig.length))


@dataclass(frozen=True)
class _Plan:
    """What :func:`align` decodes: the state and input ``names`` (states first), each one's (message,
    signal) ``resolved``, the validity ``flags`` (signals), the clock message, the messages read
    (``used_msgs``, by name) and the signals decoded from each (``used_sigs``)."""

    names: list[str]
    n: int
    resolved: dict[str, tuple[Any, Any]]
    flags: dict[str, Any]
    clock_msg: Any
    used_msgs: dict[str, Any]
    used_sigs: dict[str, list[str]]

    def key(self, msg: Any) -> int:
        """A message's frame key: id * 2 + extended, as :func:`frame_keys` gives the frames'."""
        return int(msg.frame_id) * 2 + int(bool(msg.is_extended_frame))

    def value_msgs(self) -> dict[str, Any]:
        """The messages whose signals are decoded, by name."""
        return {msg.name: msg for msg, _ in self.resolved.values()}


def frame_keys(ids: np.ndarray, extended: np.ndarray) -> np.ndarray:
    """Each frame's message key: arbitration id * 2 + extended."""
    return ids * 2 + extended.astype(np.int64)


def _plan(db: Any, bus: BusMap, state_names: Sequence[str], input_names: Sequence[str], dbc: str,
          clock_option: str) -> _Plan:
    """The signals and messages ``bus`` maps, checked against the DBC ``db`` (ValueError naming the key)."""
    names = list(state_names) + list(input_names)
    unmapped = [name for name in names if name not in bus.signals]
    if unmapped:
        raise ValueError(f"bus.signals: no signal for {', '.join(unmapped)}; map every state and input to "
                         "\"Message.Signal\" (a [bus.signals] table in the config, or --signal NAME=Message.Signal)")
    extra = [name for name in bus.signals if name not in names]
    if extra:
        raise ValueError(f"{bus.signals[extra[0]].origin}: {extra[0]!r} is not one of the config's states and "
                         f"inputs ({', '.join(names)})")
    seen: dict[str, str] = {}
    resolved: dict[str, tuple[Any, Any]] = {}
    for name in names:
        ref = bus.signals[name]
        if str(ref) in seen:
            raise ValueError(f"{ref.origin}: {str(ref)!r} is also the signal of {seen[str(ref)]!r}; each state and "
                             "input needs its own signal")
        seen[str(ref)] = name
        resolved[name] = _signal(db, ref, dbc)
    flags: dict[str, Any] = {}
    for name, ref in bus.valid.items():
        msg, sig = resolved[name]
        fmsg, fsig = _signal(db, ref, dbc)
        if fmsg.name != msg.name:
            raise ValueError(f"{ref.origin}: {str(ref)!r} is in message {fmsg.name}, but {name}'s value "
                             f"{bus.signals[name]} is in {msg.name}: a validity flag must come in the same frame")
        vm, fm = _mux_values(msg, sig), _mux_values(fmsg, fsig)
        if fm is not None and (vm is None or not vm <= fm):
            raise ValueError(f"{ref.origin}: mixed multiplexing: {str(ref)!r} is sent only under multiplexer "
                             f"value(s) {sorted(fm)}, but {bus.signals[name]} "
                             f"{'in every frame' if vm is None else f'under {sorted(vm)}'}: the flag must be in "
                             "every frame that carries the value")
        flags[name] = fsig
    clock_name = bus.clock if bus.clock is not None else resolved[state_names[0]][0].name
    clock_msg = _message(db, clock_name, clock_option if bus.clock is not None else
                         f"{clock_option} (default: the message of {state_names[0]})", dbc)
    used_msgs = {m.name: m for m, _ in resolved.values()}
    used_msgs[clock_msg.name] = clock_msg
    used_sigs: dict[str, list[str]] = {}
    for name in names:
        msg, sig = resolved[name]
        used_sigs.setdefault(msg.name, []).append(sig.name)
        if name in flags:
            used_sigs[msg.name].append(flags[name].name)
    return _Plan(names=names, n=len(state_names), resolved=resolved, flags=flags, clock_msg=clock_msg,
                 used_msgs=used_msgs, used_sigs=used_sigs)


def _decode(msg: Any, payloads: Payloads, signals: Sequence[str]) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Frames of ``msg`` decoded into arrays of ``signals`` (NaN where a frame does not carry one, inf for a
    decoded NaN) and whether each decoded (:func:`pyrhonn.framedecode.decode_frames`: cantools' values)."""
    decoded = decode_frames(msg, payloads, signals)
    arrays = {}
    for name, values in decoded.values.items():
        carried = decoded.carried[name]
        # NaN: "not in this frame"; a NaN decoded is kept apart as inf (non-finite, counted)
        arrays[name] = np.where(carried, np.where(np.isnan(values), np.inf, values), np.nan)
    return decoded.ok, arrays


#: per sample and signal, what :func:`_gather` counts
_COUNTS = ("frames", "undecodable", "flagged", "nonfinite")


def _count_into(counts: np.ndarray, at: np.ndarray) -> None:
    """``counts[i] += 1`` for each ``i`` in ``at`` (repeats counted), as ``np.add.at`` does, by a bincount."""
    if at.size and 0 <= int(at.min()) and int(at.max()) < counts.size:
        counts += np.bincount(at, minlength=counts.size).astype(counts.dtype)
    else:
        np.add.at(counts, at, 1)


def _gather(plan: _Plan, decoded: Mapping[str, tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]], K: int
            ) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """Samples 0..K-1 from each message's decoded frames ``decoded[name] = (window, ok, arrays)`` (the
    sample each frame counts for, in time order): (value, got, counts) with the latest frame of a window
    taken (see the module docs)."""
    cols = len(plan.names)
    value = np.full((K, cols), np.nan)
    got = np.zeros((K, cols), dtype=bool)
    counts = {what: np.zeros((K, cols), dtype=np.int32) for what in _COUNTS}  # per sample window: small counts
    for col, name in enumerate(plan.names):
        msg, sig = plan.resolved[name]
        window, ok, arrays = decoded[msg.name]
        _count_into(counts["undecodable"][:, col], window[~ok])
        carries = np.flatnonzero(ok & ~np.isnan(arrays[sig.name]))
        w = window[carries]
        _count_into(counts["frames"][:, col], w)
        # frames are in time order: the latest of each window wins
        windows, from_end = np.unique(w[::-1], return_index=True)
        latest = carries[w.size - 1 - from_end]
        latest_values = arrays[sig.name][latest]
        finite = np.isfinite(latest_values)
        counts["nonfinite"][windows[~finite], col] += 1
        good = finite.copy()
        flag = plan.flags.get(name)
        if flag is not None:
            down = finite & (arrays[flag.name][latest] == 0)
            counts["flagged"][windows[down], col] += 1
            good &= ~down
        got[windows[good], col] = True
        value[windows[good], col] = latest_values[good]
    return value, got, counts


def _stat_sums(counts: Mapping[str, np.ndarray], got: np.ndarray) -> np.ndarray:
    """(7, columns) int64: per signal over these samples, the sums :class:`SignalStats` gives (frames, used,
    missing, superseded, undecodable, flagged, nonfinite)."""
    frames = counts["frames"]
    return np.stack([frames.sum(axis=0), got.sum(axis=0), (frames == 0).sum(axis=0),
                     np.maximum(frames - 1, 0).sum(axis=0), counts["undecodable"].sum(axis=0),
                     counts["flagged"].sum(axis=0), counts["nonfinite"].sum(axis=0)]).astype(np.int64)


def _stats(plan: _Plan, bus: BusMap, sums: np.ndarray) -> dict[str, SignalStats]:
    """:class:`SignalStats` per name from :func:`_stat_sums`."""
    return {name: SignalStats(str(bus.signals[name]), *(int(v) for v in sums[:, col]))
            for col, name in enumerate(plan.names)}


def _stretch_error(start: float | None, stop: float | None, last: float) -> ValueError:
    return ValueError(f"--start/--stop: no sample between {start} and {stop} s (the clock's samples run from 0 to "
                      f"{last:.6g} s)")


def _kept(t_all: np.ndarray, start: float | None, stop: float | None) -> np.ndarray:
    """The samples inside --start/--stop (``t_all`` s since the first clock frame)."""
    keep = np.ones(t_all.size, dtype=bool)
    if start is not None:
        keep &= t_all >= start
    if stop is not None:
        keep &= t_all <= stop
    return keep


def _one_sample_error(source: str) -> ValueError:
    return ValueError(f"{source}: only one sample with every input; one-step-ahead identification needs at least "
                      "two")


def align(frames: Frames, db: Any, bus: BusMap, state_names: Sequence[str], input_names: Sequence[str], *,
          source: str = "the log", dbc: str = "the DBC", period_option: str = "bus.sample_period",
          clock_option: str = "bus.clock", start: float | None = None, stop: float | None = None) -> Aligned:
    """Decode ``frames`` with ``db`` and align the signals ``bus`` maps on its
    sample clock (see the module docs). Every state and input must be mapped."""
    plan = _plan(db, bus, state_names, input_names, dbc, clock_option)
    names, resolved, clock_msg, used_msgs = plan.names, plan.resolved, plan.clock_msg, plan.used_msgs

    # which frames are which message
    key = frame_keys(frames.ids, frames.extended)
    where_msg = {m.name: np.flatnonzero(key == plan.key(m)) for m in used_msgs.values()}
    if not any(idx.size for idx in where_msg.values()):
        present = sorted(set(int(i) for i in frames.ids))
        listing = ", ".join(f"0x{i:X}" for i in present[:12]) + (" ..." if len(present) > 12 else "")
        raise ValueError(f"{source}: none of its {frames.t.size} frames is one of the messages the signals come from "
                         f"({', '.join(f'{m.name} 0x{m.frame_id:X}' for m in used_msgs.values())}); the log's "
                         f"frame ids: {listing}. Is it the DBC of this bus?")
    for name in names:
        msg = resolved[name][0]
        if not where_msg[msg.name].size:
            raise ValueError(f"{bus.signals[name].origin}: {bus.signals[name]}: {source} has no frame of message "
                             f"{msg.name} (id 0x{msg.frame_id:X})")
    tc = frames.t[where_msg[clock_msg.name]]
    if not tc.size:
        raise ValueError(f"{clock_option}: {source} has no frame of the clock message {clock_msg.name} "
                         f"(id 0x{clock_msg.frame_id:X})")
    T, period_source = _period(db, clock_msg, bus, tc, period_option, dbc)
    if bus.counter is None:
        tau, clock_sample, inserted = _ticks(tc, T)
    else:
        tau, clock_sample, inserted = _counter_samples(db, bus.counter, clock_msg, frames, where_msg[clock_msg.name],
                                                       dbc, source)
    K = tau.size
    starts = tau + bus.window_start * T
    end = starts[-1] + T

    # each message's frames decoded once into arrays of the signals used (NaN where a frame does not carry one)
    decoded: dict[str, tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]] = {}
    for m in plan.value_msgs().values():
        idx = where_msg[m.name]
        if m.name == clock_msg.name:  # the clock message's own signals: from the sample's own frame
            window = clock_sample
        else:
            inside = (frames.t[idx] >= starts[0]) & (frames.t[idx] < end)
            idx = idx[inside]
            window = np.searchsorted(starts, frames.t[idx], side="right") - 1
        ok, arrays = _decode(m, frames.data.take(idx), plan.used_sigs[m.name])
        decoded[m.name] = (window, ok, arrays)
    n = plan.n
    value, got, counts = _gather(plan, decoded, K)

    # the stretch: --start/--stop, then the ends without every input cut off; a gap inside is a lost sample
    t_all = tau - tau[0]
    keep = _kept(t_all, start, stop)
    if not keep.any():
        raise _stretch_error(start, stop, float(t_all[-1]))
    have = keep & got[:, n:].all(axis=1)
    if not have.any():
        raise _no_inputs_error(bus, input_names, got[keep][:, n:], source)
    lo = int(np.argmax(have))
    hi = K - int(np.argmax(have[::-1]))
    if hi - lo < 2:
        raise _one_sample_error(source)
    sl = slice(lo, hi)
    lost = ~have[sl]
    value[sl][lost] = np.nan
    got[sl][lost] = False
    stats = _stats(plan, bus, _stat_sums({k: v[sl] for k, v in counts.items()}, got[sl]))
    return Aligned(t=t_all[sl].copy(), start=float(tau[0]), X=value[sl, :n].copy(), valid=got[sl, :n].copy(),
                   U=value[sl, n:].copy(), clock=clock_msg.name, sample_period=T, period_source=period_source,
                   window_start=bus.window_start, clock_frames=int(tc.size), clock_missing=inserted,
                   cut_start=lo, cut_end=K - hi, stats=stats, lost=lost.copy(),
                   incomplete=frames.incomplete, n_samples=hi - lo)


def _no_inputs_error(bus: BusMap, input_names: Sequence[str], got_inputs: np.ndarray, source: str) -> ValueError:
    """No kept sample has every input (``got_inputs`` (kept samples, m))."""
    j = int(np.argmin(got_inputs.sum(axis=0)))
    ref = bus.signals[input_names[j]]
    return ValueError(f"{ref.origin}: {ref}: no sample of {source} has every input (input {input_names[j]!r} "
                      f"has a value at {int(got_inputs[:, j].sum())} of {got_inputs.shape[0]} samples)")


def read_bus_log(log: str | Path, dbc: str | Path, bus: BusMap, state_names: Sequence[str],
                 input_names: Sequence[str], *, start: float | None = None, stop: float | None = None,
                 partial: bool = False, **options: str) -> Aligned:
    """:func:`read_frames` of ``log`` (``partial``: a truncated log's complete part), decoded with the DBC
    file ``dbc`` and :func:`align`-ed."""
    db = load_dbc(dbc, options.get("dbc_option", "--dbc"))
    frames = read_frames(log, options.get("log_option", "--can-log"), partial=partial)
    return align(frames, db, bus, state_names, input_names, source=str(log), dbc=str(dbc),
                 period_option=options.get("period_option", "bus.sample_period"),
                 clock_option=options.get("clock_option", "bus.clock"), start=start, stop=stop)
