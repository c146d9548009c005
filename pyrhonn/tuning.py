"""Searching the identifier's tuning (P0, Q, R, eta, beta) on held-out data: ``pyrhonn tune``.

:func:`tune` searches the EKF tuning of eq. 7-8 (P_i(0), Q_i, R_i, eta_i)
and the activation slope beta_i of a base :class:`~pyrhonn.config.IdentifierConfig`
with optuna's TPE sampler, keeping the base config's terms, activations, w0
and x0. :func:`held_out_score` is the objective it minimises, usable on its own.

The objective (exactly)
-----------------------
A trajectory of T samples (``X`` (T, n), ``U`` (T, m), ``valid`` (T, n)) is
split at N = floor(train_fraction * T): samples 0..N-1 are the *training
part*, N..T-1 the *held-out part*. A candidate config runs through the whole
trajectory in one :meth:`~pyrhonn.Identifier.run`, that is, it learns online
through the training part and keeps learning through the held-out part, as
it does when used online (no weights are frozen, nothing is refitted). Row k
of the run is x̂(k+1), computed from samples 0..k only.

Every held-out sample k = N..T-1 is a *target*. Its one-step-ahead prediction
x̂(k) (row k-1 of the run) was made before x(k) was seen. With y the reference
(``truth`` when given, else the measurements ``X``) and K_j the targets of
state j that are scored (all held-out targets when ``truth`` is given; else
those with ``valid[k, j]`` True), per state j:

    RMSE_j = sqrt( mean_{k in K_j} (y_kj - x̂_kj)^2 )
    s_j    = std_{k in K_j} y_kj        (population std, ddof = 0; 1 where it is 0)

    objective = (1/n) * sum_j RMSE_j / s_j                      (minimised)

the mean over states of the held-out one-step-ahead RMSE in units of the
state's standard deviation over its held-out targets, so that states of
different magnitudes weigh the same (0 is perfect; predicting each state by
its held-out mean would score 1). The RMSE is :func:`pyrhonn.metrics.rmse`.

A trial *fails* when the C core refuses its config (``ValueError`` at
construction, e.g. a P0 that float32 cannot hold), when the run stops
(:class:`~pyrhonn.IdentifierError`: covariance no longer positive definite,
covariance overflow, weights that would stop being finite) or when the
held-out error is not finite (predictions so large that their squares
overflow) or, for some state, exceeds :data:`DIVERGED` = 1000 times s_j
(predictions a thousand standard deviations off: the identifier diverged;
predicting the held-out mean scores 1). A failed trial is recorded as PRUNED in the study, with the reason
in its user attribute ``failure``; it is never chosen, TPE learns to avoid its
region, and the search goes on.

The search space
----------------
``params`` (default all of :data:`PARAMETERS`) are searched log-uniformly.
Each searched value is a scalar: P0 and Q become ``value * I`` (as in the
paper's eq. 20), replacing any diagonal or matrix of the base config; a
parameter that is not searched keeps the base config's value (arrays too).
Values are rounded to 3 significant digits *before* they are evaluated, so
the written config holds short numbers and scores exactly what the study
recorded.

- ``per_neuron=False`` (shared): one value per parameter for every neuron
  (optuna parameters ``p0``, ``q``, ...).
- ``per_neuron=True``: one value per parameter and neuron (``neurons[i].p0``).

Default ranges are factors of the base value b (:data:`DEFAULT_FACTORS`):
P0 and Q in [b/1e4, b*1e4], R in [b/1e3, b*1e3], eta in [b/100, 2b], beta in
[b/10, 10b]. (For eta = 1, the up-to-2 bound is where one EKF step stops
shrinking the error of the sample it learns from: the a-posteriori error is
(1 - eta g) e with 0 < g = z^T P z / (R + z^T P z) < 1, so |1 - eta g| < 1
for every g only when eta <= 2.) For a shared parameter the range spans every neuron's range. A
P0 or Q array counts by the geometric mean of its (positive) diagonal; a Q
of zero counts as 1e-3 times the neuron's P0 (the paper's ratio Q/P0 is
5e-3), so its range is [P0*1e-7, P0*10]. ``ranges`` replaces a default by an
absolute ``(low, high)`` with 0 < low < high, for every neuron.

Scaling P0, Q and R by one common factor leaves every prediction unchanged
(the gain K_i = P_i H_i / (R_i + H_i^T P_i H_i) is invariant and P_i scales),
so (P0, Q, R) has one redundant direction; all three are searched by default,
as the paper-example targets ask, and ``params=("p0", "q", "eta", "beta")`` removes the
redundancy (R stays at its base value).

When every searched parameter's base value is a scalar inside its range
(so with the default ranges unless the base has a P0 or Q array or Q = 0;
true for the shipped ``example1``), the base config is the first trial of a new study, so the best trial is
never worse than the base. Whatever happens, :attr:`TuneResult.config` is
the base config itself when no trial beats it.

The sampler is ``optuna.samplers.TPESampler(seed=seed, multivariate=True,
n_startup_trials=10, constant_liar=n_jobs > 1)``.

Study file (resuming)
---------------------
``study_path`` keeps the study in a file, so a later call with the same path
adds trials to it (the trial count continues; ``n_trials`` is the number of
*new* trials). The storage follows the suffix:

- ``.log`` (recommended): optuna's ``JournalStorage`` with a
  ``JournalFileBackend``, an append-only JSON-lines file locked with
  ``JournalFileOpenLock``; no database needed.
- ``.db``, ``.sqlite``, ``.sqlite3``: SQLite through optuna's
  ``RDBStorage("sqlite:///<path>")`` (SQLAlchemy comes with optuna), for
  tools that read optuna's SQL schema (``optuna-dashboard``, SQL clients).
  Each trial costs several committed transactions: on this machine 60
  per-neuron trials of Example 1 (T = 0.2 s) took 14.5 s with SQLite, 1.8 s
  with the journal file and 0.8 s in memory, so for short trajectories the
  journal file is the better choice.

The study is named :data:`STUDY_NAME` and records the tuning setup (a hash of
the base config and of the data, the train fraction and the search space) in
its user attributes; resuming with a different setup is refused with a
``ValueError`` naming what differs (trials of different problems cannot be
compared). A file that is not a readable study raises ``ValueError``. On
resuming, the sampler's seed is ``seed + number of trials already in the
study``, so the random start-up trials are not repeated.

Parallel trials
---------------
``n_jobs`` > 1 runs trials in that many threads (optuna's ``n_jobs``); the C
core releases the GIL while it runs, so long trajectories run in parallel.
With ``n_jobs = 1`` a seed reproduces the search exactly; with more, the
order in which trials finish, and so the search, depends on timing.
"""
from __future__ import annotations

