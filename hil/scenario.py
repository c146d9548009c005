"""The replay scenario: what the rig sends, and the truth it is scored against.

A :class:`Scenario` is a validated, seeded description of the paper's
real-time LIM test (section 6.3.2): the LIM of :mod:`pyrhonn.plants.lim`
simulated at the rig's period T = 0.3 ms, and what the real rig did to the
signals before they reached the identifier:

1. **Encoder quantisation** of the position, ``encoder_resolution`` metres
   per count (``floor``: an incremental count). Default 10 um: the paper's
   position sensor is an Acu-Rite SENC 50 glass-scale linear encoder; SENC 50
   read heads come in 0.5, 1, 2, 5 and 10 um resolutions, and 10 um is the
   one recalled for this rig (from the LIM papers of Alanis, Sanchez and
   Loukianov; RECALLED, confidence LOW - not verified against the paper's
   text here, so keep it configurable).
2. **Velocity by differencing** the quantised position,
   v(k) = (q(k) - q(k-1)) / T (the "high-frequency content" the paper
   mentions: one count per period is 10 um / 0.3 ms = 33 mm/s).
3. **The measurement hold**: states ``hold_states`` (default the position)
   are not updated for ``hold_duration`` from ``hold_start`` (the real-time
   test: from 1.1 s, lim.paper_holds); held samples go out with their
   Valid flag cleared and the last valid reading.
   **A value derived from a held or missing one is not valid either**: the
   differenced velocity v(k) needs fresh positions at k and k-1, so it is
   marked not valid through the position hold and on the first sample after
   it (whose difference spans the whole hold), and on the very first sample
   of the trajectory (no previous reading). Otherwise the rig would send the
   difference of two held readings, 0, as a fresh velocity, and the
   identifier would learn that the motor stopped. During a dropout the
   firmware replaces each invalid state by its own prediction and learns
   nothing from it. ``Plan.not_valid`` counts the flags cleared, by reason.
4. **Random frame loss**: each Measurement frame is lost on the wire with
   probability ``frame_loss`` (seeded); the rig never sends it, so the
   firmware sees a sequence-counter jump on the next one.
5. **A fixed transport delay**: every frame leaves ``transport_delay``
   seconds after its sampling instant k*T.

The LIM's input switches on at ``input_start``: 2.0 s, the paper's timing
(section 6.3.2 repeats the simulation test of section 6.3.1, whose voltages,
eq. 21-22, start at 2 s), so the motor is at rest when the 1.1 s hold begins
and starts 0.1 s before it ends. ``input_start = 1.0`` (the default before)
makes the motor move through the whole hold instead: a harder bridging test.
The plant's parameters are pyrhonn's PROPOSED
:class:`~pyrhonn.plants.lim.LimParams` (the Lab-Volt table was not found), so
Table 7's figures are a yardstick, not a target of the same motor: the report
states the signals' scale next to them.

**A recorded trajectory** replaces the plant with ``trajectory`` (the path
of a CSV of the LIM's states and inputs, :mod:`hil.trajectory`): the same
rig model is applied to it and the replay is scored against it. Times
(``start``, ``hold_start``) are then on the file's time axis, and
``input_start`` does not apply. The scenario pins the file's SHA-256
(``trajectory_sha256``, computed when not given): a logged run re-scores
only against the very file it was replayed from.

**Another identifier** replaces the LIM: ``identifier`` (the path of the
config file its export started from, float32) and ``dbc`` (the DBC
``pyrhonn export --dbc`` wrote for it). Its plant is always a recording:
``trajectory`` is a CSV with ``t`` and the config's state and input
columns (:func:`hil.trajectory.read_trajectory`), replayed as the
Measurement frames of that DBC, and the estimates are scored per state,
by the config's names, against the recording's x(k+1). The LIM's encoder
model does not apply (``encoder_resolution`` 0, ``velocity_from_position``
false: :func:`identifier_defaults` sets them); holds (``hold_states``: the
config's state indices), frame loss and delay do. Both files are pinned
by SHA-256 as the trajectory is.

Everything derives from the scenario's fields and ``seed``: the same
scenario always gives the same frames, which is what lets a logged run be
re-scored offline from the log and the scenario alone.
"""
from __future__ import annotations

import functools
import json
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["ENCODER_SENC50", "Plan", "Scenario", "TABLE7", "identifier_defaults"]

