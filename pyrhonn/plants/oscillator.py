"""Example 1 of the paper: the chaotic delayed oscillator, eq. 15 (system of [20]).

Full description, sources and confidence: docs/plants.md#oscillator.

Continuous-time model (tau = 3 s, u(t) = sin(0.3 t)):

    x1' = x2 + 0.001 x1 u
    x2' = (1 - x1^2) x2 - x1 + x3 u + 2 cos(x1(t - tau))
    x3' = x4 + 0.01 x2 x3 exp(u)
    x4' = (1 - x3^2) x4 - x3 + u / (1 + x2^2 x4^2)
          + 2 (x1(t - tau)^2 + x2(t - tau)^2) sin(x2(t - tau))
    y1 = x1 + x2,   y2 = x3 + x4        (outputs of the HONN observer, not used here)

Sources and confidence (docs/plants.md#oscillator-model): the equations, tau,
x(0) = [1 1 1 1], u(t) and the sampling periods T = 0.2 s and 0.02 s are
VERIFIED in the paper's text. The history before t = 0 (constant, equal to
x(0)) and the horizon are NOT stated: PROPOSED here, and configurable.

Integration: method of steps with classical RK4 at a fixed internal step h
that divides both tau and the sampling period T exactly (default h = 5 ms:
600 steps per delay, 40 per T = 0.2 s, 4 per T = 0.02 s). The whole fine-grid
solution and its derivative are kept as the history buffer. RK4 needs the
delayed state at t_n - tau (a stored grid point), t_n - tau + h/2 (a half
step) and t_n - tau + h (a grid point); the half-step value is the cubic
Hermite interpolant of the stored values and derivatives at the two
neighbouring grid points, x_mid = (x_a + x_b)/2 + h (f_a - f_b)/8, which is
O(h^4) accurate, the same order as RK4. For delayed times <= 0 the constant
history is used exactly. Because tau is a multiple of h, the derivative
discontinuities the delay creates (at t = 0, tau, 2 tau, ...) fall on grid
points, so no RK4 step straddles one.

The samples are the continuous solution at t_k = k T (the "zero-order hold"
of the paper samples the states; Simulink logs x(kT)). The input is also
sampled: U[k] = u(kT); inside the integrator u(t) is evaluated continuously.

Horizon: default 100 s (``DEFAULT_HORIZON``), chosen before any identifier was
run and not tuned. Reasons: (1) the oscillation's envelope grows for roughly
the first 20 s, so 100 s makes the sustained regime, not the start-up, carry
about 80% of the samples; (2) it is ~4.8 periods of u (2 pi / 0.3 = 20.9 s)
and 33 delays; (3) 500 samples at T = 0.2 s and 5000 at T = 0.02 s; (4) the
system is chaotic: differences between two integrator step sizes grow
~25-fold per 100 s, and beyond ~150 s the "true" trajectory at 1e-3
precision starts to depend on numerical details, so longer horizons are less
reproducible. Tables should also be reported at other horizons
(docs/plants.md#oscillator-horizon).

Convergence (checked by the tests and by :func:`convergence_error`): over
100 s, halving h from 5 ms to 2.5 ms changes every sample, at T = 0.2 s and
T = 0.02 s, by less than ``CONVERGENCE_BOUND`` = 5e-5 (measured: about 1.2e-5
at worst, on x4 whose range is about [-10, 12]).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from .trajectory import (
    Corruption,
    HoldWindow,
    Trajectory,
    build_trajectory,
    check_length,
    sample_times,
)
from ..validation import check_array, check_real

__all__ = [
    "CONVERGENCE_BOUND",
    "DEFAULT_HORIZON",
    "DEFAULT_STEP",
    "INPUT_NAMES",
    "OscillatorParams",
    "STATE_NAMES",
    "convergence_error",
    "integrate",
    "rhs",
    "simulate",
]

STATE_NAMES = ("x1", "x2", "x3", "x4")
INPUT_NAMES = ("u",)
DEFAULT_HORIZON = 100.0  # s, PROPOSED (see module docstring)
DEFAULT_STEP = 0.005  # s, internal RK4 step
CONVERGENCE_BOUND = 5e-5  # max |x_h - x_{h/2}| over samples, states, 100 s at h = DEFAULT_STEP
PAPER_PERIODS = (0.2, 0.02)  # s, the two sampling periods of Tables 1-4


@dataclass(frozen=True, eq=False)
class OscillatorParams:
    """Parameters of eq. 15.

    tau:
        The delay in x1(t - tau), x2(t - tau), seconds (paper: 3 s, VERIFIED).
    x0:
        (4,) initial state, also the constant history x(t) = x0 for t <= 0
        (paper: x(0) = [1 1 1 1] VERIFIED; constant history PROPOSED).
    input_frequency:
        omega in u(t) = sin(omega t), rad/s (paper: 0.3, VERIFIED).
    """

    tau: float = 3.0
    x0: np.ndarray = field(default_factory=lambda: np.ones(4))
    input_frequency: float = 0.3

    def __post_init__(self) -> None:
        object.__setattr__(self, "tau", check_real("tau", self.tau, positive=True))
        object.__setattr__(self, "x0", check_array("x0", self.x0, (4,)))
        object.__setattr__(self, "input_frequency", check_real("input_frequency", self.input_frequency))

    def to_dict(self) -> dict[str, Any]:
        return {"tau": self.tau, "x0": self.x0.tolist(), "input_frequency": self.input_frequency}


def _f(t: float, x: Sequence[float], xd: Sequence[float], w: float) -> tuple[float, float, float, float]:
    """eq. 15 on plain floats; xd is the state at t - tau (only xd[0], xd[1] are used)."""
    u = math.sin(w * t)
    x1, x2, x3, x4 = x
    d1, d2 = xd[0], xd[1]
    return (
        x2 + 0.001 * x1 * u,
        (1.0 - x1 * x1) * x2 - x1 + x3 * u + 2.0 * math.cos(d1),
        x4 + 0.01 * x2 * x3 * math.exp(u),
        (1.0 - x3 * x3) * x4 - x3 + u / (1.0 + x2 * x2 * x4 * x4) + 2.0 * (d1 * d1 + d2 * d2) * math.sin(d2),
    )


def rhs(t: float, x: np.ndarray, x_delayed: np.ndarray, params: OscillatorParams | None = None) -> np.ndarray:
    """dx/dt of eq. 15 at time t, given x(t) (4,) and x(t - tau) (4,)."""
    p = OscillatorParams() if params is None else params
    x = check_array("x", x, (4,))
    x_delayed = check_array("x_delayed", x_delayed, (4,))
    return np.array(_f(float(t), tuple(x), tuple(x_delayed), p.input_frequency))


def _steps_in(name: str, length: float, step: float) -> int:
    """length / step as an int; ValueError naming ``step`` unless it divides ``length`` exactly."""
    ratio = length / step
    k = round(ratio)
    if k < 1 or abs(ratio - k) > 1e-9 * max(1.0, ratio):
        raise ValueError(f"step: {step!r} must divide {name} = {length!r} into a whole number of steps")
    return int(k)


def integrate(
    params: OscillatorParams | None = None,
    *,
    horizon: float = DEFAULT_HORIZON,
    step: float = DEFAULT_STEP,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The fine-grid solution on [0, horizon]: ``(t, x, xdot)``.

    t is (S+1,) with t_n = n*step; x is (S+1, 4); xdot[n] is dx/dt at t_n from
    the right (the RK4 stage k1), with xdot[S] evaluated at the end point.
    ``step`` must divide ``tau`` and ``horizon`` exactly, and S + 1 is at most
    :data:`~pyrhonn.plants.trajectory.MAX_SAMPLES` (a ValueError naming
    ``horizon`` before the run otherwise).
    """
    p = OscillatorParams() if params is None else params
    if not isinstance(p, OscillatorParams):
        raise ValueError(f"params: expected OscillatorParams, got {type(p).__name__}")
    h = check_real("step", step, positive=True)
    horizon = check_real("horizon", horizon, positive=True)
    check_length("horizon", horizon, h, "step", "RK4 grid points")  # the history keeps every point
    N = _steps_in("tau", p.tau, h)  # the delay in internal steps
    S = _steps_in("horizon", horizon, h)
    w = p.input_frequency
    hist = tuple(float(v) for v in p.x0)
    xs: list[tuple[float, ...]] = [hist]
    fs: list[tuple[float, ...]] = []
    half, sixth, eighth = 0.5 * h, h / 6.0, h / 8.0
    x = hist
    for n in range(S):
        t = n * h
        m = n - N  # grid index of t - tau
        xd0 = hist if m < 0 else xs[m]
        k1 = _f(t, x, xd0, w)
        fs.append(k1)
        if m + 1 <= 0:  # the whole delayed interval [t_m, t_{m+1}] lies in the history
            xdh = hist
            xd1 = hist if m + 1 < 0 else xs[0]
        else:
            a, b, fa, fb = xs[m], xs[m + 1], fs[m], fs[m + 1]
            xdh = tuple(0.5 * (a[i] + b[i]) + eighth * (fa[i] - fb[i]) for i in range(4))
            xd1 = b
        k2 = _f(t + half, tuple(x[i] + half * k1[i] for i in range(4)), xdh, w)
        k3 = _f(t + half, tuple(x[i] + half * k2[i] for i in range(4)), xdh, w)
        k4 = _f(t + h, tuple(x[i] + h * k3[i] for i in range(4)), xd1, w)
        x = tuple(x[i] + sixth * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]) for i in range(4))
        if not all(math.isfinite(v) for v in x):
            raise FloatingPointError(f"oscillator diverged at t = {t + h:.6g} s")
        xs.append(x)
    m = S - N
    fs.append(_f(S * h, x, hist if m < 0 else xs[m], w))
    t_grid = np.arange(S + 1, dtype=np.float64) * h
    return t_grid, np.array(xs, dtype=np.float64), np.array(fs, dtype=np.float64)