import hashlib
import json
import math
import threading
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from . import metrics
from .config import IdentifierConfig, NeuronConfig
from .identifier import Identifier, IdentifierError
from .validation import check_int, check_real, fail

__all__ = [
    "DEFAULT_FACTORS",
    "DEFAULT_TRAIN_FRACTION",
    "DIVERGED",
    "Dimension",
    "PARAMETERS",
    "STUDY_NAME",
    "STUDY_SUFFIXES",
    "Score",
    "Split",
    "TrialCounts",
    "TuneResult",
    "apply_values",
    "held_out_score",
    "search_space",
    "split_point",
    "tune",
]

PARAMETERS = ("p0", "q", "r", "eta", "beta")
"""The tunable fields of :class:`~pyrhonn.config.NeuronConfig`, in search order."""

DEFAULT_FACTORS: dict[str, tuple[float, float]] = {
    "p0": (1e-4, 1e4),
    "q": (1e-4, 1e4),
    "r": (1e-3, 1e3),
    "eta": (1e-2, 2.0),
    "beta": (1e-1, 1e1),
}
"""Default search range of each parameter, as (low, high) factors of its base value."""

Q_OVER_P0 = 1e-3
"""A Q of zero is centred at this fraction of the neuron's P0 (see the module docs)."""

DIVERGED = 1e3
"""A trial whose RMSE_j / s_j exceeds this for some state has diverged (it fails)."""

DEFAULT_TRAIN_FRACTION = 0.6
STUDY_NAME = "pyrhonn-tune"
STUDY_SUFFIXES = {".db": "sqlite", ".sqlite": "sqlite", ".sqlite3": "sqlite", ".log": "journal"}
SIGNIFICANT_DIGITS = 3
_SETUP_ATTR = "pyrhonn_setup"

Progress = Callable[[str], None]


class TrialFailure(Exception):
    """A candidate config that cannot be scored (the identifier stopped or diverged)."""


# -- data and the objective ---------------------------------------------------------------------------


def split_point(n_samples: int, train_fraction: float) -> int:
    """N = floor(train_fraction * n_samples): samples 0..N-1 train, N..T-1 are held out.

    ``train_fraction`` must be in (0, 1) and leave at least one training
    sample and two held-out samples; ``ValueError`` otherwise.
    """
    T = check_int("n_samples", n_samples, 1)
    f = check_real("train_fraction", train_fraction)
    if not 0.0 < f < 1.0:
        raise fail("train_fraction", f"must be between 0 and 1 (exclusive), got {f!r}")
    N = int(math.floor(f * T))
    if N < 1:
        raise fail("train_fraction", f"{f!r} of {T} samples leaves no training sample")
    if T - N < 2:
        raise fail("train_fraction", f"{f!r} of {T} samples leaves {T - N} held-out sample(s); at least 2 "
                                     "are needed to score")
    return N