#: Acu-Rite SENC 50 linear encoder resolution assumed for the paper's rig, m
#: (RECALLED, confidence LOW; see the module docstring).
ENCODER_SENC50 = 10e-6
#: Table 7 of the paper (real-time LIM test): RMSE and absolute deviation.
TABLE7 = {"position": {"rmse": 6.8973e-5, "absolute_deviation": 7.5676e-6},
          "velocity": {"rmse": 6.1873e-4, "absolute_deviation": 1.3028e-4}}


def _fail(name: str, why: str) -> ValueError:
    return ValueError(f"{name}: {why}")


def _real(name: str, value: Any, *, lo: float | None = None, lo_open: bool = False, hi: float | None = None,
          hi_open: bool = False) -> float:
    from pyrhonn.validation import check_real

    v = check_real(name, value)  # a real, finite number (a huge JSON integer included)
    if lo is not None and (v <= lo if lo_open else v < lo):
        raise _fail(name, f"must be {'>' if lo_open else '>='} {lo}, got {value!r}")
    if hi is not None and (v >= hi if hi_open else v > hi):
        raise _fail(name, f"must be {'<' if hi_open else '<='} {hi}, got {value!r}")
    return v


@dataclass(frozen=True)
class Scenario:
    """The seeded replay scenario (all times in seconds). See the module docstring."""

    duration: float = 4.0             #: replayed time; cycles = round(duration / period)
    period: float = 3e-4              #: the rig's period T (paper: 0.3 ms)
    start: float = 0.0                #: time of the first replayed sample (rounded to a period)
    input_start: float = 2.0          #: the LIM's voltages switch on (eq. 21-22: 2 s)
    encoder_resolution: float = ENCODER_SENC50  #: m per count, 0 = not quantised
    quantiser: str = "floor"          #: "floor" (incremental count) or "round"
    velocity_from_position: bool = True  #: v = difference of the quantised position / T
    hold_start: float = 1.1           #: measurement hold (paper real-time test: 1.1 s)
    hold_duration: float = 1.0        #: 0 = no hold
    hold_states: tuple[int, ...] = (0,)  #: states held (0 = position)
    frame_loss: float = 0.0           #: probability a Measurement frame is lost
    transport_delay: float = 0.0      #: fixed delay from sampling instant to sending
    seed: int = 0
    trajectory: str = ""              #: "" = the plant; else a trajectory CSV (hil.trajectory), absolute path
    trajectory_sha256: str = ""       #: the file's SHA-256; computed when "", checked when given
    identifier: str = ""              #: "" = the LIM (firmware-lim); else an identifier's config file, absolute path
    identifier_sha256: str = ""       #: that file's SHA-256, as trajectory_sha256
    dbc: str = ""                     #: the identifier's protocol DBC (pyrhonn export --dbc), absolute path
    dbc_sha256: str = ""              #: that file's SHA-256, as trajectory_sha256

    def __post_init__(self) -> None:
        set_ = functools.partial(object.__setattr__, self)
        set_("period", _real("period", self.period, lo=1e-5, hi=1.0))
        set_("duration", _real("duration", self.duration, lo=0.0, lo_open=True, hi=3600.0))
        set_("start", _real("start", self.start, lo=0.0, hi=3600.0))
        if self.cycles < 2:
            raise _fail("duration", f"must cover at least 2 periods, got {self.duration!r}")
        set_("input_start", _real("input_start", self.input_start, lo=0.0))
        set_("encoder_resolution", _real("encoder_resolution", self.encoder_resolution, lo=0.0, hi=0.01))
        if self.quantiser not in ("floor", "round"):
            raise _fail("quantiser", f"expected 'floor' or 'round', got {self.quantiser!r}")
        if not isinstance(self.velocity_from_position, bool):
            raise _fail("velocity_from_position", f"expected a bool, got {self.velocity_from_position!r}")
        set_("hold_start", _real("hold_start", self.hold_start, lo=0.0))
        set_("hold_duration", _real("hold_duration", self.hold_duration, lo=0.0))
        states = tuple(self.hold_states) if isinstance(self.hold_states, (tuple, list)) else None
        if states is None or any(isinstance(s, bool) or not isinstance(s, (int, np.integer)) or not 0 <= s < 32
                                 for s in states):
            raise _fail("hold_states", f"expected a tuple of state indices, got {self.hold_states!r}")
        set_("hold_states", tuple(int(s) for s in states))
        set_("frame_loss", _real("frame_loss", self.frame_loss, lo=0.0, hi=0.5))
        set_("transport_delay", _real("transport_delay", self.transport_delay, lo=0.0, hi=1.0))
        if isinstance(self.seed, bool) or not isinstance(self.seed, (int, np.integer)) or not 0 <= self.seed < 2 ** 63:
            raise _fail("seed", f"expected a non-negative integer, got {self.seed!r}")
        set_("seed", int(self.seed))
        for name in ("trajectory", "identifier", "dbc"):
            self._check_file(set_, name)
        self._check_identifier()

    def _check_file(self, set_, name: str) -> None:
        from .trajectory import file_sha256

        path, pinned = getattr(self, name), getattr(self, f"{name}_sha256")
        if not isinstance(path, str):
            raise _fail(name, f"expected a file path (str), got {path!r}")
        if not isinstance(pinned, str):
            raise _fail(f"{name}_sha256", f"expected a hex string, got {pinned!r}")
        if not path:
            if pinned:
                raise _fail(f"{name}_sha256", f"given without a {name}")
            return
        absolute = str(Path(path).expanduser().resolve())
        try:
            digest = file_sha256(absolute)
        except OSError as exc:
            raise _fail(name, f"cannot read {absolute}: {exc.strerror or exc}") from None
        if pinned and pinned != digest:
            raise _fail(name, f"{absolute} has changed since this scenario was made (SHA-256 {pinned[:12]}..., "
                              f"now {digest[:12]}...): a run re-scores only against the file it replayed")
        set_(name, absolute)
        set_(f"{name}_sha256", digest)

    def _check_identifier(self) -> None:
        if bool(self.identifier) != bool(self.dbc):
            raise _fail("dbc" if self.identifier else "identifier",
                        "an identifier's config file and its DBC go together (give both, or neither for the LIM)")
        n = len(self.state_names)
        if any(s >= n for s in self.hold_states):
            raise _fail("hold_states", f"expected state indices 0..{n - 1} (the identifier's {n} states), got "
                                       f"{list(self.hold_states)}")
        if not self.identifier:
            return
        if not self.trajectory:
            raise _fail("trajectory", "an identifier's plant is a recording: give its CSV (t and the config's "
                                      "states and inputs)")
        if self.encoder_resolution != 0.0 or self.velocity_from_position:
            raise _fail("encoder_resolution" if self.encoder_resolution else "velocity_from_position",
                        "the LIM's encoder model (a quantised position, the velocity differenced from it) does not "
                        "apply to another identifier: set encoder_resolution 0 and velocity_from_position false")
        cf = self.identifier_file()
        proto = self.protocol()
        if tuple(cf.state_names) != proto.states or tuple(cf.input_names) != proto.inputs:
            raise _fail("dbc", f"{self.dbc} carries states {list(proto.states)} and inputs {list(proto.inputs)}; "
                               f"{self.identifier} identifies states {list(cf.state_names)} and inputs "
                               f"{list(cf.input_names)} (export the DBC from this config)")
        if cf.config.dtype != "float32":
            raise _fail("identifier", f"{self.identifier}: dtype is {cf.config.dtype!r}; the firmware runs the "
                                      "float32 core (tune or select with --dtype float32)")

    def identifier_file(self) -> Any:
        """The identifier's config file (pyrhonn.configfile.ConfigFile): the scenario's, or firmware-lim."""
        return _config_file(self.identifier, self.identifier_sha256)

    def reference_config(self) -> Any:
        """The float32 IdentifierConfig the firmware runs (the bit-exact check's reference)."""
        config = self.identifier_file().config
        return config if config.dtype == "float32" else config.replace(dtype="float32")

    def protocol(self) -> Any:
        """The rig's side of the protocol (pyrhonn.firmware.Protocol): the DBC's, or the LIM's."""
        return _protocol(self.dbc, self.dbc_sha256)

    @property
    def state_names(self) -> tuple[str, ...]:
        """The protocol's state signals (the LIM's: Qm, V, ...), in the identifier's order."""
        return tuple(self.protocol().states) if self.dbc else _LIM_STATES

    @property
    def cycles(self) -> int:
        return int(round(self.duration / self.period))

    @classmethod
    def at_rest(cls, cycles: int, **fields_: Any) -> Scenario:
        """``cycles`` periods of the LIM at rest (its voltages never switch on,
        no hold) for timing runs: any number of cycles stays inside the DBC's
        ranges, and the firmware's step costs the same whatever the values."""
        duration = cycles * fields_.get("period", 3e-4)
        return cls(duration=duration, hold_duration=0.0, input_start=duration + 1.0, **fields_)

    def replace(self, **changes: Any) -> Scenario:
        if "trajectory" in changes and "trajectory_sha256" not in changes:
            changes["trajectory_sha256"] = ""   # another file: pin its own content
        return Scenario(**{**asdict(self), **changes})

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["hold_states"] = list(self.hold_states)
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Scenario:
        if not isinstance(d, dict):
            raise _fail("scenario", f"expected a mapping, got {type(d).__name__}")
        names = {f.name for f in fields(cls)}
        unknown = sorted(set(d) - names)
        if unknown:
            raise _fail("scenario", f"unknown fields {unknown}")
        d = dict(d)
        if "hold_states" in d and isinstance(d["hold_states"], list):
            d["hold_states"] = tuple(d["hold_states"])
        return cls(**d)

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), sort_keys=True)

    def build(self) -> Plan:
        return _build(self)


