"""Example 2 of the paper: the electrically driven differential (two-wheeled) mobile robot of [17].

Full description, sources and confidence: docs/plants.md#robot.

States chi = [X, Y, theta, omega1, omega2, i1, i2]: pose of the axle midpoint
(m, m, rad), right/left wheel angular velocities (rad/s), armature currents
(A). Inputs u = [u1, u2], motor voltages (V).

Continuous-time model (block form chi1 = [X, Y, theta], chi2 = omega, chi3 = i):

    chi1' = J(theta) omega,     J = (r/2) [[cos th, cos th], [sin th, sin th], [1/b, -1/b]]
    M omega' + C(theta') omega + D omega = N K_T i
    L_a i' + R_a i + K_E N omega = u

    M = [[m11, m12], [m12, m11]],  m11 = r^2/(4 b^2) (m b^2 + I) + I_w,  m12 = r^2/(4 b^2) (m b^2 - I)
    m = m_c + 2 m_w,  I = m_c d^2 + 2 m_w b^2 + I_c + 2 I_m
    C = [[0, c theta'], [-c theta', 0]],  c = r^2/(2 b) m_c d,  theta' = r/(2b) (omega1 - omega2)
    D = diag(d_m1, d_m2)

Discrete time (as in the paper's source, docs/plants.md#robot-model): forward Euler,
chi(k+1) = chi(k) + T f(chi(k), u(k)), T = 0.01 s. This discrete model *is*
the plant here. Against a fine RK4 solution of the continuous model with the
same held inputs, the pose agrees to 0.05% of its range and the final states
to 2% (omega1, which ends near 0, to 0.006 rad/s); the currents differ most in
the first steps, because T is half the armature time constant L_a/R_a = 19 ms
(i2 up to 25% of its range at the start, 1.4% RMS over the run).

Scenario (paper section 6.2, VERIFIED; docs/plants.md#robot-scenario): T = 0.01 s, 15 s, u1 = sin(c(t)), u2 = cos(c(t))
with c(t) a MATLAB chirp; each state "not updated" for 0.1 s (10 samples)
starting at 13, 9, 5, 8, 6, 1, 4 s for X, Y, theta, omega1, omega2, i1, i2.
PROPOSED: c(t) = sin(2 pi (f0 + (f1 - f0) t / (2 t1)) t) with the Simulink
"Chirp Signal" defaults f0 = 0.1 Hz, f1 = 1 Hz at t1 = 100 s; zero initial
state; no disturbance.

Sources and confidence (docs/plants.md#robot-model): the equations are HIGH
confidence for this model family; J, M, m11, m12, m, I and every parameter
value are VERIFIED in ``examples/robot.py`` of the public GitHub repository
``alfredoaguiararce/rhonn-module-python``; the Coriolis
form C and the actuator equation are the standard Fukao / Das-Kar form
(RECALLED); that [17] uses exactly this form is MEDIUM. Units are the standard
ones (PROPOSED; the source states none).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any, Sequence

import numpy as np

from .trajectory import (
    Corruption,
    HoldWindow,
    Trajectory,
    build_trajectory,
    forward_euler,
    input_samples,
    sample_times,
)
from ..validation import check_array, check_real

__all__ = [
    "ChirpInput",
    "INPUT_NAMES",
    "PAPER_HOLD_DURATION",
    "PAPER_HOLD_STARTS",
    "RobotParams",
    "STATE_NAMES",
    "paper_holds",
    "rhs",
    "simulate",
]

STATE_NAMES = ("X", "Y", "theta", "omega1", "omega2", "i1", "i2")
INPUT_NAMES = ("u1", "u2")
PAPER_HOLD_STARTS = (13.0, 9.0, 5.0, 8.0, 6.0, 1.0, 4.0)  # s, per state, VERIFIED
PAPER_HOLD_DURATION = 0.1  # s, VERIFIED


def paper_holds() -> tuple[HoldWindow, ...]:
    """The paper's seven 0.1 s "not updated" windows, one per state."""
    return tuple(HoldWindow(j, s, PAPER_HOLD_DURATION) for j, s in enumerate(PAPER_HOLD_STARTS))