@dataclass(frozen=True)
class Split:
    """How a trajectory was split: ``n_samples`` T, ``n_train`` N, and per
    state the number of held-out targets scored."""

    n_samples: int
    n_train: int
    scored: tuple[int, ...]

    @property
    def n_held_out(self) -> int:
        return self.n_samples - self.n_train

    def to_dict(self) -> dict[str, Any]:
        return {"n_samples": self.n_samples, "n_train": self.n_train, "n_held_out": self.n_held_out,
                "train": [0, self.n_train - 1], "held_out": [self.n_train, self.n_samples - 1],
                "scored_targets": list(self.scored)}


@dataclass(frozen=True, eq=False)
class Score:
    """The held-out score of one config: ``value`` (the objective), and per
    state ``rmse``, ``scale`` (s_j) and ``normalised`` (RMSE_j / s_j)."""

    value: float
    rmse: np.ndarray
    scale: np.ndarray
    normalised: np.ndarray

    def to_dict(self) -> dict[str, Any]:
        return {"objective": self.value, "rmse": self.rmse.tolist(), "scale": self.scale.tolist(),
                "normalised_rmse": self.normalised.tolist()}


def _check_trajectory(config: IdentifierConfig, X: object, U: object, valid: object,
                      truth: object) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
    n, m = config.n_states, config.n_inputs
    if not isinstance(X, np.ndarray) or X.dtype != np.float64 or X.ndim != 2:
        got = f"{X.dtype} array of shape {X.shape}" if isinstance(X, np.ndarray) else type(X).__name__
        raise fail("X", f"expected a float64 array of shape (T, {n}), got {got}")
    T = X.shape[0]
    if X.shape != (T, n):
        raise fail("X", f"expected shape ({T}, {n}) (the config has {n} states), got {X.shape}")
    if T < 3:
        raise fail("X", f"needs at least 3 samples to train and score, got {T}")
    if not isinstance(U, np.ndarray) or U.dtype != np.float64 or U.shape != (T, m):
        got = f"{U.dtype} array of shape {U.shape}" if isinstance(U, np.ndarray) else type(U).__name__
        raise fail("U", f"expected a float64 array of shape ({T}, {m}), got {got}")
    if not np.all(np.isfinite(U)):
        k, j = (int(i) for i in np.argwhere(~np.isfinite(U))[0])
        raise fail(f"U[{k}, {j}]", "must be finite")
    if valid is None:
        valid = np.ones((T, n), dtype=bool)
    elif not isinstance(valid, np.ndarray) or valid.dtype != np.bool_ or valid.shape != (T, n):
        got = f"{valid.dtype} array of shape {valid.shape}" if isinstance(valid, np.ndarray) \
            else type(valid).__name__
        raise fail("valid", f"expected None or a bool array of shape ({T}, {n}), got {got}")
    bad = ~np.isfinite(X) & valid
    if np.any(bad):
        k, j = (int(i) for i in np.argwhere(bad)[0])
        raise fail(f"X[{k}, {j}]", "must be finite where valid is True")
    if truth is not None:
        if not isinstance(truth, np.ndarray) or truth.dtype != np.float64 or truth.shape != (T, n):
            got = f"{truth.dtype} array of shape {truth.shape}" if isinstance(truth, np.ndarray) \
                else type(truth).__name__
            raise fail("truth", f"expected None or a float64 array of shape ({T}, {n}), got {got}")
        if not np.all(np.isfinite(truth)):
            k, j = (int(i) for i in np.argwhere(~np.isfinite(truth))[0])
            raise fail(f"truth[{k}, {j}]", "must be finite")
    return X, U, valid, truth


