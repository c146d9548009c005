"""The firmware application of ``firmware_sim/``, driven from Python frame by frame.

``pyrhonn._fwapp`` is compiled from the very C sources the firmware builds
from (``firmware_sim/app``, the cantools-generated pack/unpack of
``firmware_sim/rhonn_id.dbc``, the float32 core), so :class:`FirmwareApp`
runs the exact firmware logic - validation, sequence counter, one
``rhonn_step`` per accepted measurement, estimate scaling, control commands,
weight transfer, diagnostics - on any python-can bus, for instance when
SocketCAN is absent::

    import can
    from pyrhonn.firmware import FirmwareApp

    bus = can.Bus(interface="virtual", channel="rig")
    app = FirmwareApp(bus, config)       # a float32 IdentifierConfig with 6 states, 2 inputs
    app.serve(n_frames=10_000)           # or until=time.monotonic() + 5.0, or until=callable
    replies = app.handle(msg)            # one frame in, the frames the firmware sends out

The rig's side of the protocol (encode a measurement, decode an estimate,
control and weight-transfer frames, the Diagnostics and per-neuron Health
frames) is here too, on cantools and the DBC embedded in the extension at
build time: :func:`database`, :func:`measurement_message`,
:func:`decode_estimate`, :func:`control_message`,
:func:`weight_load_messages`, :func:`decode_diagnostics`,
:func:`decode_health`. Bit-rate figures of
the design come from :func:`fd_frame_bits` and :func:`cycle_bus_time`.

**Another identifier.** The module-level functions speak the LIM's protocol
(``firmware_sim/rhonn_id.dbc``). A :class:`Protocol` is the same protocol
for any identifier whose DBC ``pyrhonn export --dbc`` wrote (its states are
the Measurement signals with a ``Valid<state>`` flag, its inputs the other
value signals, its estimates ``<state>Hat``), read from the DBC with
cantools; with ``library``, the firmware application compiled for that DBC
(firmware_sim/tools/build_twin.py), :class:`FirmwareApp` runs it::

    proto = Protocol.from_dbc("id.dbc", library=twin)  # twin: the compiled module
    app = FirmwareApp(bus, config, protocol=proto)
    bus.send(proto.measurement_message(0, x, u))

Control and WeightLoad frames are authenticated as AUTOSAR SecOC does
(docs/firmware-protocol.md, Authentication): a :class:`SecOCSender` holds the
key and the rig's freshness counter and is the one place that secures them::

    sender = SecOCSender(TEST_KEY)           # the public test key of the simulations
    bus.send(control_message("Reset", token=1, sender=sender))
"""
from __future__ import annotations

import functools
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import can
import numpy as np

from . import _fwapp
from .config import IdentifierConfig
from .identifier import Identifier, _check_capacity

__all__ = [
    "COMMANDS",
    "ESTIMATE_SIGNALS",
    "Estimate",
    "FirmwareApp",
    "FirmwareError",
    "Health",
    "INPUT_SIGNALS",
    "Protocol",
    "SECOC_ENABLED",
    "STATE_SIGNALS",
    "SecOCSender",
    "TEST_KEY",
    "VALID_SIGNALS",
    "WEIGHTS_PER_FRAME",
    "control_message",
    "cycle_bus_time",
    "database",
    "decode_diagnostics",
    "decode_estimate",
    "decode_health",
    "fd_frame_bits",
    "lim_protocol",
    "measurement_message",
    "protocol_layout",
    "status_name",
    "weight_load_messages",
]

_ffi, _lib = _fwapp.ffi, _fwapp.lib

#: Measurement/Estimate signals in the identifier's state and input order
#: (pyrhonn.plants.lim.STATE_NAMES, INPUT_NAMES).
STATE_SIGNALS = ("Qm", "V", "LambdaA", "LambdaB", "Ia", "Ib")
VALID_SIGNALS = tuple(f"Valid{s}" for s in STATE_SIGNALS)
INPUT_SIGNALS = ("Ua", "Ub")
ESTIMATE_SIGNALS = tuple(f"{s}Hat" for s in STATE_SIGNALS)
#: Control.Command values (the DBC's value table).
COMMANDS = {"Reset": 1, "LearningOff": 2, "LearningOn": 3, "WeightsBegin": 4, "WeightsCommit": 5,
            "WeightsAbort": 6, "DiagRequest": 7}
WEIGHTS_PER_FRAME = int(_lib.FW_WEIGHTS_PER_FRAME)