@dataclass(frozen=True)
class RobotParams:
    """Physical parameters: values VERIFIED in a reference implementation, units PROPOSED.

    Sources and units: docs/plants.md#robot-parameters.

    Validated on construction: every field finite, lengths/masses/inertias of
    the body and the electrical constants > 0, d, m_w, I_w, I_m, d_m1, d_m2 >= 0
    (ValueError naming the field). M is then positive definite.
    Derived with the defaults: m = 32, I = 19.455, m11 = 0.37955,
    m12 = -0.01455, c = 0.135, N K_T = 16.344, N K_E = 1.251.
    """

    b: float = 0.75  #: half the distance between the wheels, m
    d: float = 0.30  #: distance from the axle midpoint to the centre of mass, m
    r: float = 0.15  #: wheel radius, m
    m_c: float = 30.0  #: body mass, kg
    m_w: float = 1.0  #: mass of one wheel with its motor, kg
    I_c: float = 15.625  #: body inertia about the vertical axis, kg m^2
    I_w: float = 0.005  #: wheel inertia about its axle, kg m^2
    I_m: float = 0.0025  #: wheel + motor inertia about a diameter, kg m^2
    R_a: float = 2.5  #: armature resistance, ohm
    L_a: float = 0.048  #: armature inductance, H
    K_E: float = 0.02  #: back-EMF constant, V s/rad
    K_T: float = 0.2613  #: torque constant, N m/A
    N: float = 62.55  #: gear ratio
    d_m1: float = 0.5  #: viscous damping of the right wheel, N m s/rad
    d_m2: float = 0.5  #: viscous damping of the left wheel, N m s/rad

    def __post_init__(self) -> None:
        for f in fields(self):
            nonneg = f.name in ("d", "d_m1", "d_m2", "I_m", "I_w", "m_w")
            v = check_real(f.name, getattr(self, f.name), positive=not nonneg, nonnegative=nonneg)
            object.__setattr__(self, f.name, v)

    @property
    def mass(self) -> float:
        """m = m_c + 2 m_w."""
        return self.m_c + 2.0 * self.m_w

    @property
    def yaw_inertia(self) -> float:
        """I = m_c d^2 + 2 m_w b^2 + I_c + 2 I_m."""
        return self.m_c * self.d ** 2 + 2.0 * self.m_w * self.b ** 2 + self.I_c + 2.0 * self.I_m

    def inertia(self) -> tuple[float, float]:
        """(m11, m12) of M."""
        k = self.r ** 2 / (4.0 * self.b ** 2)
        mb2 = self.mass * self.b ** 2
        return k * (mb2 + self.yaw_inertia) + self.I_w, k * (mb2 - self.yaw_inertia)

    @property
    def coriolis(self) -> float:
        """c = r^2 / (2 b) m_c d."""
        return self.r ** 2 / (2.0 * self.b) * self.m_c * self.d

    def to_dict(self) -> dict[str, Any]:
        return {f.name: getattr(self, f.name) for f in fields(self)}


@dataclass(frozen=True)
class ChirpInput:
    """u1 = amplitude sin(c(t)), u2 = amplitude cos(c(t)), c(t) = sin(2 pi (f0 + (f1 - f0) t / (2 t1)) t).

    c(t) is a linear chirp from f0 Hz at t = 0 reaching f1 Hz at t = t1
    (PROPOSED: the Simulink Chirp Signal defaults 0.1 Hz, 1 Hz, 100 s, so
    c(t) = sin(2 pi (0.1 + 0.0045 t) t)). amplitude = 1 V as in the paper.
    """

    f0: float = 0.1
    f1: float = 1.0
    t1: float = 100.0
    amplitude: float = 1.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "f0", check_real("f0", self.f0, nonnegative=True))
        object.__setattr__(self, "f1", check_real("f1", self.f1, nonnegative=True))
        object.__setattr__(self, "t1", check_real("t1", self.t1, positive=True))
        object.__setattr__(self, "amplitude", check_real("amplitude", self.amplitude))

    def chirp(self, t: np.ndarray) -> np.ndarray:
        return np.sin(2.0 * np.pi * (self.f0 + (self.f1 - self.f0) * t / (2.0 * self.t1)) * t)

    def __call__(self, t: np.ndarray) -> np.ndarray:
        """(T, 2) inputs at the times t (T,)."""
        c = self.chirp(t)
        return self.amplitude * np.column_stack([np.sin(c), np.cos(c)])

    def to_dict(self) -> dict[str, Any]:
        return {"f0": self.f0, "f1": self.f1, "t1": self.t1, "amplitude": self.amplitude}