class _Problem:
    """A trajectory prepared for scoring configs of one dtype (thread-safe: read only)."""

    def __init__(self, config: IdentifierConfig, X: np.ndarray, U: np.ndarray, valid: np.ndarray | None,
                 truth: np.ndarray | None, train_fraction: float) -> None:
        X, U, valid_mask, truth = _check_trajectory(config, X, U, valid, truth)
        T, n = X.shape
        self.n_train = split_point(T, train_fraction)
        self.train_fraction = float(train_fraction)
        self.dtype = config.dtype
        self.n_states = n
        N = self.n_train
        # The run's precision is the config's dtype; converting to it is the documented step.
        with np.errstate(over="ignore", invalid="ignore"):
            Xr = np.ascontiguousarray(X.astype(self.dtype))
            Ur = np.ascontiguousarray(U.astype(self.dtype))
        for name, a, r, mask in (("X", X, Xr, valid_mask), ("U", U, Ur, np.ones(U.shape, dtype=bool))):
            over = ~np.isfinite(r) & np.isfinite(a) & mask
            if np.any(over):
                k, j = (int(i) for i in np.argwhere(over)[0])
                raise fail(f"{name}[{k}, {j}]", f"{float(a[k, j])!r} overflows {self.dtype}")
        self.X, self.U = Xr, Ur
        self.valid = None if valid is None else np.ascontiguousarray(valid_mask)
        reference = X if truth is None else truth
        self.targets = reference[N:]
        self.mask = valid_mask[N:] if truth is None else np.ones((T - N, n), dtype=bool)
        scored = self.mask.sum(axis=0)
        for j in range(n):
            if scored[j] < 2:
                raise fail("valid", f"state {j} has {int(scored[j])} valid held-out sample(s) (samples {N}.."
                                    f"{T - 1}); at least 2 are needed to score it (lower train_fraction?)")
        self.scale = np.empty(n)
        for j in range(n):
            y = self.targets[self.mask[:, j], j]
            s = float(np.std(y))
            self.scale[j] = s if s > 0.0 else 1.0
        self.split = Split(int(T), int(N), tuple(int(c) for c in scored))
        digest = hashlib.sha256()
        for a in (np.where(valid_mask, X, 0.0), U, valid_mask, X if truth is None else truth):
            a = np.where(np.isfinite(a), a, 0.0) if a.dtype == np.float64 else a  # NaN payloads vary
            digest.update(np.ascontiguousarray(a).tobytes())
            digest.update(repr(a.shape).encode())
        digest.update(b"truth" if truth is not None else b"measured")
        self.data_hash = digest.hexdigest()

    def score(self, config: IdentifierConfig) -> Score:
        """The objective of ``config``; :class:`TrialFailure` when it cannot be scored."""
        if config.dtype != self.dtype:
            raise fail("config.dtype", f"{config.dtype!r} differs from the problem's {self.dtype!r}")
        try:
            ident = Identifier(config)
        except ValueError as exc:
            raise TrialFailure(f"config rejected: {exc}") from None
        try:
            rows = ident.run(self.X, self.U, self.valid)
        except IdentifierError as exc:
            raise TrialFailure(f"identifier stopped: {exc}") from None
        N = self.n_train
        est = rows[N - 1:-1].astype(np.float64)
        n = self.n_states
        rmse = np.empty(n)
        with np.errstate(over="ignore", invalid="ignore"):
            for j in range(n):
                mask = self.mask[:, j]
                e = est[mask, j]
                if not np.all(np.isfinite(e)):
                    raise TrialFailure(f"state {j}: held-out predictions are not finite")
                rmse[j] = metrics.rmse(self.targets[mask, j][:, None], e[:, None])[0]
        if not np.all(np.isfinite(rmse)):
            j = int(np.argmin(np.isfinite(rmse)))
            raise TrialFailure(f"state {j}: held-out error overflows (the identifier diverged)")
        normalised = rmse / self.scale
        if np.any(normalised > DIVERGED):
            j = int(np.argmax(normalised))
            raise TrialFailure(f"state {j}: held-out RMSE is {normalised[j]:.3g} times the state's std "
                               f"(> {DIVERGED:g}: the identifier diverged)")
        return Score(float(np.mean(normalised)), rmse, self.scale.copy(), normalised)


def held_out_score(config: IdentifierConfig, X: np.ndarray, U: np.ndarray, valid: np.ndarray | None = None,
                   *, truth: np.ndarray | None = None,
                   train_fraction: float = DEFAULT_TRAIN_FRACTION) -> Score:
    """The objective of :func:`tune` for one config (see the module docs).

    ``X`` (T, n) and ``U`` (T, m) are float64 (converted to the config's
    dtype to run, with an error if a value overflows it); ``valid`` is None
    or bool (T, n), and X may be NaN where it is False; ``truth`` (T, n), if
    given, is the reference scored at every held-out target. Raises
    ``ValueError`` for bad arguments and when the config cannot be scored
    (the identifier stopped or diverged).
    """
    if not isinstance(config, IdentifierConfig):
        raise fail("config", f"expected an IdentifierConfig, got {type(config).__name__}")
    problem = _Problem(config, X, U, valid, truth, train_fraction)
    try:
        return problem.score(config)
    except TrialFailure as exc:
        raise ValueError(f"config: cannot be scored: {exc}") from None


