"""Sampled trajectories and the measurement model shared by every plant.

A plant simulator produces the *true* sampled states ``X`` (what the paper's
tables compare against) and the *measured* states ``X_meas`` (what the
identifier is fed). The two differ only through the measurement model in this
module, which is the one place where sensor effects are applied
(docs/plants.md#measurement-model):

1. **Additive Gaussian noise**, per-state standard deviation (``Corruption.noise_std``).
2. **Encoder-style quantisation** of chosen states, per-state resolution
   (``Corruption.resolution``; 0 means "not quantised").
3. **Random dropouts**: each (sample, state) pair independently lost with a
   given probability (``Corruption.dropout``).
4. **Hold windows** (:class:`HoldWindow`): state j "is not updated" from
   ``start`` for ``duration`` seconds. These are the paper's delays in
   Examples 2 and 3 ("information is not updated for 0.1 s").

Order of operations (fixed, see :func:`measure`): reading = quantise(X + noise);
then a sample is *invalid* if it is dropped or inside a hold window; an invalid
sample shows the last valid reading of that state (sample-and-hold), or NaN
when there is no earlier valid reading (only possible when sample 0 itself is
invalid; the C core ignores invalid entries and accepts NaN there).

Randomness: one ``numpy.random.SeedSequence(seed)`` is split into two
independent child streams, one for noise and one for dropouts. So for a fixed
seed the noise realisation does not change when dropouts are switched on or
off, and vice versa; the same seed always gives the same trajectory.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from ..validation import check_array, check_int, check_real, fail

__all__ = ["MAX_SAMPLES", "Corruption", "HoldWindow", "Trajectory", "check_length", "measure",
           "sample_times"]

QUANTISERS = ("floor", "round")

#: The most points a simulated run may have: the samples of a plant's run
#: (:func:`sample_times`) and the steps of the oscillator's internal RK4 grid.
#: Why this number: it covers the longest run any documented entry asks for,
#: a ``pyrhonn hil`` scenario with start and duration at their 3600 s maximum
#: at the rig's 0.3 ms period (7200 s: 24,000,001 samples; ``hil trajectory``
#: at 3600 s and 0.3 ms: 12,000,001), and bounds the memory of one run: a
#: simulation holds about 300 bytes per sample (measured: LIM 280, robot 320;
#: the oscillator's RK4 history about 520 per step), so this is some 7.5 GB
#: (13 GB for the oscillator's grid) at most. Beyond it a run would take hours
#: of pure-Python stepping and exhaust memory, so it is refused up front with a
#: message naming the horizon, instead of a numpy MemoryError part way.
MAX_SAMPLES = 25_000_000


def check_multiple(path: str, value: float, unit: float, unit_name: str) -> int:
    """``value / unit`` as an int, if it is an integer to 1e-9 relative; else ValueError."""
    ratio = value / unit
    k = round(ratio)
    if k < 1 or abs(ratio - k) > 1e-9 * max(1.0, abs(ratio)):
        raise fail(path, f"{value!r} must be a positive integer multiple of {unit_name} = {unit!r}")
    return int(k)


def _short(x: float) -> str:
    """``x`` in a few digits, exponents without padding: 1e9, 2.5e7, 0.0001."""
    return re.sub(r"e([+-])0*(\d)", lambda m: f"e{'-' if m.group(1) == '-' else ''}{m.group(2)}", f"{x:.4g}")


def check_length(path: str, length: float, step: float, step_name: str = "dt", what: str = "samples") -> None:
    """ValueError naming ``path`` when ``length`` seconds at ``step`` seconds make
    more than :data:`MAX_SAMPLES` points (``length / step + 1``, both ends
    included); checked before anything of that size is allocated.
    ``length`` and ``step`` are finite and > 0 (already validated)."""
    count = length / step + 1.0  # inf for a huge length over a tiny step: refused as well
    if not count <= MAX_SAMPLES:
        raise fail(path, f"{_short(length)} s at {step_name} {_short(step)} s is {_short(count)} {what} "
                         f"(limit {_short(MAX_SAMPLES)}); shorten {path} or lengthen {step_name}")


def sample_times(dt: float, horizon: float) -> np.ndarray:
    """t_k = k*dt for k = 0..K with K = horizon/dt (which must be an integer).

    Both ends are included, as a Simulink log of a fixed-step run from 0 to
    ``horizon`` would: K + 1 samples, at most :data:`MAX_SAMPLES` (checked
    before anything is allocated).
    """
    dt = check_real("dt", dt, positive=True)
    horizon = check_real("horizon", horizon, positive=True)
    check_length("horizon", horizon, dt)
    K = check_multiple("horizon", horizon, dt, "dt")
    return np.arange(K + 1, dtype=np.float64) * dt

#: relative part (of dt) of the tolerance on the sample times' uniformity
UNIFORM_RTOL = 1e-9
#: ulps of the largest |t| allowed on top (float64 rounding of t itself)
UNIFORM_ULPS = 4.0


def uniform_time_error(t: np.ndarray, dt: float) -> int | None:
    """The index of the first sample time that is not t[0] + k*dt, or None.

    The tolerance is ``UNIFORM_RTOL * dt`` plus ``UNIFORM_ULPS`` ulps of the
    largest |t|: float64 rounds t = k*dt to a few 1e-13 s at t ~ 2000 s,
    which is more than any fixed fraction of a 0.3 ms step, so a tolerance
    on dt alone refuses the sample times of every long run. Against the grid
    (not step by step), so a drift of the spacing is caught however slow.
    """
    k = np.arange(t.shape[0], dtype=np.float64)
    grid = t[0] + k * dt
    scale = max(float(np.max(np.abs(t))), float(np.max(np.abs(grid))))
    tol = UNIFORM_RTOL * dt + UNIFORM_ULPS * float(np.spacing(scale))
    bad = ~(np.abs(t - grid) <= tol)  # NaN counts as off
    return int(np.argmax(bad)) if bad.any() else None


def input_samples(inputs: object, t: np.ndarray, width: int, source: type, kind: str) -> tuple[np.ndarray, dict[str, Any]]:
    """The (T, width) inputs of a run: ``inputs`` is an input generator of
    type ``source`` (called on the sample times ``t``) or an explicit float64
    array of exactly that shape; returns U and a description for metadata."""
    T = t.shape[0]
    if isinstance(inputs, source):
        return inputs(t), {"kind": kind, **inputs.to_dict()}  # type: ignore[operator, attr-defined]
    if isinstance(inputs, np.ndarray):
        if inputs.dtype != np.float64 or inputs.shape != (T, width):
            raise fail("inputs", f"expected a float64 array of shape ({T}, {width}), got {inputs.dtype} {inputs.shape}")
        if not np.all(np.isfinite(inputs)):
            raise fail("inputs", "must be finite")
        return inputs.copy(), {"kind": "array"}
    raise fail("inputs", f"expected a {source.__name__} or a numpy array, got {type(inputs).__name__}")


def forward_euler(f: Callable[[tuple[float, ...], list[float]], tuple[float, ...]], x0: tuple[float, ...],
                  U: np.ndarray, dt: float, plant: str) -> np.ndarray:
    """x(k+1) = x(k) + dt f(x(k), u(k)) from x(0) = x0 over the rows of U:
    the (T, n) states. Plain floats in the loop (this is the hot path of a
    simulation); a non-finite state raises FloatingPointError."""
    n = len(x0)
    X = np.empty((U.shape[0], n))
    X[0] = x0
    x = x0
    h = float(dt)
    rows = U.tolist()
    for k in range(U.shape[0] - 1):
        d = f(x, rows[k])
        x = tuple(x[i] + h * d[i] for i in range(n))
        X[k + 1] = x
    if not np.all(np.isfinite(X)):
        raise FloatingPointError(f"{plant} simulation diverged; reduce dt")
    return X



@dataclass(frozen=True)
class HoldWindow:
    """State ``state`` (0-based) is not updated for ``duration`` seconds from ``start``.

    Every sample with ``start <= t_k < start + duration`` (to a tolerance of
    1e-6*dt, so that 2.1 s at dt = 1e-4 is sample 21000 despite rounding) is
    invalid and shows the last valid reading before it. A 0.1 s window at
    dt = 0.01 therefore covers exactly 10 samples. A window that extends past
    the end of the trajectory is clipped (the paper's robot windows at 13 s
    simply vanish in a 10 s run).
    """

    state: int
    start: float
    duration: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "state", check_int("state", self.state, 0))
        object.__setattr__(self, "start", check_real("start", self.start, nonnegative=True))
        object.__setattr__(self, "duration", check_real("duration", self.duration, positive=True))

    def mask(self, t: np.ndarray, dt: float) -> np.ndarray:
        """Boolean (T,) mask of the samples this window covers."""
        tol = 1e-6 * dt
        return (t >= self.start - tol) & (t < self.start + self.duration - tol)

    def to_dict(self) -> dict[str, Any]:
        return {"state": self.state, "start": self.start, "duration": self.duration}


@dataclass(frozen=True, eq=False)
class Corruption:
    """Sensor imperfections beyond the paper's scenarios; all off by default.

    Parameters
    ----------
    noise_std:
        (n,) standard deviation of additive zero-mean Gaussian noise per
        state, >= 0, in the state's units; None for no noise.
    resolution:
        (n,) quantisation step per state, >= 0 (0 = that state is not
        quantised); None for no quantisation. Models an encoder or ADC.
    quantiser:
        ``"floor"`` (default): reading = res * floor(value / res), the count
        of whole increments passed, as an incremental encoder reports; the
        error lies in (-res, 0]. ``"round"``: nearest level, error in
        [-res/2, res/2].
    dropout:
        Probability in [0, 1) that a given sample of a given state is lost
        (scalar for all states, or an (n,) array). A lost sample is invalid
        and shows the last valid reading.
    seed:
        Seed of the numpy Generator streams (noise and dropouts are
        independent children of ``SeedSequence(seed)``).
    """

    noise_std: np.ndarray | None = None
    resolution: np.ndarray | None = None
    quantiser: str = "floor"
    dropout: float | np.ndarray = 0.0
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("noise_std", "resolution"):
            v = getattr(self, name)
            if v is None:
                continue
            if not isinstance(v, np.ndarray) or v.ndim != 1:
                raise fail(name, f"expected a 1-D numpy array (one entry per state) or None, got {v!r}")
            arr = check_array(name, v, (v.shape[0],))
            if np.any(arr < 0):
                raise fail(f"{name}[{int(np.argmax(arr < 0))}]", "must be >= 0")
            object.__setattr__(self, name, arr)
        if self.quantiser not in QUANTISERS:
            raise fail("quantiser", f"expected one of {QUANTISERS}, got {self.quantiser!r}")
        if isinstance(self.dropout, np.ndarray):
            if self.dropout.ndim != 1:
                raise fail("dropout", f"expected a scalar or a 1-D array, got shape {self.dropout.shape}")
            p = check_array("dropout", self.dropout, (self.dropout.shape[0],))
            bad = (p < 0) | (p >= 1)
            if np.any(bad):
                raise fail(f"dropout[{int(np.argmax(bad))}]", "must be in [0, 1)")
            object.__setattr__(self, "dropout", p)
        else:
            p0 = check_real("dropout", self.dropout)
            if not 0.0 <= p0 < 1.0:
                raise fail("dropout", f"must be in [0, 1), got {p0!r}")
            object.__setattr__(self, "dropout", p0)
        object.__setattr__(self, "seed", check_int("seed", self.seed, 0))

    @classmethod
    def by_name(
        cls,
        state_names: Sequence[str],
        *,
        noise_std: Mapping[str, float] | None = None,
        resolution: Mapping[str, float] | None = None,
        quantiser: str = "floor",
        dropout: float | Mapping[str, float] = 0.0,
        seed: int = 0,
    ) -> Corruption:
        """Build from per-state mappings keyed by state name; unnamed states get 0.

        ``Corruption.by_name(lim.STATE_NAMES, resolution={"q_m": 5e-6})``
        """
        names = list(state_names)

        def vec(field_name: str, mapping: Mapping[str, float] | None) -> np.ndarray | None:
            if mapping is None:
                return None
            out = np.zeros(len(names))
            for key, value in mapping.items():
                if key not in names:
                    raise fail(field_name, f"unknown state {key!r}; states are {names}")
                out[names.index(key)] = check_real(f"{field_name}[{key!r}]", value)
            return out

        drop: float | np.ndarray = dropout if not isinstance(dropout, Mapping) else vec("dropout", dropout)  # type: ignore[assignment]
        return cls(noise_std=vec("noise_std", noise_std), resolution=vec("resolution", resolution),
                   quantiser=quantiser, dropout=drop, seed=seed)

    def check_states(self, n: int) -> None:
        """ValueError unless every per-state array has n entries."""
        for name in ("noise_std", "resolution", "dropout"):
            v = getattr(self, name)
            if isinstance(v, np.ndarray) and v.shape != (n,):
                raise fail(f"corruption.{name}", f"expected shape ({n},) for {n} states, got {v.shape}")

    def to_dict(self) -> dict[str, Any]:
        def arr(v: Any) -> Any:
            return v.tolist() if isinstance(v, np.ndarray) else v

        return {"noise_std": arr(self.noise_std), "resolution": arr(self.resolution),
                "quantiser": self.quantiser, "dropout": arr(self.dropout), "seed": self.seed}


def measure(
    t: np.ndarray,
    X: np.ndarray,
    *,
    dt: float,
    holds: Sequence[HoldWindow] = (),
    corruption: Corruption | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """What the identifier sees: ``(X_meas, valid)``, both (T, n).

    Steps, in this order:

    1. reading = X + noise (noise drawn for the whole (T, n) array from the
       noise stream, so a state's noise does not depend on other states' std);
    2. reading = quantise(reading) for states with resolution > 0;
    3. valid = not dropped (dropout stream) and not inside any hold window;
    4. X_meas[k, j] = reading[k', j] with k' the last valid sample <= k of
       state j (so X_meas equals the reading where valid); NaN if none.
    """
    if not isinstance(t, np.ndarray) or t.ndim != 1 or t.dtype != np.float64:
        raise fail("t", "expected a float64 numpy array of shape (T,)")
    if not isinstance(X, np.ndarray) or X.dtype != np.float64 or X.ndim != 2 or X.shape[0] != t.shape[0]:
        raise fail("X", f"expected a float64 numpy array of shape ({t.shape[0]}, n)")
    dt = check_real("dt", dt, positive=True)
    T, n = X.shape
    reading = X.copy()
    valid = np.ones((T, n), dtype=bool)
    if corruption is not None:
        if not isinstance(corruption, Corruption):
            raise fail("corruption", f"expected a Corruption or None, got {type(corruption).__name__}")
        corruption.check_states(n)
        noise_seq, drop_seq = np.random.SeedSequence(corruption.seed).spawn(2)
        if corruption.noise_std is not None:
            reading += np.random.default_rng(noise_seq).standard_normal((T, n)) * corruption.noise_std
        if corruption.resolution is not None:
            res = corruption.resolution
            q = res > 0
            levels = reading[:, q] / res[q]
            levels = np.floor(levels) if corruption.quantiser == "floor" else np.round(levels)
            reading[:, q] = levels * res[q]
        p = corruption.dropout
        if isinstance(p, np.ndarray) or p > 0.0:
            valid &= np.random.default_rng(drop_seq).random((T, n)) >= p
    if not isinstance(holds, (tuple, list)):
        raise fail("holds", f"expected a sequence of HoldWindow, got {type(holds).__name__}")
    for h, window in enumerate(holds):
        if not isinstance(window, HoldWindow):
            raise fail(f"holds[{h}]", f"expected a HoldWindow, got {type(window).__name__}")
        if window.state >= n:
            raise fail(f"holds[{h}].state", f"state index {window.state} out of range 0..{n - 1}")
        valid[window.mask(t, dt), window.state] = False
    # sample-and-hold: index of the last valid sample at or before k, per state
    idx = np.where(valid, np.arange(T)[:, None], -1)
    np.maximum.accumulate(idx, axis=0, out=idx)
    X_meas = np.take_along_axis(reading, np.maximum(idx, 0), axis=0)
    X_meas[idx < 0] = np.nan
    return X_meas, valid


@dataclass(frozen=True, eq=False)
class Trajectory:
    """A sampled run of a plant.

    Attributes
    ----------
    t:
        (T,) sample times t_k = k*dt, float64.
    X:
        (T, n) true states x(t_k) (the reference for metrics).
    U:
        (T, m) inputs u(t_k); u(k) acts on the step from k to k+1.
    valid:
        (T, n) bool, False where a state's measurement is not updated (hold
        window or dropout).
    X_meas:
        (T, n) what the identifier sees: the (noisy, quantised) reading where
        valid, the held last valid reading where not (NaN if none yet).
    state_names, input_names:
        n and m names.
    dt:
        Sampling period T in seconds.
    metadata:
        Plant name, parameters, scenario, measurement model and sources.

    Arrays must already have exactly these shapes and dtypes (float64, bool);
    nothing is converted.
    """

    t: np.ndarray
    X: np.ndarray
    U: np.ndarray
    valid: np.ndarray
    X_meas: np.ndarray
    state_names: tuple[str, ...]
    input_names: tuple[str, ...]
    dt: float
    metadata: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        check_real("dt", self.dt, positive=True)
        if not isinstance(self.t, np.ndarray) or self.t.dtype != np.float64 or self.t.ndim != 1:
            raise fail("t", "expected a float64 numpy array of shape (T,)")
        T = self.t.shape[0]
        if T < 1:
            raise fail("t", "needs at least one sample")
        if T > 1:
            off = uniform_time_error(self.t, self.dt)
            if off is not None:
                raise fail("t", f"samples must be uniformly spaced by dt = {self.dt!r} (t[{off}] = "
                                f"{float(self.t[off])!r} is off t[0] + {off} dt)")
        if not isinstance(self.state_names, tuple) or not all(isinstance(s, str) for s in self.state_names):
            raise fail("state_names", "expected a tuple of str")
        if not isinstance(self.input_names, tuple) or not all(isinstance(s, str) for s in self.input_names):
            raise fail("input_names", "expected a tuple of str")
        n, m = len(self.state_names), len(self.input_names)
        for name, shape, dtype in (("X", (T, n), np.float64), ("U", (T, m), np.float64),
                                   ("X_meas", (T, n), np.float64), ("valid", (T, n), np.bool_)):
            a = getattr(self, name)
            if not isinstance(a, np.ndarray) or a.dtype != dtype or a.shape != shape:
                got = f"{a.dtype} {a.shape}" if isinstance(a, np.ndarray) else type(a).__name__
                raise fail(name, f"expected a {np.dtype(dtype).name} array of shape {shape}, got {got}")
        for name in ("X", "U"):
            a = getattr(self, name)
            if not np.all(np.isfinite(a)):
                k, j = (int(i) for i in np.argwhere(~np.isfinite(a))[0])
                raise fail(f"{name}[{k}, {j}]", "must be finite")
        bad = ~np.isfinite(self.X_meas) & self.valid
        if np.any(bad):
            k, j = (int(i) for i in np.argwhere(bad)[0])
            raise fail(f"X_meas[{k}, {j}]", "must be finite where valid is True")
        if not isinstance(self.metadata, dict):
            raise fail("metadata", f"expected a dict, got {type(self.metadata).__name__}")

    @property
    def n_samples(self) -> int:
        return int(self.t.shape[0])

    @property
    def n_states(self) -> int:
        return len(self.state_names)

    @property
    def n_inputs(self) -> int:
        return len(self.input_names)

    def state(self, name: str) -> np.ndarray:
        """The true samples of one state, by name."""
        if name not in self.state_names:
            raise fail("name", f"unknown state {name!r}; states are {list(self.state_names)}")
        return self.X[:, self.state_names.index(name)]

    def remeasure(self, *, holds: Sequence[HoldWindow] = (), corruption: Corruption | None = None) -> Trajectory:
        """The same true run seen through another measurement model (no re-simulation)."""
        X_meas, valid = measure(self.t, self.X, dt=self.dt, holds=holds, corruption=corruption)
        meta = dict(self.metadata)
        meta["holds"] = [h.to_dict() for h in holds]
        meta["corruption"] = None if corruption is None else corruption.to_dict()
        return Trajectory(t=self.t, X=self.X, U=self.U, valid=valid, X_meas=X_meas,
                          state_names=self.state_names, input_names=self.input_names,
                          dt=self.dt, metadata=meta)


def build_trajectory(
    *,
    t: np.ndarray,
    X: np.ndarray,
    U: np.ndarray,
    state_names: tuple[str, ...],
    input_names: tuple[str, ...],
    dt: float,
    holds: Sequence[HoldWindow],
    corruption: Corruption | None,
    metadata: dict[str, Any],
) -> Trajectory:
    """Apply the measurement model and assemble a :class:`Trajectory` (used by every plant)."""
    holds = tuple(holds)
    X_meas, valid = measure(t, X, dt=dt, holds=holds, corruption=corruption)
    meta = dict(metadata)
    meta["holds"] = [h.to_dict() for h in holds]
    meta["corruption"] = None if corruption is None else corruption.to_dict()
    return Trajectory(t=t, X=X, U=U, valid=valid, X_meas=X_meas, state_names=state_names,
                      input_names=input_names, dt=dt, metadata=meta)