_COUNTERS = ("frames_in", "frames_out", "rejected", "rejected_unknown_id", "rejected_length", "rejected_range",
             "rejected_seq_repeat", "rejected_seq_jump", "rejected_state", "rejected_weights", "measurements",
             "step_errors", "commands", "weight_chunks", "hal_errors", "overruns", "cycle_time_ns", "step_time_ns",
             "step_time_max_ns", "step_time_worst_ns", "last_reject", "last_step_status", "rejected_auth",
             "rejected_freshness", "lost_frames", "seq_gaps", "restarts", "rx_drops")


class FirmwareError(ValueError):
    """A call into the firmware application failed (``status`` is the fw_status name)."""

    def __init__(self, status: str, message: str) -> None:
        super().__init__(message)
        self.status = status


def status_name(status: int) -> str:
    """The fw_status name of a status code."""
    return _ffi.string(_lib.fw_status_name(status)).decode()


@functools.cache
def database():
    """The cantools database of the DBC the extension was built from."""
    import cantools

    text = _ffi.new("const unsigned char **")
    n = _lib.fwpy_dbc(text)
    return cantools.database.load_string(bytes(_ffi.buffer(text[0], n)).decode("utf-8"), database_format="dbc")


def _test_key() -> bytes | None:
    key = _ffi.new("const unsigned char **")
    n = _lib.fwpy_secoc_key(key)
    return bytes(_ffi.buffer(key[0], n)) if n else None


#: The key compiled into pyrhonn._fwapp (firmware_sim/config/fw_secoc_key.h):
#: the PUBLIC test key "pyrhonn-TEST-key" of the simulations, not a secret.
#: None when the twin was built with a provisioned key, which it never hands out.
TEST_KEY: bytes | None = _test_key()
#: Whether the twin's firmware checks the command authentication (FW_SECOC).
SECOC_ENABLED = bool(_lib.FW_SECOC)


class SecOCSender:
    """The rig's side of the command authentication: the AES-128 key and the
    64-bit freshness counter shared by Control and WeightLoad.

    :meth:`protect` adds one to the counter and writes the secured trailer
    (the low 32 bits of the freshness value and the 8-byte truncated
    AES-CMAC over DataId | authentic bytes | full freshness value) with the
    firmware's own C code (``fw_secoc_protect``), which the tests check
    against RFC 4493 and the ``cryptography`` package. One sender per
    firmware: the firmware refuses a freshness value it has already seen.
    """

    def __init__(self, key: bytes, freshness: int = 0) -> None:
        if not isinstance(key, (bytes, bytearray)) or len(key) != int(_lib.FW_AES128_KEY):
            raise ValueError(f"key: expected {int(_lib.FW_AES128_KEY)} bytes (AES-128), got "
                             f"{len(key) if isinstance(key, (bytes, bytearray)) else type(key).__name__}")
        if isinstance(freshness, bool) or not isinstance(freshness, (int, np.integer)) \
                or not 0 <= freshness < 2 ** 64 - 1:
            raise ValueError(f"freshness: expected an integer in 0..2**64-2, got {freshness!r}")
        self._key = _ffi.new("fw_cmac_key *")
        _lib.fw_cmac_init(self._key, bytes(key))
        self._freshness = int(freshness)

    @property
    def freshness(self) -> int:
        """The freshness value of the last frame secured (0: none yet)."""
        return self._freshness

    def protect(self, frame_id: int, payload: bytes) -> bytes:
        """``payload`` (a whole frame, trailer bytes included and
        overwritten) secured with the next freshness value."""
        n = len(payload)
        if isinstance(frame_id, bool) or not isinstance(frame_id, (int, np.integer)) or not 0 <= frame_id <= 0x7FF:
            raise ValueError(f"frame_id: expected an 11-bit CAN identifier (the DataId), got {frame_id!r}")
        if not int(_lib.FW_SECOC_TRAILER_BYTES) <= n <= int(_lib.FW_MAX_FRAME_LEN):
            raise ValueError(f"payload: {n} bytes cannot carry the {int(_lib.FW_SECOC_TRAILER_BYTES)}-byte "
                             "SecOC trailer")
        if self._freshness >= 2 ** 64 - 1:
            raise ValueError("freshness: the 64-bit counter is spent; provision a new key")
        buf = _ffi.new("uint8_t[]", bytes(payload))
        status = _lib.fw_secoc_protect(self._key, int(frame_id), buf, n, self._freshness + 1)
        if status != _lib.FW_OK:
            raise FirmwareError(status_name(status), f"protect: {status_name(status)}")
        self._freshness += 1
        return bytes(_ffi.buffer(buf, n))


