"""Example 3 of the paper: the linear induction motor (LIM), alpha-beta model of [11].

Full description, sources and confidence: docs/plants.md#lim (the 0.3 ms
real-time rig: docs/plants.md#lim-rig).

States x = [q_m, v, lambda_a, lambda_b, i_a, i_b]: position (m), velocity
(m/s), secondary fluxes (Wb, secondary/moving frame), primary currents (A,
primary/fixed frame). Inputs u = [u_a, u_b], primary voltages (V).
rho1 = sin(n_p q_m), rho2 = cos(n_p q_m).

Continuous-time model (docs/plants.md#lim-model, DERIVED from the induction-machine
equations; the k_i names RECALLED from the Sanchez/Loukianov/Alanis papers):

    q_m' = v
    v'   = k1 [(rho2 la - rho1 lb) ib - (rho1 la + rho2 lb) ia] - k2 v - k3 F_L
    la'  = -k6 la + k5 (rho2 ia + rho1 ib)
    lb'  = -k6 lb + k5 (rho2 ib - rho1 ia)
    ia'  = k9 ia + k8 (rho2 la - rho1 lb) + k7 v (rho1 la + rho2 lb) - k10 ua
    ib'  = k9 ib + k8 (rho1 la + rho2 lb) - k7 v (rho2 la - rho1 lb) - k10 ub

    k1 = n_p L_sr / (D_m L_r)    k2 = R_m / D_m      k3 = 1 / D_m
    k5 = R_r L_sr / L_r          k6 = R_r / L_r      k7 = n_p L_sr / (L_s L_r - L_sr^2)
    k8 = L_sr R_r / (L_r (L_s L_r - L_sr^2))
    k9 = (L_r^2 R_s + L_sr^2 R_r) / (L_r (L_sr^2 - L_s L_r))  (< 0)
    k10 = L_r / (L_sr^2 - L_s L_r)                            (< 0)

Discrete time: forward Euler at T, x(k+1) = x(k) + T f(x(k), u(k)), the form the
papers print (structure MEDIUM-HIGH confidence, docs/plants.md#lim-model).

Parameters: the Lab-Volt 8228 table was NOT FOUND, so every value in
:class:`LimParams` is PROPOSED (docs/plants.md#lim-parameters) and configurable.

Inputs (eq. 21-22). The OCR text prints, for t >= 2 s,
``u_a = 255(170 cos(0.3t(98.6/6 t - 98.6/3)))`` and the same with sin for u_b,
and 0 before 2 s. Interpretation used here (docs/plants.md#lim-inputs):
u_a = A cos(phi(t)), u_b = A sin(phi(t)), phi(t) = 0.3 t (98.6 t / 6 - 98.6 / 3),
a chirp with phi(2) = 0 and instantaneous frequency 9.86 (t - 1) rad/s, so the
input switches on at 2 s with u_a = A, u_b = 0. A = 170 V (the peak of 120 V
rms); the "255" factor is read as a DAC/PWM scaling or typesetting artifact and
dropped (PROPOSED, confidence LOW; set ``LimInput(amplitude=255 * 170)`` to
take it literally). The chirp constants are VERIFIED in the text.

Scenario: T = 1e-4 s (VERIFIED; real time 3e-4 s), horizon 5 s, zero initial
state, F_L = 0 (PROPOSED). The position measurement is not updated for 1 s
from 2.1 s (10 000 samples at 1e-4; docs/plants.md#lim-scenario). The paper's sentence
("it is not possible to update the information of the LIM states starting at
2.1 s") can also be read as all states; ``paper_holds(all_states=True)`` gives
that reading. In the real-time test the delay starts at 1.1 s.
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
    "INPUT_NAMES",
    "LimConstants",
    "LimInput",
    "LimParams",
    "STATE_NAMES",
    "paper_holds",
    "rhs",
    "simulate",
]

STATE_NAMES = ("q_m", "v", "lambda_a", "lambda_b", "i_a", "i_b")
INPUT_NAMES = ("u_a", "u_b")


def paper_holds(start: float = 2.1, duration: float = 1.0, *, all_states: bool = False) -> tuple[HoldWindow, ...]:
    """The paper's delay: the position (or, with ``all_states``, every state)
    not updated for ``duration`` from ``start`` (simulation: 2.1 s; real time: 1.1 s)."""
    states = range(len(STATE_NAMES)) if all_states else (0,)
    return tuple(HoldWindow(j, start, duration) for j in states)


@dataclass(frozen=True)
class LimConstants:
    """The k_i of the model (k4 = n_p L_sr is defined in the papers but unused)."""

    k1: float
    k2: float
    k3: float
    k5: float
    k6: float
    k7: float
    k8: float
    k9: float
    k10: float


@dataclass(frozen=True)
class LimParams:
    """LIM parameters. ALL PROPOSED (docs/plants.md#lim-parameters): the Lab-Volt 8228 table was not found.

    R_s, R_r, L_s, L_r, L_sr are an unverified recollection of a small-LIM set
    from the LIM-control literature (F.-J. Lin et al.); D_m, R_m are chosen for
    a small educational carriage; n_p acts as pi / tau_p (rad/m) with a pole
    pitch tau_p of about 45.6 mm; F_L is an unknown external load, 0 here.
    """

    R_s: float = 5.3685  #: primary winding resistance per phase, ohm
    R_r: float = 3.5315  #: secondary resistance per phase, ohm
    L_s: float = 0.0403  #: primary inductance per phase, H
    L_r: float = 0.0403  #: secondary inductance per phase, H
    L_sr: float = 0.0373  #: magnetising inductance per phase, H
    D_m: float = 2.8  #: moving (primary) mass, kg
    R_m: float = 5.0  #: viscous friction coefficient, N s/m
    n_p: float = 69.0  #: "pole pairs" in rho = sin(n_p q_m), rad/m
    F_L: float = 0.0  #: load force, N

    def __post_init__(self) -> None:
        for f in fields(self):
            kind = {"R_m": "nonneg", "F_L": "any"}.get(f.name, "pos")
            v = check_real(f.name, getattr(self, f.name), positive=kind == "pos", nonnegative=kind == "nonneg")
            object.__setattr__(self, f.name, v)
        if not self.L_sr ** 2 < self.L_s * self.L_r:
            raise ValueError(f"L_sr: must satisfy L_sr^2 < L_s L_r (positive leakage), got L_sr = {self.L_sr!r} "
                             f"with L_s L_r = {self.L_s * self.L_r!r}")

    def constants(self) -> LimConstants:
        sigma = self.L_s * self.L_r - self.L_sr ** 2  # > 0
        return LimConstants(
            k1=self.n_p * self.L_sr / (self.D_m * self.L_r),
            k2=self.R_m / self.D_m,
            k3=1.0 / self.D_m,
            k5=self.R_r * self.L_sr / self.L_r,
            k6=self.R_r / self.L_r,
            k7=self.n_p * self.L_sr / sigma,
            k8=self.L_sr * self.R_r / (self.L_r * sigma),
            k9=-(self.L_r ** 2 * self.R_s + self.L_sr ** 2 * self.R_r) / (self.L_r * sigma),
            k10=-self.L_r / sigma,
        )

    def to_dict(self) -> dict[str, Any]:
        return {f.name: getattr(self, f.name) for f in fields(self)}


@dataclass(frozen=True)
class LimInput:
    """Eq. 21-22 as interpreted in the module docstring.

    u = 0 for t < start; u_a = A cos(phi), u_b = A sin(phi) for t >= start,
    phi(t) = gain * t * (slope * t - offset). Defaults: A = 170 V (PROPOSED),
    start = 2 s, gain = 0.3, slope = 98.6/6, offset = 98.6/3 (VERIFIED).
    """

    amplitude: float = 170.0
    start: float = 2.0
    gain: float = 0.3
    slope: float = 98.6 / 6.0
    offset: float = 98.6 / 3.0

    def __post_init__(self) -> None:
        for f in fields(self):
            v = check_real(f.name, getattr(self, f.name), nonnegative=f.name == "start")
            object.__setattr__(self, f.name, v)

    def phase(self, t: np.ndarray) -> np.ndarray:
        return self.gain * t * (self.slope * t - self.offset)

    def __call__(self, t: np.ndarray) -> np.ndarray:
        """(T, 2) inputs at the times t (T,)."""
        on = t >= self.start - 1e-9
        phi = self.phase(t)
        return np.column_stack([np.where(on, self.amplitude * np.cos(phi), 0.0),
                                np.where(on, self.amplitude * np.sin(phi), 0.0)])

    def to_dict(self) -> dict[str, Any]:
        return {f.name: getattr(self, f.name) for f in fields(self)}


def _f(k: LimConstants, n_p: float, F_L: float, x: Sequence[float], ua: float, ub: float) -> tuple[float, ...]:
    q, v, la, lb, ia, ib = x
    r1, r2 = math.sin(n_p * q), math.cos(n_p * q)
    a = r2 * la - r1 * lb  # flux rotated into the primary frame, alpha part
    b = r1 * la + r2 * lb  # beta part
    return (
        v,
        k.k1 * (a * ib - b * ia) - k.k2 * v - k.k3 * F_L,
        -k.k6 * la + k.k5 * (r2 * ia + r1 * ib),
        -k.k6 * lb + k.k5 * (r2 * ib - r1 * ia),
        k.k9 * ia + k.k8 * a + k.k7 * v * b - k.k10 * ua,
        k.k9 * ib + k.k8 * b - k.k7 * v * a - k.k10 * ub,
    )


def rhs(x: np.ndarray, u: np.ndarray, params: LimParams | None = None) -> np.ndarray:
    """The continuous-time vector field f(x, u), (6,) for x (6,) and u (2,)."""
    p = LimParams() if params is None else params
    x = check_array("x", x, (6,))
    u = check_array("u", u, (2,))
    return np.array(_f(p.constants(), p.n_p, p.F_L, tuple(x), float(u[0]), float(u[1])))


def simulate(
    params: LimParams | None = None,
    *,
    dt: float = 1e-4,
    horizon: float = 5.0,
    inputs: LimInput | np.ndarray | None = None,
    x0: np.ndarray | None = None,
    holds: Sequence[HoldWindow] | None = None,
    corruption: Corruption | None = None,
) -> Trajectory:
    """Example 3: forward-Euler run over ``horizon`` (PROPOSED 5 s) at ``dt``.

    inputs:
        A :class:`LimInput` (default: eq. 21-22 with A = 170 V), or an explicit
        (T, 2) float64 array of u(k) for the T = horizon/dt + 1 samples.
    x0:
        (6,) initial state; zeros by default (PROPOSED).
    holds:
        None for the paper's delay (:func:`paper_holds`: position, 1 s from
        2.1 s); ``()`` for none.
    """
    p = LimParams() if params is None else params
    if not isinstance(p, LimParams):
        raise ValueError(f"params: expected LimParams, got {type(p).__name__}")
    t = sample_times(dt, horizon)
    U, input_meta = input_samples(LimInput() if inputs is None else inputs, t, 2, LimInput, "eq. 21-22")
    x = tuple(check_array("x0", x0, (6,))) if x0 is not None else (0.0,) * 6
    k = p.constants()
    X = forward_euler(lambda xs, u: _f(k, p.n_p, p.F_L, xs, u[0], u[1]), x, U, dt, "LIM")
    meta = {
        "plant": "lim",
        "example": 3,
        "params": p.to_dict(),
        "constants": {f.name: getattr(k, f.name) for f in fields(k)},
        "inputs": input_meta,
        "horizon": float(horizon),
        "discretisation": "forward Euler",
        "sources": "docs/plants.md#lim: structure MEDIUM-HIGH, all parameters PROPOSED, "
                   "A = 170 V PROPOSED (LOW), horizon 5 s / zero initial state / F_L = 0 PROPOSED",
    }
    return build_trajectory(t=t, X=X, U=U, state_names=STATE_NAMES, input_names=INPUT_NAMES, dt=float(dt),
                            holds=paper_holds() if holds is None else holds, corruption=corruption, metadata=meta)