# -- the search space ---------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Dimension:
    """One searched value: optuna parameter ``name``, the config field
    ``param`` it sets in ``neurons``, its log-uniform range and the base
    value (None when the base config has no single scalar value in range)."""

    name: str
    param: str
    neurons: tuple[int, ...]
    low: float
    high: float
    base: float | None

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "param": self.param, "neurons": list(self.neurons), "low": self.low,
                "high": self.high, "base": self.base}


def _geomean(values: np.ndarray) -> float:
    return float(np.exp(np.mean(np.log(values))))


def _center(neuron: NeuronConfig, param: str) -> tuple[float, float | None]:
    """``(centre of the default range, scalar base value or None)`` of one neuron's parameter."""
    if param == "p0":
        if isinstance(neuron.p0, np.ndarray):
            return _geomean(np.diag(neuron.p0_matrix())), None
        return float(neuron.p0), float(neuron.p0)
    if param == "q":
        q = neuron.q
        if isinstance(q, np.ndarray):
            positive = q[q > 0]
            if positive.size:
                return _geomean(positive), None
            return _center(neuron, "p0")[0] * Q_OVER_P0, None
        if q > 0:
            return float(q), float(q)
        return _center(neuron, "p0")[0] * Q_OVER_P0, None
    value = float(getattr(neuron, param))
    return value, value


def _round(value: float) -> float:
    return float(f"{value:.{SIGNIFICANT_DIGITS - 1}e}")


def _check_ranges(ranges: Mapping[str, Any] | None) -> dict[str, tuple[float, float]]:
    if ranges is None:
        return {}
    if not isinstance(ranges, Mapping):
        raise fail("ranges", f"expected a mapping of parameter -> (low, high), got {type(ranges).__name__}")
    out: dict[str, tuple[float, float]] = {}
    for key, value in ranges.items():
        if key not in PARAMETERS:
            raise fail("ranges", f"unknown parameter {key!r}; expected one of {', '.join(PARAMETERS)}")
        if not isinstance(value, tuple) or len(value) != 2:
            raise fail(f"ranges[{key!r}]", f"expected a tuple (low, high), got {value!r}")
        low = check_real(f"ranges[{key!r}].low", value[0], positive=True)
        high = check_real(f"ranges[{key!r}].high", value[1], positive=True)
        if not low < high:
            raise fail(f"ranges[{key!r}]", f"low must be < high, got ({low!r}, {high!r})")
        out[key] = (low, high)
    return out


def _check_params(params: Sequence[str]) -> tuple[str, ...]:
    if isinstance(params, str) or not isinstance(params, (tuple, list)):
        raise fail("params", f"expected a tuple of parameter names, got {type(params).__name__}")
    if not params:
        raise fail("params", f"expected at least one of {', '.join(PARAMETERS)}")
    for p in params:
        if p not in PARAMETERS:
            raise fail("params", f"unknown parameter {p!r}; expected some of {', '.join(PARAMETERS)}")
    if len(set(params)) != len(params):
        raise fail("params", f"duplicate entries in {list(params)}")
    return tuple(p for p in PARAMETERS if p in params)


def search_space(config: IdentifierConfig, *, params: Sequence[str] = PARAMETERS, per_neuron: bool = False,
                 ranges: Mapping[str, tuple[float, float]] | None = None) -> tuple[Dimension, ...]:
    """The dimensions :func:`tune` searches for ``config`` (see the module docs)."""
    if not isinstance(config, IdentifierConfig):
        raise fail("config", f"expected an IdentifierConfig, got {type(config).__name__}")
    if not isinstance(per_neuron, bool):
        raise fail("per_neuron", f"expected a bool, got {type(per_neuron).__name__}")
    chosen = _check_params(params)
    fixed = _check_ranges(ranges)
    dims: list[Dimension] = []
    for param in chosen:
        lo_f, hi_f = DEFAULT_FACTORS[param]
        centres = [_center(nr, param) for nr in config.neurons]
        groups = [(f"neurons[{i}].{param}", (i,)) for i in range(config.n_states)] if per_neuron \
            else [(param, tuple(range(config.n_states)))]
        for name, members in groups:
            cs = [centres[i][0] for i in members]
            bases = {centres[i][1] for i in members}
            low, high = fixed.get(param, (min(cs) * lo_f, max(cs) * hi_f))
            base = bases.pop() if len(bases) == 1 else None
            if base is not None and not low <= base <= high:
                base = None
            dims.append(Dimension(name, param, members, float(low), float(high), base))
    return tuple(dims)