_LIM_STATES = ("Qm", "V", "LambdaA", "LambdaB", "Ia", "Ib")


@functools.lru_cache(maxsize=8)
def _config_file(path: str, digest: str) -> Any:
    from pyrhonn.configfile import load_config, load_shipped

    if not path:
        return load_shipped("firmware-lim")
    try:
        return load_config(path)
    except OSError as exc:
        raise _fail("identifier", f"cannot read {path}: {exc.strerror or exc}") from None
    except ValueError as exc:
        raise _fail("identifier", str(exc)) from None


@functools.lru_cache(maxsize=8)
def _protocol(path: str, digest: str) -> Any:
    from pyrhonn.firmware import Protocol, lim_protocol

    if not path:
        return lim_protocol()
    try:
        return Protocol.from_dbc(path)
    except ValueError as exc:
        raise _fail("dbc", str(exc)) from None


def identifier_defaults(fields_: dict[str, Any]) -> dict[str, Any]:
    """``fields_`` with, when it names an identifier, the LIM-only settings that do not apply to it off unless
    set: no encoder quantisation, no velocity differencing, no hold."""
    if not fields_.get("identifier"):
        return fields_
    return {"encoder_resolution": 0.0, "velocity_from_position": False, "hold_duration": 0.0, **fields_}