# -- the rig's side of the protocol -------------------------------------------------


def _message(name: str, data: bytes) -> can.Message:
    msg = database().get_message_by_name(name)
    return can.Message(arbitration_id=msg.frame_id, is_extended_id=msg.is_extended_frame, data=data,
                       is_fd=msg.is_fd, bitrate_switch=msg.is_fd)


@dataclass(frozen=True)
class Estimate:
    """A decoded Estimate frame: x̂(k+1) in physical units (float64) or raw."""

    seq: int
    step_status: int
    learning: bool
    saturated: bool
    resync: bool
    xhat: np.ndarray


def protocol_layout(db: Any) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """(states, inputs) of a protocol database: the states are the Measurement signals with a
    ``Valid<state>`` flag, in the flags' order, the inputs its other value signals (in the frame's
    order: by start bit), and each state has its ``<state>Hat`` in the Estimate. ValueError naming
    what does not fit that shape."""
    try:
        meas, est = db.get_message_by_name("Measurement"), db.get_message_by_name("Estimate")
    except KeyError as exc:
        raise ValueError(f"the DBC has no {exc.args[0]} message (the protocol needs Measurement and "
                         "Estimate)") from None
    names = [sig.name for sig in sorted(meas.signals, key=lambda sig: sig.start)]   # in the frame's order
    if not names or names[0] != "Seq":
        raise ValueError("Measurement: its first signal must be Seq")
    states = tuple(n[len("Valid"):] for n in names if n.startswith("Valid") and n[len("Valid"):] in names)
    if not states:
        raise ValueError("Measurement: no Valid<state> flag for any of its signals (no state)")
    flags = {f"Valid{x}" for x in states}
    inputs = tuple(n for n in names[1:] if n not in flags and n not in states)
    want = ["Seq", "StepStatus", "Learning", "Saturated", "Resync", *(f"{x}Hat" for x in states)]
    got = [sig.name for sig in sorted(est.signals, key=lambda sig: sig.start)]
    if got != want:
        raise ValueError(f"Estimate: expected the signals {want}, got {got}")
    return states, inputs


