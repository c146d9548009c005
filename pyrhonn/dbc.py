"""A CAN FD database (DBC) for an exported identifier: ``pyrhonn export --dbc``.

The frames are those of the LIM firmware's protocol (``firmware_sim/rhonn_id.dbc``),
laid out for this identifier's states and inputs:

- **Measurement** (id 256, rig -> identifier): ``Seq`` (16 bits), one ``Valid<state>``
  flag per state, then every state and every input, each a 16-bit signed
  integer at its own scale;
- **Estimate** (id 257, identifier -> rig): ``Seq``, ``StepStatus``, ``Learning``,
  ``Saturated``, ``Resync``, then ``<state>Hat`` per state, at its
  Measurement signal's scale;
- **Control**, **ControlAck**, **WeightLoad**, **Diagnostics** and **Health**: the
  LIM protocol's own, the neuron index ranges set to this identifier's.

Each frame is as long as the CAN FD length that holds it (at most 64 bytes:
an identifier whose Measurement does not fit is refused, naming how many
bytes it needs).

**Scaling from the data.** Each state's and input's signal covers the range
the data file takes, with ``headroom`` (default 1.0: twice the data's largest
magnitude) either side of 0; its scale (one LSB, the signal's resolution) is
the smallest 1, 2 or 5 times a power of ten at which 16 signed bits reach
that range (below 1, that is 1/N for an integer N). A signal that is 0
throughout gets +-1; a largest magnitude below 1e-20 or above 1e30 is
refused. Each signal's comment states the data's range, the resolution and
the accepted range, and :func:`scalings` returns them.
"""
from __future__ import annotations

import copy
import math
from dataclasses import dataclass
from decimal import Decimal
from pathlib import Path
from typing import TYPE_CHECKING, Any, Sequence

import numpy as np

if TYPE_CHECKING:
    from .configfile import ConfigFile

__all__ = ["FD_LENGTHS", "SignalScaling", "database_text", "export_dbc", "scaling_for", "scalings", "write_dbc"]

#: the CAN FD frame lengths, bytes
FD_LENGTHS = (8, 12, 16, 20, 24, 32, 48, 64)
BITS = 16  #: every state and input signal is a 16-bit signed integer
RAW_MAX = 2 ** (BITS - 1) - 1
MEASUREMENT_ID, ESTIMATE_ID = 256, 257
MAGNITUDES = (1e-20, 1e30)  #: the largest magnitude (headroom included) a signal may be scaled for


@dataclass(frozen=True)
class SignalScaling:
    """One state's or input's signal: ``scale`` is its LSB (resolution), ``limit`` the accepted
    magnitude (the signal's range is [-limit, limit]); ``data_min``, ``data_max`` the data's range."""

    name: str
    scale: float
    limit: float
    data_min: float
    data_max: float

    @property
    def comment(self) -> str:
        return (f"Scaled from the data's range [{self.data_min:.6g}, {self.data_max:.6g}]: resolution "
                f"{self.scale:g} per LSB, {BITS}-bit signed, accepted range +-{self.limit:g}.")


def _nice_step(reach: float) -> float:
    """The smallest 1, 2 or 5 times a power of ten whose RAW_MAX steps reach ``reach`` (> 0)."""
    exp = math.floor(math.log10(reach / RAW_MAX))
    for e in (exp - 1, exp, exp + 1, exp + 2):
        for m in (1, 2, 5):
            step = float(f"{m}e{e}")        # the decimal text, as the DBC holds it
            if step * RAW_MAX >= reach:
                return step
    raise AssertionError(reach)   # 10^(exp+2) reaches it always


def scaling_for(name: str, values: np.ndarray, headroom: float = 1.0) -> SignalScaling:
    """The 16-bit signal of ``values`` (finite ones; the data's range) with ``headroom`` (a fraction of
    the largest magnitude) either side; a ValueError naming ``name`` when there is no finite value."""
    from .validation import check_real

    headroom = check_real("headroom", headroom, nonnegative=True)
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v)]
    if v.size == 0:
        raise ValueError(f"{name}: no finite value in the data to scale its signal from")
    lo, hi = float(v.min()), float(v.max())
    peak = max(abs(lo), abs(hi))
    reach = peak * (1.0 + headroom)
    if reach == 0.0:
        reach = 1.0                                 # a signal that is 0 throughout: +-1
    if not math.isfinite(reach) or not MAGNITUDES[0] <= reach <= MAGNITUDES[1]:
        raise ValueError(f"{name}: the data's largest magnitude {peak:g} is outside what a scaled 16-bit signal "
                         f"carries here ({MAGNITUDES[0]:g} .. {MAGNITUDES[1]:g} with the headroom)")
    scale = _nice_step(reach)
    # the accepted range: whole LSBs that cover the reach (the nearest float of the exact decimal product,
    # never below the data's largest magnitude, which is a float at most that product)
    count = min(RAW_MAX, math.ceil(reach / scale))
    limit = float(Decimal(count) * Decimal(repr(scale)))
    return SignalScaling(name=name, scale=scale, limit=limit, data_min=lo, data_max=hi)