class _Coefficients:
    """Precomputed scalars for the float-level right-hand side."""

    def __init__(self, p: RobotParams) -> None:
        m11, m12 = p.inertia()
        det = m11 * m11 - m12 * m12
        self.a11, self.a12 = m11 / det, -m12 / det  # M^{-1} = [[a11, a12], [a12, a11]]
        self.half_r = 0.5 * p.r
        self.r_2b = p.r / (2.0 * p.b)
        self.c = p.coriolis
        self.nkt = p.N * p.K_T
        self.nke = p.N * p.K_E
        self.d1, self.d2 = p.d_m1, p.d_m2
        self.R_a, self.inv_La = p.R_a, 1.0 / p.L_a


def _f(k: _Coefficients, x: Sequence[float], u1: float, u2: float) -> tuple[float, ...]:
    _, _, th, w1, w2, i1, i2 = x
    v = k.half_r * (w1 + w2)
    thdot = k.r_2b * (w1 - w2)
    # M w' = N K_T i - C(theta') w - D w,  C w = [c th' w2, -c th' w1]
    g1 = k.nkt * i1 - k.c * thdot * w2 - k.d1 * w1
    g2 = k.nkt * i2 + k.c * thdot * w1 - k.d2 * w2
    return (
        v * math.cos(th),
        v * math.sin(th),
        thdot,
        k.a11 * g1 + k.a12 * g2,
        k.a12 * g1 + k.a11 * g2,
        (u1 - k.R_a * i1 - k.nke * w1) * k.inv_La,
        (u2 - k.R_a * i2 - k.nke * w2) * k.inv_La,
    )


def rhs(x: np.ndarray, u: np.ndarray, params: RobotParams | None = None) -> np.ndarray:
    """The continuous-time vector field f(chi, u), (7,) for x (7,) and u (2,)."""
    p = RobotParams() if params is None else params
    x = check_array("x", x, (7,))
    u = check_array("u", u, (2,))
    return np.array(_f(_Coefficients(p), tuple(x), float(u[0]), float(u[1])))


def simulate(
    params: RobotParams | None = None,
    *,
    dt: float = 0.01,
    horizon: float = 15.0,
    inputs: ChirpInput | np.ndarray | None = None,
    x0: np.ndarray | None = None,
    holds: Sequence[HoldWindow] | None = None,
    corruption: Corruption | None = None,
) -> Trajectory:
    """Example 2: forward-Euler run over ``horizon`` at ``dt``.

    inputs:
        A :class:`ChirpInput` (default: the PROPOSED chirp), or an explicit
        (T, 2) float64 array of u(k) for the T = horizon/dt + 1 samples.
    x0:
        (7,) initial state; zeros by default (PROPOSED).
    holds:
        None for the paper's windows (:func:`paper_holds`); ``()`` for none.
    """
    p = RobotParams() if params is None else params
    if not isinstance(p, RobotParams):
        raise ValueError(f"params: expected RobotParams, got {type(p).__name__}")
    t = sample_times(dt, horizon)
    U, input_meta = input_samples(ChirpInput() if inputs is None else inputs, t, 2, ChirpInput, "chirp")
    x = tuple(check_array("x0", x0, (7,))) if x0 is not None else (0.0,) * 7
    k = _Coefficients(p)
    X = forward_euler(lambda xs, u: _f(k, xs, u[0], u[1]), x, U, dt, "robot")
    meta = {
        "plant": "robot",
        "example": 2,
        "params": p.to_dict(),
        "inputs": input_meta,
        "horizon": float(horizon),
        "discretisation": "forward Euler",
        "sources": "docs/plants.md#robot: model HIGH/MEDIUM, parameters VERIFIED in "
                   "alfredoaguiararce/rhonn-module-python, chirp and zero initial state PROPOSED",
    }
    return build_trajectory(t=t, X=X, U=U, state_names=STATE_NAMES, input_names=INPUT_NAMES, dt=float(dt),
                            holds=paper_holds() if holds is None else holds, corruption=corruption, metadata=meta)