class Protocol:
    """The frames of one identifier's protocol (see the module docstring): the LIM's
    (:func:`lim_protocol`) or another identifier's DBC (:meth:`from_dbc`).

    ``states``, ``inputs``: the signal names in the identifier's order; ``library``: the firmware
    application compiled for this DBC (a cffi module as ``pyrhonn._fwapp``), or None (the rig's side
    only)."""

    def __init__(self, db: Any, *, library: Any = None, source: str = "") -> None:
        self.database = db
        self.source = source
        self.states, self.inputs = protocol_layout(db)
        self.valid_signals = tuple(f"Valid{x}" for x in self.states)
        self.estimate_signals = tuple(f"{x}Hat" for x in self.states)
        self.library = library
        if library is not None:
            n, m = int(library.lib.FW_N_STATES), int(library.lib.FW_N_INPUTS)
            if (n, m) != (len(self.states), len(self.inputs)):
                raise ValueError(f"library: compiled for {n} states and {m} inputs, the DBC carries "
                                 f"{len(self.states)} and {len(self.inputs)}")
        self._meas = db.get_message_by_name("Measurement")
        self._est = db.get_message_by_name("Estimate")

    @classmethod
    def from_dbc(cls, path: str | Path, *, library: Any = None) -> Protocol:
        """The protocol of a DBC file (``pyrhonn export --dbc``); ValueError naming the file."""
        import cantools

        source = str(path)
        try:
            db = cantools.database.load_file(source, database_format="dbc")
        except OSError as exc:
            raise ValueError(f"{source}: cannot read it: {exc.strerror or exc}") from None
        except Exception as exc:  # cantools' parse errors have no common base class
            raise ValueError(f"{source}: not a DBC cantools reads: {exc}") from None
        try:
            return cls(db, library=library, source=source)
        except ValueError as exc:
            raise ValueError(f"{source}: {exc}") from None

    @property
    def version(self) -> str:
        return str(self.database.version)

    @property
    def measurement_length(self) -> int:
        return int(self._meas.length)

    def signal_range(self, name: str) -> tuple[float, float]:
        """The accepted [min, max] of a Measurement signal."""
        sig = self._meas.get_signal_by_name(name)
        return float(sig.minimum), float(sig.maximum)

    def measurement_message(self, seq: int, x: Sequence[float], u: Sequence[float],
                            valid: Sequence[bool] | None = None, *, scaling: bool = True) -> can.Message:
        """A Measurement frame. ``x`` and ``u`` are physical values in the identifier's order
        (rounded to the signals' resolution by cantools, which refuses values outside the DBC
        ranges), or raw integers with ``scaling=False``."""
        n, m = len(self.states), len(self.inputs)
        if len(x) != n or len(u) != m:
            raise ValueError(f"x, u: expected {n} states and {m} inputs, got {len(x)} and {len(u)}")
        flags = [True] * n if valid is None else list(valid)
        if len(flags) != n:
            raise ValueError(f"valid: expected {n} flags, got {len(flags)}")
        values: dict[str, Any] = {"Seq": int(seq) & 0xFFFF}
        for name, flag, value, ok in zip(self.states, self.valid_signals, x, flags):
            values[flag] = int(bool(ok))
            values[name] = float(value) if scaling else int(value)
        for name, value in zip(self.inputs, u):
            values[name] = float(value) if scaling else int(value)
        data = self._meas.encode(values, scaling=scaling)
        return can.Message(arbitration_id=self._meas.frame_id, is_extended_id=self._meas.is_extended_frame,
                           data=data, is_fd=self._meas.is_fd, bitrate_switch=self._meas.is_fd)

    def decode_estimate(self, msg: can.Message, *, scaling: bool = True) -> Estimate:
        """Decode an Estimate frame (ValueError for any other frame)."""
        if msg.arbitration_id != self._est.frame_id or msg.is_extended_id:
            raise ValueError(f"msg: not an Estimate frame (id 0x{msg.arbitration_id:x})")
        d = self._est.decode(bytes(msg.data), scaling=scaling, decode_choices=False)
        return Estimate(seq=int(d["Seq"]), step_status=int(d["StepStatus"]), learning=bool(d["Learning"]),
                        saturated=bool(d["Saturated"]), resync=bool(d["Resync"]),
                        xhat=np.array([d[x] for x in self.estimate_signals],
                                      dtype=np.float64 if scaling else np.int64))

    def decode_measurement(self, data: bytes) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(x, u, valid) of a Measurement frame's payload, physical, in the identifier's order."""
        d = self._meas.decode(bytes(data), decode_choices=False)
        return (np.array([d[x] for x in self.states], dtype=np.float64),
                np.array([d[x] for x in self.inputs], dtype=np.float64),
                np.array([bool(d[x]) for x in self.valid_signals], dtype=bool))


@functools.cache
def lim_protocol() -> Protocol:
    """The LIM's protocol, that of the DBC the extension was built from, with its firmware."""
    return Protocol(database(), library=_fwapp, source="firmware_sim/rhonn_id.dbc")


def measurement_message(seq: int, x: Sequence[float], u: Sequence[float], valid: Sequence[bool] | None = None,
                        *, scaling: bool = True) -> can.Message:
    """A Measurement frame of the LIM's protocol. ``x`` (6,) and ``u`` (2,) are physical values
    (rounded to the signals' resolution by cantools, which refuses values outside the DBC ranges),
    or raw integers with ``scaling=False``."""
    return lim_protocol().measurement_message(seq, x, u, valid, scaling=scaling)


def decode_estimate(msg: can.Message, *, scaling: bool = True) -> Estimate:
    """Decode an Estimate frame of the LIM's protocol (ValueError for any other frame)."""
    return lim_protocol().decode_estimate(msg, scaling=scaling)


def decode_diagnostics(msg: can.Message) -> dict[str, int | float]:
    """Decode a Diagnostics frame into its signals (times in us, the rest
    as integers; ValueError for any other frame)."""
    m = database().get_message_by_name("Diagnostics")
    if msg.arbitration_id != m.frame_id or msg.is_extended_id:
        raise ValueError(f"msg: not a Diagnostics frame (id 0x{msg.arbitration_id:x})")
    d = m.decode(bytes(msg.data), decode_choices=False)
    return {k: (float(v) if k in ("CycleTime", "StepTime", "StepTimeMax") else int(v)) for k, v in d.items()}