@dataclass(frozen=True, eq=False)
class Plan:
    """The frames of a scenario, cycle by cycle (N = scenario.cycles).

    ``X`` (N, n), ``U`` (N, m), ``valid`` (N, n) (the LIM: n = 6, m = 2):
    what Measurement k carries (Seq = k mod 65536); ``truth_next`` (N, n):
    the noise-free (or recorded) x(k+1) that Estimate k predicts; ``lost``
    (N,): frames lost on the wire; ``t`` (N,): sampling instants;
    ``derived`` (N, n): the flags of ``valid`` cleared
    because the value is derived from a held or missing reading (the
    differenced velocity), not held itself.
    """

    scenario: Scenario
    t: np.ndarray
    X: np.ndarray
    U: np.ndarray
    valid: np.ndarray
    truth_next: np.ndarray
    lost: np.ndarray
    derived: np.ndarray

    @property
    def cycles(self) -> int:
        return int(self.t.shape[0])

    @property
    def not_valid(self) -> dict[str, dict[str, int]]:
        """Per state signal with any flag cleared, how many samples went out
        not valid and why: ``held`` (the measurement hold) and ``derived``
        (computed from a held or missing reading)."""
        held = ~self.valid & ~self.derived
        return {name: {"held": int(held[:, j].sum()), "derived": int(self.derived[:, j].sum())}
                for j, name in enumerate(self.scenario.state_names) if not self.valid[:, j].all()}

    def frames(self) -> list:
        """The Measurement frames (python-can messages), lost ones included."""
        proto = self.scenario.protocol()
        return [proto.measurement_message(k & 0xFFFF, self.X[k], self.U[k], self.valid[k])
                for k in range(self.cycles)]