def sample(params: OscillatorParams | None = None, *, dt: float = 0.2, horizon: float = DEFAULT_HORIZON,
           step: float = DEFAULT_STEP) -> tuple[np.ndarray, np.ndarray]:
    """``(t, X)``: the solution at t_k = k*dt, k = 0..horizon/dt. Both the
    samples and the internal RK4 steps (horizon/step) are limited to
    :data:`~pyrhonn.plants.trajectory.MAX_SAMPLES`, checked before any run."""
    t = sample_times(dt, horizon)  # checks dt, horizon and the number of samples
    every = _steps_in("dt", check_real("dt", dt, positive=True), check_real("step", step, positive=True))
    _, x, _ = integrate(params, horizon=horizon, step=step)  # checks the RK4 grid's length first
    return t, x[::every].copy()


def convergence_error(
    params: OscillatorParams | None = None,
    *,
    dt: float = 0.2,
    horizon: float = DEFAULT_HORIZON,
    step: float = DEFAULT_STEP,
) -> np.ndarray:
    """(4,) max over samples of |x_step(kT) - x_{step/2}(kT)| per state.

    The integrator is converged at ``step`` when this is small against the
    state ranges; at the defaults it is below ``CONVERGENCE_BOUND``. As RK4
    is 4th order, the error of the ``step`` run itself is about 16/15 of it.
    """
    _, coarse = sample(params, dt=dt, horizon=horizon, step=step)
    _, fine = sample(params, dt=dt, horizon=horizon, step=step / 2.0)
    return np.max(np.abs(coarse - fine), axis=0)