@dataclass(frozen=True)
class Health:
    """A decoded Health frame: the filter health of one neuron, as the
    firmware's rhonn_get_health gave it. ``innovation``, ``nis`` and
    ``trace_p`` are None when the firmware flagged the value as saturated
    (it did not fit the frame's float32): a limit, not a measurement.
    ``gated``: the updates the innovation gate skipped; None in a 32-byte
    frame of rhonn_id 2.1 and before, which did not carry it."""

    neuron: int
    innovation: float | None
    nis: float | None
    trace_p: float | None
    updates: int
    rejected: int
    resets: int
    bounded: int
    fail_run: int
    gated: int | None = None


def decode_health(msg: can.Message) -> Health:
    """Decode a Health frame (ValueError for any other frame); a 32-byte one
    (rhonn_id 2.1 and before) without ``gated``."""
    m = database().get_message_by_name("Health")
    if msg.arbitration_id != m.frame_id or msg.is_extended_id:
        raise ValueError(f"msg: not a Health frame (id 0x{msg.arbitration_id:x})")
    data = bytes(msg.data)
    old = len(data) == HEALTH_LENGTH_2_1
    if len(data) not in (HEALTH_LENGTH_2_1, m.length):
        raise ValueError(f"msg: a Health frame is {m.length} bytes ({HEALTH_LENGTH_2_1} before rhonn_id 2.2), "
                         f"got {len(data)}")
    d = m.decode(data + bytes(m.length - len(data)), decode_choices=False)

    def value(name: str) -> float | None:
        return None if d[f"{name}Sat"] else float(d[name])

    return Health(neuron=int(d["Neuron"]), innovation=value("Innovation"), nis=value("Nis"),
                  trace_p=value("TraceP"), updates=int(d["Updates"]), rejected=int(d["Rejected"]),
                  resets=int(d["Resets"]), bounded=int(d["Bounded"]), fail_run=int(d["FailRun"]),
                  gated=None if old else int(d["Gated"]))


#: the Health frame's length up to rhonn_id 2.1 (then without Gated)
HEALTH_LENGTH_2_1 = 32


def _secured(name: str, values: dict[str, Any], sender: SecOCSender, *, strict: bool = True) -> can.Message:
    if not isinstance(sender, SecOCSender):
        raise ValueError(f"sender: expected a SecOCSender, got {type(sender).__name__}")
    msg = database().get_message_by_name(name)
    data = msg.encode({**values, "Freshness": 0, "Mac": 0}, strict=strict)
    return _message(name, sender.protect(msg.frame_id, data))


def control_message(command: str | int, token: int = 0, *, sender: SecOCSender) -> can.Message:
    """A Control frame secured by ``sender`` (the next freshness value);
    ``command`` is a name of :data:`COMMANDS` or a raw number."""
    cmd = COMMANDS[command] if isinstance(command, str) else int(command)
    return _secured("Control", {"Command": cmd, "Token": int(token)}, sender, strict=False)


def weight_load_messages(weights: Sequence[np.ndarray], *, sender: SecOCSender) -> list[can.Message]:
    """WeightLoad frames carrying w_i of every neuron (float32 on the wire),
    :data:`WEIGHTS_PER_FRAME` values a frame, each secured by ``sender``;
    send them between WeightsBegin and WeightsCommit, in order."""
    out = []
    for i, w in enumerate(weights):
        w = np.asarray(w, dtype=np.float32)
        for first in range(0, w.size, WEIGHTS_PER_FRAME):
            chunk = w[first:first + WEIGHTS_PER_FRAME]
            values: dict[str, Any] = {"Neuron": i, "First": first, "Count": int(chunk.size)}
            values.update({f"W{k:02d}": float(chunk[k]) if k < chunk.size else 0.0
                           for k in range(WEIGHTS_PER_FRAME)})
            out.append(_secured("WeightLoad", values, sender))
    return out


# -- bus timing -------------------------------------------------------------------------


def fd_frame_bits(payload: int, *, extended: bool = False) -> tuple[int, int]:
    """Worst-case length of one CAN FD frame with bit-rate switch (ISO
    11898-1:2015), as (arbitration-phase bits, data-phase bits).

    Arbitration phase at the nominal rate: SOF, identifier, RRS, IDE, FDF,
    res, BRS (17 bits with an 11-bit identifier, 36 with a 29-bit one), their
    worst-case stuff bits, and after the CRC delimiter ACK, ACK delimiter,
    EOF and intermission (12 bits). Data phase: ESI, DLC, the payload and
    their worst-case dynamic stuff bits (one per 4 bits after the first 5),
    the stuff count (4 bits), the CRC (17 bits up to 16 bytes, else 21) with
    its fixed stuff bits (6 or 7) and the CRC delimiter."""
    if payload not in (0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64):
        raise ValueError(f"payload: {payload} is not a CAN FD data length")
    head = 36 if extended else 17
    dynamic = head + 5 + 8 * payload                   # SOF .. end of data: dynamically stuffed
    stuff = (dynamic - 1) // 4
    stuff_head = (head - 1) // 4
    crc, fixed = (17, 6) if payload <= 16 else (21, 7)
    arbitration = head + stuff_head + 12
    data = 5 + 8 * payload + (stuff - stuff_head) + 4 + crc + fixed + 1
    return arbitration, data