def apply_values(config: IdentifierConfig, space: Sequence[Dimension], values: Mapping[str, float]) -> IdentifierConfig:
    """``config`` with every dimension of ``space`` set to ``values[name]``
    rounded to 3 significant digits (the config :func:`tune` evaluates)."""
    changes: list[dict[str, float]] = [{} for _ in config.neurons]
    for dim in space:
        if dim.name not in values:
            raise fail("values", f"missing {dim.name!r}")
        v = _round(check_real(f"values[{dim.name!r}]", values[dim.name], positive=True))
        for i in dim.neurons:
            changes[i][dim.param] = v
    neurons = tuple(replace(nr, **ch) if ch else nr for nr, ch in zip(config.neurons, changes))
    return config.replace(neurons=neurons)


# -- the study ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class TrialCounts:
    """Trials in the study by state: scored (COMPLETE), failed (PRUNED:
    the identifier stopped or diverged), errored (FAIL: interrupted or an
    unexpected error) and still RUNNING (e.g. left by a killed run)."""

    total: int
    complete: int
    failed: int
    errored: int
    running: int

    def to_dict(self) -> dict[str, int]:
        return {"total": self.total, "complete": self.complete, "failed": self.failed, "errored": self.errored,
                "running": self.running}


@dataclass(frozen=True, eq=False)
class TuneResult:
    """What :func:`tune` found.

    ``config`` is the best config: the best scored trial's, or the base
    config itself when no trial beat it (``improved`` False, ``best_trial``
    None). ``base`` is the base config's held-out score (None, with
    ``base_failure`` the reason, when it cannot be scored) and ``best`` the
    score of ``config`` (None only if neither could be scored).
    ``best_values`` are the searched values of ``config`` by dimension name
    (for the base config: those it has as scalars). ``top`` lists the five
    best scored trials of the study; ``counts`` counts every trial of the
    study, including those of earlier runs of a resumed study.
    """

    config: IdentifierConfig
    base: Score | None
    base_failure: str | None
    best: Score | None
    best_trial: int | None
    best_values: dict[str, float]
    improved: bool
    new_trials: int
    counts: TrialCounts
    split: Split
    space: tuple[Dimension, ...]
    per_neuron: bool
    train_fraction: float
    seed: int
    study_name: str
    storage: str | None
    top: tuple[dict[str, Any], ...] = field(default=())

    def summary(self) -> dict[str, Any]:
        """A JSON-serialisable summary of the study and the result."""
        return {
            "objective": "mean over states of held-out one-step-ahead RMSE / std of the held-out targets "
                         "(pyrhonn.tuning)",
            "split": self.split.to_dict(),
            "train_fraction": self.train_fraction,
            "per_neuron": self.per_neuron,
            "space": [d.to_dict() for d in self.space],
            "seed": self.seed,
            "study_name": self.study_name,
            "storage": self.storage,
            "new_trials": self.new_trials,
            "trials": self.counts.to_dict(),
            "base": None if self.base is None else self.base.to_dict(),
            "base_failure": self.base_failure,
            "best": None if self.best is None else self.best.to_dict(),
            "best_trial": self.best_trial,
            "best_values": dict(self.best_values),
            "improved": self.improved,
            "top_trials": [dict(t) for t in self.top],
        }


def _storage_kind(path: Path) -> str:
    kind = STUDY_SUFFIXES.get(path.suffix.lower())
    if kind is None:
        raise fail("study_path", f"{str(path)!r}: unknown study file type {path.suffix!r}; use .db (SQLite) "
                                 "or .log (optuna journal file)")
    return kind


def check_study_path(path: str | Path) -> Path:
    """The study file path, checked before any work: a known suffix, an
    existing folder, not a folder itself. Returns it as a Path."""
    if not isinstance(path, (str, Path)) or not str(path):
        raise fail("study_path", f"expected a file path, got {path!r}")
    p = Path(path)
    _storage_kind(p)
    if p.is_dir():
        raise fail("study_path", f"{str(p)!r} is a directory")
    parent = p.parent if str(p.parent) else Path(".")
    if not parent.is_dir():
        raise fail("study_path", f"{str(p)!r}: folder {str(parent)!r} does not exist")
    return p