def _recorded(sc: Scenario, cycles: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """(X, U, t, k0) of the scenario's trajectory file: its samples at the
    period, and the index of the first replayed one (t = start)."""
    from .trajectory import file_sha256, read_trajectory

    if file_sha256(sc.trajectory) != sc.trajectory_sha256:
        raise _fail("trajectory", f"{sc.trajectory} has changed since this scenario was made")
    rt = read_trajectory(sc.trajectory, sc.period, sc.identifier_file() if sc.identifier else None)
    t = rt.t
    k0 = int(round((sc.start - t[0]) / sc.period))
    need = k0 + cycles + 1                       # x(k+1) of the last frame included
    if sc.start < t[0] - 1e-6 * sc.period or need > t.size:
        raise _fail("trajectory", f"{sc.trajectory} covers t = {t[0]:g}..{t[-1]:g} s at {sc.period:g} s; the "
                                  f"scenario needs {sc.start:g}..{sc.start + cycles * sc.period:g} s (start, duration)")
    return rt.X, rt.U, t, k0


@functools.lru_cache(maxsize=8)
def _build(sc: Scenario) -> Plan:
    from pyrhonn.plants import lim
    from pyrhonn.plants.trajectory import HoldWindow

    proto = sc.protocol()
    n = len(proto.states)

    N = sc.cycles
    if sc.trajectory:
        Xtrue, U, t, k0 = _recorded(sc, N)
    else:
        k0 = int(round(sc.start / sc.period))
        horizon = (k0 + N) * sc.period          # samples 0 .. k0+N: x(k+1) of the last frame included
        traj = lim.simulate(dt=sc.period, horizon=horizon, inputs=lim.LimInput(start=sc.input_start), holds=())
        Xtrue, U, t = traj.X, traj.U, traj.t
    reading = Xtrue.copy()
    if sc.encoder_resolution > 0:
        levels = Xtrue[:, 0] / sc.encoder_resolution
        levels = np.floor(levels) if sc.quantiser == "floor" else np.round(levels)
        reading[:, 0] = levels * sc.encoder_resolution
    T = Xtrue.shape[0]
    valid = np.ones((T, n), dtype=bool)
    if sc.hold_duration > 0:
        for j in sc.hold_states:
            valid[HoldWindow(j, sc.hold_start, sc.hold_duration).mask(t, sc.period), j] = False
    derived = np.zeros((T, n), dtype=bool)
    if sc.velocity_from_position:
        reading[1:, 1] = np.diff(reading[:, 0]) / sc.period
        reading[0, 1] = 0.0
        # v(k) is fresh only if both positions it differences are: not through a hold of the position,
        # nor on the first sample after it (the difference spans the hold), nor at sample 0 (no q(-1))
        fresh = valid[:, 0].copy()
        fresh[1:] &= valid[:-1, 0]
        fresh[0] = False
        derived[:, 1] = valid[:, 1] & ~fresh
        valid[:, 1] &= fresh
    idx = np.where(valid, np.arange(T)[:, None], -1)
    np.maximum.accumulate(idx, axis=0, out=idx)
    held = np.take_along_axis(reading, np.maximum(idx, 0), axis=0)
    held[idx < 0] = 0.0                      # invalid before any valid reading: ignored by the firmware
    sl = slice(k0, k0 + N)
    X, Uk, V, D = held[sl].copy(), U[sl].copy(), valid[sl].copy(), derived[sl].copy()
    # the DBC's ranges: refuse a scenario the protocol cannot carry, naming where
    for j, name in enumerate(proto.states + proto.inputs):
        col = X[:, j] if j < n else Uk[:, j - n]
        lo, hi = proto.signal_range(name)
        bad = (col < lo) | (col > hi)
        if bad.any():
            k = int(np.argmax(bad))
            span = f"start {sc.start:g} s and duration {sc.duration:g} s"
            why = (f"t is the trajectory file's time: {span} replay a part of it the DBC cannot carry"
                   if sc.trajectory else f"t is the trajectory time: {span} take the simulated LIM, driven from "
                                         f"input_start {sc.input_start:g} s, outside what the DBC can carry")
            raise ValueError(f"scenario: {name} = {float(col[k]):.6g} at t = {t[k0 + k]:.4f} s is outside the DBC range "
                             f"[{lo:g}, {hi:g}] ({why})")
    rng = np.random.default_rng(np.random.SeedSequence([sc.seed, 0x4811]))
    lost = rng.random(N) < sc.frame_loss if sc.frame_loss > 0 else np.zeros(N, dtype=bool)
    for a in (X, Uk, V, D, lost):
        a.setflags(write=False)
    truth_next = Xtrue[k0 + 1:k0 + N + 1].copy()
    truth_next.setflags(write=False)
    tk = t[sl].copy()
    tk.setflags(write=False)
    return Plan(scenario=sc, t=tk, X=X, U=Uk, valid=V, truth_next=truth_next, lost=lost,
                derived=D)