def scalings(state_names: Sequence[str], input_names: Sequence[str], X: np.ndarray, U: np.ndarray,
             headroom: float = 1.0) -> list[SignalScaling]:
    """Every state's and input's signal, in that order, scaled from the data ``X`` (T, n) and ``U`` (T, m)."""
    n, m = len(state_names), len(input_names)
    if not isinstance(X, np.ndarray) or X.ndim != 2 or X.shape[1] != n:
        raise ValueError(f"X: expected an array (T, {n}), got {getattr(X, 'shape', type(X).__name__)}")
    if not isinstance(U, np.ndarray) or U.ndim != 2 or U.shape != (X.shape[0], m):
        raise ValueError(f"U: expected an array ({X.shape[0]}, {m}), got {getattr(U, 'shape', type(U).__name__)}")
    return ([scaling_for(name, X[:, j], headroom) for j, name in enumerate(state_names)]
            + [scaling_for(name, U[:, j], headroom) for j, name in enumerate(input_names)])


def _fd_length(bits: int, what: str) -> int:
    need = -(-bits // 8)
    for length in FD_LENGTHS:
        if length >= need:
            return length
    raise ValueError(f"{what}: needs {need} bytes, more than the 64 a CAN FD frame carries")


def _signal_line(name: str, start: int, s: SignalScaling, receiver: str) -> str:
    return f' SG_ {name} : {start}|{BITS}@1- ({s.scale:g},0) [{-s.limit:g}|{s.limit:g}] "" {receiver}'


def _frames_text(state_names: Sequence[str], sig: list[SignalScaling], version: str) -> str:
    """A DBC of the Measurement and Estimate frames alone (merged with the protocol's other frames)."""
    n = len(state_names)
    flags_end = 16 + n
    first = -(-flags_end // 8) * 8                      # the values start on a byte
    meas_bits = first + BITS * len(sig)
    meas_len = _fd_length(meas_bits, f"Measurement of {n} states and {len(sig) - n} inputs")
    est_len = _fd_length(24 + BITS * n, f"Estimate of {n} states")
    lines = [f'VERSION "{version}"', "", "NS_ :", "", "BS_:", "", "BU_: RIG RHONN", "",
             f"BO_ {MEASUREMENT_ID} Measurement: {meas_len} RIG",
             ' SG_ Seq : 0|16@1+ (1,0) [0|65535] "" RHONN']
    lines += [f' SG_ Valid{name} : {16 + j}|1@1+ (1,0) [0|1] "" RHONN' for j, name in enumerate(state_names)]
    lines += [_signal_line(s.name, first + BITS * i, s, "RHONN") for i, s in enumerate(sig)]
    lines += ["", f"BO_ {ESTIMATE_ID} Estimate: {est_len} RHONN",
              ' SG_ Seq : 0|16@1+ (1,0) [0|65535] "" RIG', ' SG_ StepStatus : 16|4@1+ (1,0) [0|15] "" RIG',
              ' SG_ Learning : 20|1@1+ (1,0) [0|1] "" RIG', ' SG_ Saturated : 21|1@1+ (1,0) [0|1] "" RIG',
              ' SG_ Resync : 22|1@1+ (1,0) [0|1] "" RIG']
    lines += [_signal_line(f"{s.name}Hat", 24 + BITS * j, s, "RIG") for j, s in enumerate(sig[:n])]
    lines += ["", ""]
    lines.append(f'CM_ BO_ {MEASUREMENT_ID} "One sample x(k), u(k) per cycle: {n} states, each with its Valid flag '
                 f'(0: dropped or held; neither learnt nor used), and {len(sig) - n} input(s). Rejected as the LIM '
                 'protocol\'s Measurement: wrong length, a valid state or any input outside its range, a repeated '
                 'or jumping Seq.";')
    lines.append(f'CM_ SG_ {MEASUREMENT_ID} Seq "Sequence counter, +1 per cycle, wraps 65535 -> 0. Echoed in the '
                 'Estimate.";')
    lines += [f'CM_ SG_ {MEASUREMENT_ID} Valid{name} "1: {name} is a fresh measurement; 0: dropped or held."; '
              for name in state_names]
    lines += [f'CM_ SG_ {MEASUREMENT_ID} {s.name} "{s.comment}";' for s in sig]
    lines.append(f'CM_ BO_ {ESTIMATE_ID} "x_hat(k+1), the prediction made from the Measurement with the same Seq, '
                 'at the Measurement\'s scaling, rounded to the nearest LSB and saturated to the signal\'s range.";')
    lines += [f'CM_ SG_ {ESTIMATE_ID} {s.name}Hat "Predicted {s.name}(k+1), scaled as Measurement.{s.name}: '
              f'resolution {s.scale:g}, accepted range +-{s.limit:g}.";' for s in sig[:n]]
    return "\n".join(line.rstrip() for line in lines) + "\n"


def database_text(state_names: Sequence[str], input_names: Sequence[str], X: np.ndarray, U: np.ndarray, *,
                  name: str = "identifier", headroom: float = 1.0) -> tuple[str, list[SignalScaling]]:
    """The DBC text of an identifier's protocol (see the module docstring) and its signals' scalings."""
    import cantools
    from cantools.database.can import Bus

    from .firmware import database

    sig = scalings(state_names, input_names, X, U, headroom)
    n = len(state_names)
    protocol = copy.deepcopy(database())   # database() is the process's own protocol, cached: not changed here
    protocol_version = protocol.version
    version = f"{protocol_version} {name}"
    frames: Any = cantools.database.load_string(_frames_text(state_names, sig, version), database_format="dbc")
    messages: list[Any] = []
    for msg in protocol.messages:
        if msg.frame_id in (MEASUREMENT_ID, ESTIMATE_ID):
            new = frames.get_message_by_frame_id(msg.frame_id)
            new.is_fd = True
            new.dbc = msg.dbc                          # the frame's attributes: CAN FD with bit-rate switch
            for field in new.signals:                  # the value tables (Estimate.StepStatus) the firmware reads
                if field.name in msg.signal_tree and msg.get_signal_by_name(field.name).choices:
                    field.choices = copy.deepcopy(msg.get_signal_by_name(field.name).choices)
            messages.append(new)
            continue
        for s in msg.signals:
            if s.name == "Neuron":
                s.maximum = n - 1
                s.comment = f"Neuron (state) index, 0..{n - 1}."
        messages.append(msg)
    protocol.messages[:] = messages
    protocol.version = version
    meas, est = (frames.get_message_by_frame_id(i) for i in (MEASUREMENT_ID, ESTIMATE_ID))
    for i, bus in enumerate(protocol.buses):
        protocol.buses[i] = Bus(name=bus.name, baudrate=bus.baudrate, fd_baudrate=bus.fd_baudrate, comment=(
                       f"pyrhonn export: the RHONN identifier {name} ({n} states, {len(sig) - n} inputs) as a CAN FD "
                       f"node, in the protocol of firmware_sim/rhonn_id.dbc ({protocol_version}): per cycle one "
                       f"Measurement ({meas.length} bytes) from the rig and one Estimate ({est.length} bytes) back. "
                       "State and input signals are 16-bit signed, scaled from the data's ranges (each signal's "
                       "comment states its resolution and accepted range). All messages are CAN FD with bit-rate "
                       "switch, 11-bit identifiers, little-endian (Intel) signals."))
    protocol.refresh()
    return protocol.as_dbc_string(), sig


def write_dbc(path: str | Path, state_names: Sequence[str], input_names: Sequence[str], X: np.ndarray,
              U: np.ndarray, *, name: str = "identifier", headroom: float = 1.0) -> list[SignalScaling]:
    """Write :func:`database_text` to ``path`` (replaced whole); the signals' scalings."""
    from . import atomic

    text, sig = database_text(state_names, input_names, X, U, name=name, headroom=headroom)
    atomic.write_text(path, text)
    return sig


def export_dbc(path: str | Path, cf: ConfigFile, X: np.ndarray, U: np.ndarray, valid: np.ndarray, *,
               name: str) -> list[str]:
    """``pyrhonn export --dbc``: the DBC of the config file ``cf``'s identifier, scaled from a data file's
    measured values (a state's value not valid on a row is not part of its range); one line per signal
    saying its resolution and range."""
    if not isinstance(valid, np.ndarray) or valid.shape != X.shape or valid.dtype != np.bool_:
        raise ValueError(f"valid: expected a bool array of shape {X.shape}")
    measured = np.where(valid, np.asarray(X, dtype=np.float64), np.nan)
    sig = write_dbc(path, cf.state_names, cf.input_names, measured, np.asarray(U, dtype=np.float64), name=name)
    return [f"  {s.name:<16} resolution {s.scale:<8g} accepted +-{s.limit:<10g} (data {s.data_min:.6g} .. "
            f"{s.data_max:.6g})" for s in sig]