def _open_storage(path: Path) -> Any:
    import optuna

    kind = _storage_kind(path)
    try:
        if kind == "sqlite":
            return optuna.storages.RDBStorage(f"sqlite:///{path.resolve()}",
                                              engine_kwargs={"connect_args": {"timeout": 60}})
        try:
            from optuna.storages.journal import JournalFileBackend, JournalFileOpenLock
        except ImportError:  # optuna 3.x names (not tested here: this environment has optuna 5)
            from optuna.storages import JournalFileOpenLock  # type: ignore[attr-defined,no-redef]
            from optuna.storages import JournalFileStorage as JournalFileBackend  # type: ignore[no-redef]

        backend = JournalFileBackend(str(path), lock_obj=JournalFileOpenLock(str(path)))
        return optuna.storages.JournalStorage(backend)
    except Exception as exc:  # SQLAlchemy, JSON and optuna errors alike: the file is not a usable study
        raise _unreadable(path, exc) from None


def _unreadable(path: Path, exc: BaseException) -> ValueError:
    reason = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
    return fail("study_path", f"{str(path)!r} is not a readable optuna study file ({reason})")


def _sha(obj: Any) -> str:
    return hashlib.sha256(json.dumps(obj, sort_keys=True).encode()).hexdigest()


def _setup(config: IdentifierConfig, problem: _Problem, space: Sequence[Dimension], per_neuron: bool) -> dict[str, Any]:
    return {
        "format": "pyrhonn-tune",
        "version": 1,
        "config_sha256": _sha(config.to_dict()),
        "data_sha256": problem.data_hash,
        "n_samples": problem.split.n_samples,
        "train_fraction": problem.train_fraction,
        "per_neuron": per_neuron,
        "space": [d.to_dict() for d in space],
    }


_SETUP_WHAT = {
    "format": "study format",
    "version": "study format version",
    "config_sha256": "base config (terms, tuning, dtype)",
    "data_sha256": "data",
    "n_samples": "number of samples",
    "train_fraction": "train fraction",
    "per_neuron": "shared / per-neuron search",
    "space": "search space (parameters or ranges)",
}


def _check_setup(path: str, stored: Any, setup: dict[str, Any]) -> None:
    if not isinstance(stored, dict):
        raise fail("study_path", f"{path!r} holds a study {STUDY_NAME!r} that pyrhonn tune did not create")
    differ = [_SETUP_WHAT[k] for k in setup if stored.get(k) != setup[k]]
    if differ:
        raise fail("study_path", f"{path!r} was made for a different tuning problem ({', '.join(differ)} "
                                 "differ); use a new study file, or the same config, data and options")


def _counts(study: Any) -> TrialCounts:
    from optuna.trial import TrialState

    trials = study.get_trials(deepcopy=False)
    states = [t.state for t in trials]
    return TrialCounts(total=len(trials), complete=states.count(TrialState.COMPLETE),
                       failed=states.count(TrialState.PRUNED), errored=states.count(TrialState.FAIL),
                       running=states.count(TrialState.RUNNING) + states.count(TrialState.WAITING))