def cycle_bus_time(nominal_bps: float, data_bps: float, *, frames: Sequence[str] = ("Measurement", "Estimate")
                   ) -> float:
    """Worst-case bus time in seconds of the given messages (one each), at
    the given arbitration and data bit rates."""
    total = 0.0
    for name in frames:
        a, d = fd_frame_bits(database().get_message_by_name(name).length)
        total += a / nominal_bps + d / data_bps
    return total


# -- the application ------------------------------------------------------------------------


def _make_c_config(config: IdentifierConfig, ffi: Any = _ffi) -> Any:
    # Identifier._c_config fills a rhonn_config from an IdentifierConfig
    # through whichever FFI it is handed: reuse it with the firmware's, so the
    # Python-to-C mapping of a configuration exists once.
    return Identifier._c_config(SimpleNamespace(_ffi=ffi), config)  # type: ignore[arg-type]


class FirmwareApp:
    """The firmware application (fw_app) on a python-can bus.

    Parameters
    ----------
    bus:
        A python-can bus (any interface: virtual, socketcan, pcan, ...), or
        None to drive the application with :meth:`handle` only.
    config:
        The identifier: an :class:`IdentifierConfig` (or an
        :class:`Identifier`, whose current weights become w0). It must be
        float32 (the firmware's precision) with the protocol's states and
        inputs (the LIM's: 6 and 2).
    deadline_ns:
        StepTime above this counts as an overrun (0: no check).
    diag_period:
        Accepted measurements per Diagnostics frame (0: on DiagRequest only).
    host_clock:
        True: the firmware's clock is the host's monotonic clock (real step
        times). False: a simulated clock that only :attr:`clock_ns` moves
        (deterministic diagnostics).
    protocol:
        A :class:`Protocol` with its ``library`` (the firmware compiled for
        another identifier's DBC); None: the LIM's.
    """

    def __init__(self, bus: can.BusABC | None, config: IdentifierConfig | Identifier, *,
                 deadline_ns: int = 300_000, diag_period: int = 0, host_clock: bool = True,
                 protocol: Protocol | None = None) -> None:
        if protocol is None:
            protocol = lim_protocol()
        if not isinstance(protocol, Protocol) or protocol.library is None:
            raise ValueError("protocol: expected a Protocol with the firmware compiled for it (library), got "
                             f"{type(protocol).__name__}")
        self._ffi, self._lib = protocol.library.ffi, protocol.library.lib
        self.protocol = protocol
        if isinstance(config, Identifier):
            config = config.as_config()
        if not isinstance(config, IdentifierConfig):
            raise ValueError(f"config: expected an IdentifierConfig or Identifier, got {type(config).__name__}")
        if config.dtype != "float32":
            raise ValueError(f"config.dtype: the firmware runs the float32 core, got {config.dtype!r} "
                             "(use config.replace(dtype='float32'))")
        n, m = int(self._lib.FW_N_STATES), int(self._lib.FW_N_INPUTS)
        if config.n_states != n or config.n_inputs != m:
            raise ValueError(f"config: the protocol carries {n} states and {m} inputs, got "
                             f"{config.n_states} states and {config.n_inputs} inputs")
        _check_capacity(config, {name: int(getattr(_lib, name)) for name in (
            "RHONN_MAX_STATES", "RHONN_MAX_INPUTS", "RHONN_MAX_TERMS", "RHONN_MAX_FACTORS", "RHONN_MAX_DELAY",
            "RHONN_MAX_POWER")})
        for name, value, hi in (("deadline_ns", deadline_ns, 2 ** 32 - 1), ("diag_period", diag_period, 2 ** 16 - 1)):
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not 0 <= value <= hi:
                raise ValueError(f"{name}: expected an integer in 0..{hi}, got {value!r}")
        if bus is not None and not (hasattr(bus, "recv") and hasattr(bus, "send")):
            raise ValueError(f"bus: expected a python-can bus, got {type(bus).__name__}")
        self._bus = bus
        self._config = config
        self._c_config = _make_c_config(config, self._ffi)  # copied into the identifier by fw_app_init
        self._app = self._ffi.new("fw_app *")
        self._mem = self._ffi.new("fw_mem_hal *")
        self._hal = self._ffi.new("fw_hal *")
        self._host_clock = bool(host_clock)
        self._lib.fwpy_bind_hal(self._mem, self._hal, 1 if host_clock else 0)
        app_cfg = self._ffi.new("fw_app_config *")
        app_cfg.identifier = self._c_config
        app_cfg.deadline_ns = int(deadline_ns)
        app_cfg.diag_period = int(diag_period)
        status = self._lib.fw_app_init(self._app, app_cfg, self._hal)
        if status != self._lib.FW_OK:
            name = self._status_name(status)
            raise FirmwareError(name, f"config: rejected by fw_app_init ({name})")
        self._frame = self._ffi.new("fw_frame *")
        self._data = self._ffi.new("uint8_t[]", int(self._lib.FW_MAX_FRAME_LEN) + 1)
        self._net = self._ffi.new("const rhonn_t **")
        self._lib.fw_app_get_identifier(self._app, self._net)
        self.last_status = "FW_OK"
        self.tx_failures = 0

    # -- driving it ---------------------------------------------------------------------

    @property
    def config(self) -> IdentifierConfig:
        return self._config

    @property
    def bus(self) -> can.BusABC | None:
        return self._bus

    @property
    def clock_ns(self) -> int:
        """The simulated clock (host_clock=False); each firmware read adds :attr:`tick_ns`."""
        return int(self._mem.now_ns)

    @clock_ns.setter
    def clock_ns(self, value: int) -> None:
        self._mem.now_ns = int(value)

    @property
    def tick_ns(self) -> int:
        return int(self._mem.tick_ns)

    @tick_ns.setter
    def tick_ns(self, value: int) -> None:
        self._mem.tick_ns = int(value)

    def _now(self) -> int:
        return int(self._lib.fwpy_now_ns()) if self._host_clock else int(self._mem.now_ns)

    def handle_frame(self, can_id: int, data: bytes, now_ns: int | None = None) -> list[can.Message]:
        """One received frame by SocketCAN-style id (with the FW_CAN_*_FLAG
        bits) and payload; returns what the firmware sends in response.
        :attr:`last_status` holds fw_app_on_frame's status name."""
        data = bytes(data)
        n = min(len(data), int(self._lib.FW_MAX_FRAME_LEN) + 1)  # anything longer is rejected alike (FW_E_LENGTH)
        self._ffi.memmove(self._data, data, n)
        status = self._lib.fw_app_on_frame(self._app, int(can_id) & 0xFFFFFFFF, self._data if n else self._ffi.NULL, n,
                                      self._now() if now_ns is None else int(now_ns))
        self.last_status = self._status_name(status)
        return self._drain()

    def handle(self, msg: can.Message) -> list[can.Message]:
        """One python-can message in, the firmware's replies out (the
        Estimate of a measurement, the ControlAck of a command, and any
        Diagnostics frame due)."""
        can_id = msg.arbitration_id
        if msg.is_extended_id:
            can_id |= int(self._lib.FW_CAN_EFF_FLAG)
        if msg.is_remote_frame:
            can_id |= int(self._lib.FW_CAN_RTR_FLAG)
        if msg.is_error_frame:
            can_id |= int(self._lib.FW_CAN_ERR_FLAG)
        return self.handle_frame(can_id, bytes(msg.data))

    def _drain(self) -> list[can.Message]:
        out = []
        f = self._frame
        while self._lib.fw_mem_hal_pop(self._mem, f) == self._lib.FW_OK:
            out.append(can.Message(
                arbitration_id=int(f.id) & 0x1FFFFFFF, is_extended_id=bool(f.id & self._lib.FW_CAN_EFF_FLAG),
                data=bytes(self._ffi.buffer(f.data, int(f.len))), is_fd=bool(f.flags & self._lib.FW_FRAME_FD),
                bitrate_switch=bool(f.flags & self._lib.FW_FRAME_BRS), timestamp=time.time()))
        return out

    def serve(self, n_frames: int | None = None, *, until: float | Callable[[], bool] | None = None,
              timeout: float = 0.05) -> int:
        """Receive from the bus, handle, send the replies; return the number
        of frames handled. Stops after ``n_frames`` frames, or when ``until``
        - a ``time.monotonic()`` deadline or a callable returning True - is
        reached (checked at least every ``timeout`` seconds). A reply the bus
        refuses (can.CanError) is counted in :attr:`tx_failures`."""
        if self._bus is None:
            raise ValueError("serve: this FirmwareApp has no bus (use handle)")
        if n_frames is None and until is None:
            raise ValueError("serve: give n_frames, until, or both")
        if n_frames is not None and (isinstance(n_frames, bool) or not isinstance(n_frames, int) or n_frames < 0):
            raise ValueError(f"n_frames: expected a non-negative int, got {n_frames!r}")
        if until is None:
            stop: Callable[[], bool] = lambda: False  # noqa: E731
        elif callable(until):
            stop = until
        else:
            deadline = float(until)
            stop = lambda: time.monotonic() >= deadline  # noqa: E731
        handled = 0
        while (n_frames is None or handled < n_frames) and not stop():
            msg = self._bus.recv(timeout)
            if msg is None:
                continue
            for reply in self.handle(msg):
                try:
                    self._bus.send(reply)
                except can.CanError:
                    self.tx_failures += 1
            handled += 1
        return handled

    def send_diagnostics(self) -> list[can.Message]:
        """A Diagnostics frame now, followed by one Health frame per neuron
        (returned, not sent)."""
        self._check(self._lib.fw_app_send_diagnostics(self._app), "send_diagnostics")
        return self._drain()

    def note_overrun(self) -> None:
        self._check(self._lib.fw_app_note_overrun(self._app), "note_overrun")

    def note_rx_drops(self, dropped: int) -> None:
        """Count frames the platform's receive queue dropped (``dropped`` in
        0..2**32-1), as the Linux runner does with the kernel's SO_RXQ_OVFL
        count."""
        if isinstance(dropped, bool) or not isinstance(dropped, (int, np.integer)) or not 0 <= dropped < 2 ** 32:
            raise ValueError(f"dropped: expected an integer in 0..{2 ** 32 - 1}, got {dropped!r}")
        self._check(self._lib.fw_app_note_rx_drops(self._app, int(dropped)), "note_rx_drops")

    # -- looking inside -----------------------------------------------------------------------

    @property
    def counters(self) -> dict[str, int]:
        c = self._ffi.new("fw_counters *")
        self._check(self._lib.fw_app_get_counters(self._app, c), "counters")
        return {name: int(getattr(c, name)) for name in _COUNTERS}

    @property
    def prediction(self) -> np.ndarray:
        """x̂(k) of the firmware's identifier (float32)."""
        out = np.empty(self._config.n_states, dtype=np.float32)
        self._check_core(self._lib.rhonn_get_prediction(self._net[0], self._ffi.from_buffer("float[]", out), out.size),
                         "prediction")
        return out

    def get_weights(self, neuron: int) -> np.ndarray:
        L = self._config.neurons[neuron].n_terms
        out = np.empty(L, dtype=np.float32)
        self._check_core(self._lib.rhonn_get_weights(self._net[0], neuron, self._ffi.from_buffer("float[]", out), L),
                         "weights")
        return out

    def get_covariance(self, neuron: int) -> np.ndarray:
        """P_i packed (upper triangle row by row), as the core stores it."""
        L = self._config.neurons[neuron].n_terms
        out = np.empty(L * (L + 1) // 2, dtype=np.float32)
        self._check_core(self._lib.rhonn_get_covariance(self._net[0], neuron, self._ffi.from_buffer("float[]", out),
                                                   out.size), "covariance")
        return out

    @property
    def freshness(self) -> int:
        """The last freshness value the firmware accepted (command authentication)."""
        out = self._ffi.new("uint64_t *")
        self._check(self._lib.fw_app_get_freshness(self._app, out), "freshness")
        return int(out[0])

    def identifier_bytes(self) -> bytes:
        """The whole rhonn_t, byte for byte (for bit-exact comparisons)."""
        return bytes(self._ffi.buffer(self._net[0], self._ffi.sizeof("rhonn_t")))

    def _status_name(self, status: int) -> str:
        return self._ffi.string(self._lib.fw_status_name(status)).decode()

    def _check(self, status: int, what: str) -> None:
        if status != self._lib.FW_OK:
            raise FirmwareError(self._status_name(status), f"{what}: {self._status_name(status)}")

    def _check_core(self, status: int, what: str) -> None:
        if status != 0:
            raise FirmwareError("FW_E_STATE", f"{what}: rejected by the core (status {status})")