def simulate(
    params: OscillatorParams | None = None,
    *,
    dt: float = 0.2,
    horizon: float = DEFAULT_HORIZON,
    step: float = DEFAULT_STEP,
    holds: Sequence[HoldWindow] = (),
    corruption: Corruption | None = None,
) -> Trajectory:
    """Example 1 sampled at ``dt`` (the paper: 0.2 s and 0.02 s) over ``horizon``.

    The delay of this example is in the dynamics (tau), so the paper's
    scenario has no hold windows (``holds=()``); holds, noise, quantisation
    and dropouts can be added for robustness studies.
    """
    p = OscillatorParams() if params is None else params
    t, X = sample(p, dt=dt, horizon=horizon, step=step)
    U = np.sin(p.input_frequency * t)[:, None]
    meta = {
        "plant": "oscillator",
        "example": 1,
        "equation": "eq. 15",
        "params": p.to_dict(),
        "horizon": float(horizon),
        "integrator": {"method": "RK4, method of steps, cubic Hermite half-step history", "step": float(step)},
        "sources": "docs/plants.md#oscillator: eq. 15, tau, x(0), u, T VERIFIED; constant history and "
                   "horizon PROPOSED",
    }
    return build_trajectory(t=t, X=X, U=U, state_names=STATE_NAMES, input_names=INPUT_NAMES, dt=float(dt),
                            holds=holds, corruption=corruption, metadata=meta)