def tune(
    config: IdentifierConfig,
    X: np.ndarray,
    U: np.ndarray,
    valid: np.ndarray | None = None,
    *,
    truth: np.ndarray | None = None,
    train_fraction: float = DEFAULT_TRAIN_FRACTION,
    n_trials: int = 50,
    n_jobs: int = 1,
    seed: int = 0,
    per_neuron: bool = False,
    params: Sequence[str] = PARAMETERS,
    ranges: Mapping[str, tuple[float, float]] | None = None,
    study_path: str | Path | None = None,
    n_startup_trials: int = 10,
    progress: Progress | None = None,
) -> TuneResult:
    """Search P0, Q, R, eta and beta of ``config`` on ``(X, U, valid)``.

    The objective, the search space, failed trials, the study file and
    parallel trials are described in the module docs. ``X``, ``U``,
    ``valid`` and ``truth`` are as for :func:`held_out_score`; the runs use
    ``config.dtype``. ``n_trials`` new trials are run (>= 1), ``n_jobs``
    threads at a time; ``progress``, if given, receives one line per
    finished trial. Bad arguments raise ``ValueError`` naming them, before
    any trial runs; a failing trial never raises.
    """
    if not isinstance(config, IdentifierConfig):
        raise fail("config", f"expected an IdentifierConfig, got {type(config).__name__}")
    n_trials = check_int("n_trials", n_trials, 1)
    n_jobs = check_int("n_jobs", n_jobs, 1)
    seed = check_int("seed", seed, 0, 2**32 - 1)
    n_startup_trials = check_int("n_startup_trials", n_startup_trials, 0)
    if progress is not None and not callable(progress):
        raise fail("progress", "expected a callable or None")
    space = search_space(config, params=params, per_neuron=per_neuron, ranges=ranges)
    problem = _Problem(config, X, U, valid, truth, train_fraction)
    path = None if study_path is None else check_study_path(study_path)

    base: Score | None
    base_failure: str | None = None
    try:
        base = problem.score(config)
    except TrialFailure as exc:
        base, base_failure = None, str(exc)

    import optuna
    from optuna.trial import TrialState

    storage = None if path is None else _open_storage(path)
    setup = _setup(config, problem, space, per_neuron)
    try:
        study = optuna.create_study(study_name=STUDY_NAME, storage=storage, direction="minimize",
                                    load_if_exists=True)
        existing = study.get_trials(deepcopy=False)
        stored = study.user_attrs.get(_SETUP_ATTR)
    except Exception as exc:
        raise _unreadable(path if path is not None else Path("<memory>"), exc) from None
    enqueued = False
    if existing or stored is not None:
        _check_setup(str(path), stored, setup)
    else:
        study.set_user_attr(_SETUP_ATTR, setup)
        if all(d.base is not None for d in space):
            study.enqueue_trial({d.name: d.base for d in space}, user_attrs={"base": True})
            enqueued = True
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", optuna.exceptions.ExperimentalWarning)
        study.sampler = optuna.samplers.TPESampler(seed=(seed + len(existing)) % 2**32, multivariate=True,
                                                   n_startup_trials=n_startup_trials,
                                                   constant_liar=n_jobs > 1)

    def objective(trial: Any) -> float:
        values = {d.name: trial.suggest_float(d.name, d.low, d.high, log=True) for d in space}
        candidate = apply_values(config, space, values)
        try:
            score = problem.score(candidate)
        except TrialFailure as exc:
            trial.set_user_attr("failure", str(exc))
            raise optuna.TrialPruned(str(exc)) from None
        trial.set_user_attr("rmse", score.rmse.tolist())
        trial.set_user_attr("normalised_rmse", score.normalised.tolist())
        return score.value

    lock = threading.Lock()
    done = [0]

    def report(study_: Any, trial: Any) -> None:
        if progress is None:
            return
        with lock:
            done[0] += 1
            k = done[0]
        if trial.state == TrialState.COMPLETE:
            what = f"score {trial.value:.6g}"
        elif trial.state == TrialState.PRUNED:
            what = f"failed ({trial.user_attrs.get('failure', 'pruned')})"
        else:
            what = trial.state.name.lower()
        try:
            best = f"best {study_.best_value:.6g} (trial {study_.best_trial.number})"
        except ValueError:
            best = "no scored trial yet"
        progress(f"trial {trial.number} [{k}/{n_trials}]: {what}; {best}")

    # The enqueued base trial runs alone first: with RDBStorage (SQLite) and n_jobs > 1, two threads
    # can pop the same waiting trial, which then runs twice or fails with "Cannot tell a COMPLETE
    # trial" (optuna issue #4002, reproduced with optuna 5.0 here).
    first = 1 if enqueued else 0
    try:
        if first:
            study.optimize(objective, n_trials=1, n_jobs=1, callbacks=[report], gc_after_trial=False)
        if n_trials > first:
            study.optimize(objective, n_trials=n_trials - first, n_jobs=n_jobs, callbacks=[report],
                           gc_after_trial=False)
    except json.JSONDecodeError as exc:  # a journal cut short (an interrupted write) read back mid-run
        raise _unreadable(path if path is not None else Path("<memory>"), exc) from None

    complete = [t for t in study.get_trials(deepcopy=False, states=(TrialState.COMPLETE,))]
    best_score: Score | None = None
    best_trial: int | None = None
    best_config = config
    best_values: dict[str, float] = {}
    if complete:
        winner = min(complete, key=lambda t: (t.value, t.number))
        candidate = apply_values(config, space, winner.params)
        try:
            score = problem.score(candidate)
        except TrialFailure:  # pragma: no cover - the C core is deterministic
            score = None
        if score is not None and (base is None or score.value < base.value):
            best_score, best_trial, best_config = score, winner.number, candidate
            best_values = {d.name: _round(winner.params[d.name]) for d in space}
    improved = best_score is not None
    if not improved:
        best_score = base
        best_values = {d.name: d.base for d in space if d.base is not None}
    top = tuple({"trial": t.number, "objective": t.value,
                 "values": {d.name: _round(t.params[d.name]) for d in space}}
                for t in sorted(complete, key=lambda t: (t.value, t.number))[:5])
    return TuneResult(
        config=best_config, base=base, base_failure=base_failure, best=best_score, best_trial=best_trial,
        best_values=best_values, improved=improved, new_trials=n_trials, counts=_counts(study),
        split=problem.split, space=space, per_neuron=per_neuron, train_fraction=problem.train_fraction,
        seed=seed, study_name=STUDY_NAME, storage=None if path is None else str(path), top=top,
    )
