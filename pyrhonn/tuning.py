"""Searching the identifier's tuning (P0, Q, R, eta, beta) on held-out data: ``pyrhonn tune``.

:func:`tune` searches the EKF tuning of eq. 7-8 (P_i(0), Q_i, R_i, eta_i)
and the activation slope beta_i of a base :class:`~pyrhonn.config.IdentifierConfig`
with optuna's TPE sampler, keeping the base config's terms, activations
and x0; with ``structure=`` it searches the terms too, through the selection
settings of :mod:`pyrhonn.structure` (see Structure search). A trial that
changes a neuron's beta starts from w0 refitted for its own S: least squares
on the training samples (those of the first fold, so that no fold's held-out
block fits a weight; :func:`pyrhonn.regressors.refit_w0`); a neuron whose
beta is unchanged keeps its w0.
:func:`held_out_score` is the objective it minimises, usable on its own.

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

Blocked cross-validation (``folds`` = K > 1)
---------------------------------------------
The held-out part N..T-1 is cut into K contiguous blocks (:func:`fold_bounds`:
b_f = N + floor(f (T - N) / K)). Fold f (1..K) *trains* on samples 0..N_f-1
(N_f = b_{f-1}) and *scores* samples N_f..E_f-1 (E_f = b_f): the candidate
runs from sample 0, learning online through the training part and through
its block, and the objective above is computed on the block's targets alone
(RMSE_fj / s_fj, s_fj the std of the block's targets). A trial scores the
mean over folds and states. No fold sees a sample after its block: this is
forward-chaining (rolling-origin) validation, as the identifier runs online.
Without structure search every fold's run is a prefix of the same run, so one
run serves all folds; with it each fold runs the selection made on its own
training part. K = 1 is the single split. Each fold needs two valid targets
per state.

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

The free-run guard (``free_run_guard``, on by default)
--------------------------------------------------------
The objective scores one step ahead, and a tuning that predicts one step
better can simulate worse. After the search, the best trial and the base
config are run free over the held-out part (learning online up to the split,
then the weights frozen and the network fed its own predictions:
:meth:`_Problem.free_run_score`, the mean over states of the free-run RRSE).
Where the base's free run is informative (mean RRSE below 1) and the best
trial's is worse by more than :data:`FREE_RUN_TOLERANCE`, the base config is
kept and :attr:`TuneResult.kept_base` says why.

When every searched parameter's base value is a scalar inside its range
(so with the default ranges unless the base has a P0 or Q array or Q = 0;
true for the shipped ``example1``), the base config is the first trial of a new study, so the best trial is
never worse than the base. Whatever happens, :attr:`TuneResult.config` is
the base config itself when no trial beats it.

The sampler is ``optuna.samplers.TPESampler(seed=seed, multivariate=True,
n_startup_trials=10)`` (seed and ``constant_liar``: see below).

Structure search (``structure=StructureSearch(...)``)
-----------------------------------------------------
Each trial also draws the selection settings (integers, uniformly by TPE):
the deepest state tap ``max_delay``, the ``degree`` of the products and the
most terms per neuron ``max_terms``; the stopping rule (``criterion``,
default the extended BIC) picks each neuron's terms up to ``max_terms``.
For each fold, :func:`pyrhonn.structure.select` runs on the fold's training
part only (samples 0..N_f-1; selections are cached per fold and settings),
and the selected config (its terms, least-squares w0, and P0, Q, R from its
fit) is tuned by *factors*: every searched P0, Q, R, eta, beta is the
selected neuron's own value times a factor drawn log-uniformly in
:data:`DEFAULT_FACTORS` (``ranges`` then gives factor ranges). The candidate
is scored as above. The base config is scored as usual and only names the
states, inputs and dtype; it is the result when no trial beats it. A
selection that refuses the settings (too few rows for ``max_terms``) fails
the trial. The written config is the best trial's selection on the training
part of the last fold (the single split's training part when K = 1) with its
factors; it scores the last fold's part of the recorded value (exactly the
recorded value when K = 1).

The study: files, databases, workers
------------------------------------
``study_path`` keeps the study, so that a later call, or other workers on
this or other machines, add trials to it. ``n_trials`` is the number of
trials the study holds when the call returns: every worker counts all the
study's trials (scored, failed, errored, running elsewhere; those of
earlier calls too) and asks for a new one only while there are fewer than
``n_trials``, holding a lock across the count and the ask (a PostgreSQL
advisory lock for a database, ``flock`` on the file otherwise, and a thread
lock), so two workers with ``n_trials = 20`` run 20 together, and a study
resumes with a larger ``n_trials``. A killed worker's trial stays RUNNING
and counts. Each trial records the ``worker`` (host:pid) that ran it.
``study_path`` is a database URL when it has the form ``scheme://...``
(:func:`check_study`):

- ``postgresql://user[:password]@host[:port]/database`` (SQLAlchemy through
  optuna's ``RDBStorage``, driver psycopg2 if installed, else psycopg;
  ``postgresql+psycopg://`` names it): the way to share a study between
  machines. The database must exist; optuna creates its tables.
- ``sqlite:///relative/path.db`` or ``sqlite:////absolute/path.db``.

Anything else is a file path, whose suffix chooses the storage:

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
the base config and of the data, the train fraction, the folds, the structure
search settings and the search space) in
its user attributes; resuming with a different setup is refused with a
``ValueError`` naming what differs (trials of different problems cannot be
compared). A file that is not a readable study, a database that cannot be
reached, and a bad URL raise ``ValueError`` naming ``study_path``. The
sampler's seed is ``seed + the number of calls that joined the study
before`` (counted in the study under the same lock), so neither a resumed
run nor two workers given the same seed repeat each other's random start-up
trials. TPE runs with ``constant_liar`` whenever other trials may be running
(``n_jobs`` > 1 or a stored study).

Parallel trials
---------------
``n_jobs`` > 1 runs trials in that many threads of this call; the C
core releases the GIL while it runs, so long trajectories run in parallel.
With ``n_jobs = 1`` a seed reproduces the search exactly; with more, the
order in which trials finish, and so the search, depends on timing.

``batch`` = B > 1 has each worker ask B trials at once and run their B
configs in one call (:func:`pyrhonn.population.run_identifiers_outcomes`:
the tunings of one structure laid out across members, each member's run
bit for bit its own ``Identifier.run``), then report the B scores. Every
trial's score is exactly what it would be alone; the search differs from B
= 1 as with ``n_jobs`` = B (TPE proposes B trials before seeing their
scores, with ``constant_liar``), and a seed still reproduces it with
``n_jobs = 1``.

In a structure search, a trial's terms are those its settings select, and
only configs of one structure share a population. So the batch's first
trial draws the selection settings and its tuning factors as usual, and the
other B - 1 are enqueued with those settings fixed (optuna's
``enqueue_trial``; TPE draws their factors): every fold's B configs share
the fold's selected structure and run in one call (the batch's configs
are grouped by structure, fold by fold, so trials of other settings that
select the same terms would share a call too). The search then spends its trials as B tunings of each drawn
setting: fewer settings for the same number of trials than with B = 1. A
first trial whose settings the selection refuses fails alone, and the batch
starts again from a new draw.
"""
from __future__ import annotations

import fcntl
import hashlib
import importlib.util
import json
import math
import os
import re
import socket
import threading
import warnings
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from . import metrics
from .config import Activation, IdentifierConfig, NeuronConfig
from .identifier import Identifier, IdentifierError, capacities
from .regressors import refit_w0
from .simulation import scores, simulate
from .structure import CandidateSpace, Criterion, Selection, select
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
    "StructureSearch",
    "StudyStorage",
    "TrialCounts",
    "TuneResult",
    "apply_factors",
    "apply_values",
    "check_study",
    "fold_bounds",
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
_RUNS_ATTR = "pyrhonn_runs"

Progress = Callable[[str], None]


#: The free-run guard: a best trial whose held-out free run is worse than the base config's by more than
#: this fraction is not written (the base config is kept, and the result says why). It applies where the
#: base's free run means something (mean RRSE < 1, better than the held-out mean): a chaotic plant's free
#: run leaves the measurements whatever the tuning, and cannot judge one.
FREE_RUN_TOLERANCE = 0.05


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


def fold_bounds(n_samples: int, n_train: int, folds: int) -> tuple[tuple[int, int], ...]:
    """The folds of blocked cross-validation: ``(N_f, E_f)`` for f = 1..K.

    The held-out part N..T-1 of the single split is cut into ``folds`` = K
    contiguous blocks, b_f = N + floor(f (T - N) / K); fold f trains on
    samples 0..N_f-1 (N_f = b_{f-1}) and scores N_f..E_f-1 (E_f = b_f). K = 1
    is the single split. Every fold needs at least two samples.
    """
    K = check_int("folds", folds, 1)
    T, N = n_samples, n_train
    b = [N + (f * (T - N)) // K for f in range(K + 1)]
    if b[1] - b[0] < 2:
        raise fail("folds", f"{K} folds of the {T - N} held-out samples ({N}..{T - 1}) leave {b[1] - b[0]} in a "
                            "fold; at least 2 are needed (fewer folds, or a lower train fraction)")
    return tuple((b[f], b[f + 1]) for f in range(K))


@dataclass(frozen=True)
class Split:
    """How a trajectory was split: ``n_samples`` T, ``n_train`` N (the
    training part of the first fold), per state the number of targets scored
    (over all folds), and ``folds``, the ``(N_f, E_f)`` of each fold
    (:func:`fold_bounds`; one fold ``(N, T)`` for the single split)."""

    n_samples: int
    n_train: int
    scored: tuple[int, ...]
    folds: tuple[tuple[int, int], ...] = ()

    @property
    def n_held_out(self) -> int:
        return self.n_samples - self.n_train

    def to_dict(self) -> dict[str, Any]:
        folds = self.folds or ((self.n_train, self.n_samples),)
        return {"n_samples": self.n_samples, "n_train": self.n_train, "n_held_out": self.n_held_out,
                "train": [0, self.n_train - 1], "held_out": [self.n_train, self.n_samples - 1],
                "scored_targets": list(self.scored),
                "folds": [{"train": [0, n - 1], "scored": [n, e - 1]} for n, e in folds]}


@dataclass(frozen=True, eq=False)
class Score:
    """The held-out score of one config: ``value`` (the objective), and per
    state ``rmse``, ``scale`` (s_j) and ``normalised`` (RMSE_j / s_j), each
    the mean over the folds; ``folds`` holds each fold's objective (one
    value for the single split)."""

    value: float
    rmse: np.ndarray
    scale: np.ndarray
    normalised: np.ndarray
    folds: tuple[float, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        return {"objective": self.value, "rmse": self.rmse.tolist(), "scale": self.scale.tolist(),
                "normalised_rmse": self.normalised.tolist(), "folds": list(self.folds)}


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
                 truth: np.ndarray | None, train_fraction: float, folds: int = 1) -> None:
        X, U, valid_mask, truth = _check_trajectory(config, X, U, valid, truth)
        T, n = X.shape
        self.n_train = split_point(T, train_fraction)
        self.train_fraction = float(train_fraction)
        self.folds = fold_bounds(T, self.n_train, folds)
        self.dtype = config.dtype
        self.n_states = n
        self.raw = (X, U, valid_mask)  # float64, for the structure selection
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
        self.reference = np.where(np.isfinite(reference), reference, 0.0)
        self.has_truth = truth is not None
        # Per fold f: the targets N_f..E_f-1, which of them are scored, and s_j over them.
        self.targets: list[np.ndarray] = []
        self.masks: list[np.ndarray] = []
        self.scales: list[np.ndarray] = []
        total = np.zeros(n, dtype=int)
        for f, (N, E) in enumerate(self.folds):
            mask = valid_mask[N:E] if truth is None else np.ones((E - N, n), dtype=bool)
            scored = mask.sum(axis=0)
            for j in range(n):
                if scored[j] < 2:
                    where = "held-out" if len(self.folds) == 1 else f"fold {f + 1}'s"
                    raise fail("valid", f"state {j} has {int(scored[j])} valid {where} sample(s) (samples {N}.."
                                        f"{E - 1}); at least 2 are needed to score it (lower train_fraction"
                                        + ("?)" if len(self.folds) == 1 else " or fewer folds?)"))
            scale = np.empty(n)
            for j in range(n):
                s = float(np.std(reference[N:E][mask[:, j], j]))
                scale[j] = s if s > 0.0 else 1.0
            self.targets.append(reference[N:E])
            self.masks.append(mask)
            self.scales.append(scale)
            total += scored
        self.split = Split(int(T), int(self.n_train), tuple(int(c) for c in total), self.folds)
        digest = hashlib.sha256()
        for a in (np.where(valid_mask, X, 0.0), U, valid_mask, X if truth is None else truth):
            a = np.where(np.isfinite(a), a, 0.0) if a.dtype == np.float64 else a  # NaN payloads vary
            digest.update(np.ascontiguousarray(a).tobytes())
            digest.update(repr(a.shape).encode())
        digest.update(b"truth" if truth is not None else b"measured")
        self.data_hash = digest.hexdigest()

    def refit(self, config: IdentifierConfig, reference: IdentifierConfig, end: int | None = None) -> IdentifierConfig:
        """``config`` with w0 refitted on the training samples (0..end-1, by default the first fold's
        training part) for every neuron whose beta or activation differs from ``reference``'s
        (:func:`pyrhonn.regressors.refit_w0`): a trial that changes S starts from a fit for its own S."""
        X, U, valid = self.raw
        return refit_w0(config, X, U, valid, self.folds[0][0] if end is None else end, reference)

    def free_run_score(self, config: IdentifierConfig) -> float:
        """The mean over states of the held-out free-run RRSE: learning online up to the split,
        then the weights frozen and the network fed its own predictions over every held-out
        sample (:mod:`pyrhonn.simulation`); inf when the run diverges or cannot run."""
        N = self.n_train
        X = np.where(np.isfinite(self.X), self.X, 0.0).astype(self.dtype)
        try:
            with np.errstate(all="ignore"):
                sim = simulate(Identifier(config), X, self.U if config.n_inputs else None, self.valid,
                               free_run_from=N)
        except ValueError:
            return math.inf
        assert sim.free_run is not None
        reference = self.reference
        mask = np.zeros(reference.shape, dtype=bool)
        mask[N:] = True if self.valid is None or self.has_truth else self.valid[N:]
        sc = scores(reference, sim.free_run.astype(np.float64), mask)
        values = sc.rrse[np.isfinite(sc.rrse) | np.isinf(sc.rrse)]
        return float(np.mean(values)) if values.size else math.inf

    def _run(self, config: IdentifierConfig, end: int) -> np.ndarray:
        rows = self._run_many([config], end)[0]
        if isinstance(rows, TrialFailure):
            raise rows
        return rows

    def _fold_error(self, f: int, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(RMSE_j, RMSE_j / s_j) of fold f from a run's rows (row k is x̂(k+1))."""
        N, E = self.folds[f]
        est = rows[N - 1:E - 1].astype(np.float64)
        n = self.n_states
        rmse = np.empty(n)
        where = "" if len(self.folds) == 1 else f"fold {f + 1}, "
        with np.errstate(over="ignore", invalid="ignore"):
            for j in range(n):
                mask = self.masks[f][:, j]
                e = est[mask, j]
                if not np.all(np.isfinite(e)):
                    raise TrialFailure(f"{where}state {j}: held-out predictions are not finite")
                rmse[j] = metrics.rmse(self.targets[f][mask, j][:, None], e[:, None])[0]
        if not np.all(np.isfinite(rmse)):
            j = int(np.argmin(np.isfinite(rmse)))
            raise TrialFailure(f"{where}state {j}: held-out error overflows (the identifier diverged)")
        normalised = rmse / self.scales[f]
        if np.any(normalised > DIVERGED):
            j = int(np.argmax(normalised))
            raise TrialFailure(f"{where}state {j}: held-out RMSE is {normalised[j]:.3g} times the state's std "
                               f"(> {DIVERGED:g}: the identifier diverged)")
        return rmse, normalised

    def _combine(self, errors: Sequence[tuple[np.ndarray, np.ndarray]]) -> Score:
        rmse = np.mean([e[0] for e in errors], axis=0)
        normalised = np.mean([e[1] for e in errors], axis=0)
        scale = np.mean(self.scales, axis=0)
        folds = tuple(float(np.mean(e[1])) for e in errors)
        return Score(float(np.mean(folds)), rmse, scale, normalised, folds)

    def score(self, config: IdentifierConfig) -> Score:
        """The objective of ``config`` (one run serves every fold); :class:`TrialFailure` when it cannot be scored."""
        rows = self._run(config, self.folds[-1][1])
        return self._combine([self._fold_error(f, rows) for f in range(len(self.folds))])

    def _run_many(self, configs: Sequence[IdentifierConfig], end: int) -> list[np.ndarray | TrialFailure]:
        """Each config's run over samples 0..end-1, or the TrialFailure
        that fails it (the core refused the config, or the run stopped). The
        configs must share their structure; they run in one population call,
        unless only one of them can run (then ``Identifier.run``, which takes
        the identifier's own fastest path)."""
        from .population import run_identifiers_outcomes

        outcomes: list[np.ndarray | TrialFailure | None] = [None] * len(configs)
        runnable: dict[int, Identifier] = {}
        for k, config in enumerate(configs):
            if config.dtype != self.dtype:
                raise fail("config.dtype", f"{config.dtype!r} differs from the problem's {self.dtype!r}")
            try:
                runnable[k] = Identifier(config)
            except ValueError as exc:
                outcomes[k] = TrialFailure(f"config rejected: {exc}")
        valid = None if self.valid is None else self.valid[:end]
        runs: list[np.ndarray | IdentifierError] = []
        if len(runnable) == 1:
            try:
                runs = [next(iter(runnable.values())).run(self.X[:end], self.U[:end], valid)]
            except IdentifierError as exc:
                runs = [exc]
        elif runnable:
            runs = run_identifiers_outcomes(list(runnable.values()), self.X[:end], self.U[:end], valid)
        for k, rows in zip(runnable, runs):
            outcomes[k] = TrialFailure(f"identifier stopped: {rows}") if isinstance(rows, IdentifierError) else rows
        assert all(o is not None for o in outcomes)
        return outcomes  # type: ignore[return-value]

    def score_many(self, configs: Sequence[IdentifierConfig]) -> list[Score | TrialFailure]:
        """:meth:`score` of several tunings of one structure, run in one population call;
        each entry the config's Score or the TrialFailure ``score`` would raise for it."""
        outcomes: list[Score | TrialFailure] = []
        for rows in self._run_many(configs, self.folds[-1][1]):
            if isinstance(rows, TrialFailure):
                outcomes.append(rows)
                continue
            try:
                outcomes.append(self._combine([self._fold_error(f, rows) for f in range(len(self.folds))]))
            except TrialFailure as exc:
                outcomes.append(exc)
        return outcomes

    def score_folds(self, configs: Sequence[IdentifierConfig]) -> Score:
        """The objective when fold f runs ``configs[f]`` (structure search: each fold's own selection)."""
        errors = []
        for f, cfg in enumerate(configs):
            errors.append(self._fold_error(f, self._run(cfg, self.folds[f][1])))
        return self._combine(errors)

    def score_folds_many(self, trials: Sequence[Sequence[IdentifierConfig]]) -> list[Score | TrialFailure]:
        """:meth:`score_folds` of several trials (``trials[t][f]``: trial t's
        config for fold f), each entry the Score or the TrialFailure
        ``score_folds`` would raise (its first failing fold's). Per fold, the
        trials' configs that share a structure run as populations of up to
        RHONN_MAX_POPULATION members; the others alone."""
        from .population import max_population, structure_key

        n_folds = len(self.folds)
        for t, configs in enumerate(trials):
            if len(configs) != n_folds:
                raise fail(f"trials[{t}]", f"expected one config per fold ({n_folds}), got {len(configs)}")
        size = max_population(self.dtype)
        errors: list[list[tuple[np.ndarray, np.ndarray] | TrialFailure | None]] = [
            [None] * n_folds for _ in trials]
        for f in range(n_folds):
            groups: dict[tuple[Any, ...], list[int]] = {}
            for t, configs in enumerate(trials):
                groups.setdefault(structure_key(configs[f]), []).append(t)
            for members in groups.values():
                for start in range(0, len(members), size):
                    chunk = members[start:start + size]
                    runs = self._run_many([trials[t][f] for t in chunk], self.folds[f][1])
                    for t, rows in zip(chunk, runs):
                        if isinstance(rows, TrialFailure):
                            errors[t][f] = rows
                            continue
                        try:
                            errors[t][f] = self._fold_error(f, rows)
                        except TrialFailure as exc:
                            errors[t][f] = exc
        outcomes: list[Score | TrialFailure] = []
        for per_fold in errors:
            failure = next((e for e in per_fold if isinstance(e, TrialFailure)), None)
            outcomes.append(failure if failure is not None else self._combine(per_fold))  # type: ignore[arg-type]
        return outcomes


def held_out_score(config: IdentifierConfig, X: np.ndarray, U: np.ndarray, valid: np.ndarray | None = None,
                   *, truth: np.ndarray | None = None,
                   train_fraction: float = DEFAULT_TRAIN_FRACTION, folds: int = 1) -> Score:
    """The objective of :func:`tune` for one config (see the module docs).

    ``X`` (T, n) and ``U`` (T, m) are float64 (converted to the config's
    dtype to run, with an error if a value overflows it); ``valid`` is None
    or bool (T, n), and X may be NaN where it is False; ``truth`` (T, n), if
    given, is the reference scored at every held-out target; ``folds`` > 1
    scores blocked cross-validation (:func:`fold_bounds`). Raises
    ``ValueError`` for bad arguments and when the config cannot be scored
    (the identifier stopped or diverged).
    """
    if not isinstance(config, IdentifierConfig):
        raise fail("config", f"expected an IdentifierConfig, got {type(config).__name__}")
    problem = _Problem(config, X, U, valid, truth, train_fraction, folds)
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
                 ranges: Mapping[str, tuple[float, float]] | None = None,
                 relative: bool = False) -> tuple[Dimension, ...]:
    """The dimensions :func:`tune` searches for ``config`` (see the module docs).

    With ``relative`` (structure search) every dimension is a factor of
    each neuron's own value: the default range is :data:`DEFAULT_FACTORS`,
    ``ranges`` are factor ranges, and the base value is the factor 1.
    """
    if not isinstance(config, IdentifierConfig):
        raise fail("config", f"expected an IdentifierConfig, got {type(config).__name__}")
    if not isinstance(per_neuron, bool):
        raise fail("per_neuron", f"expected a bool, got {type(per_neuron).__name__}")
    chosen = _check_params(params)
    fixed = _check_ranges(ranges)
    dims: list[Dimension] = []
    for param in chosen:
        lo_f, hi_f = DEFAULT_FACTORS[param]
        centres = [(1.0, 1.0) if relative else _center(nr, param) for nr in config.neurons]
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
    return _apply(config, space, values, relative=False)


def apply_factors(config: IdentifierConfig, space: Sequence[Dimension], values: Mapping[str, float]) -> IdentifierConfig:
    """``config`` with every dimension of a relative ``space`` applied as a
    factor (rounded to 3 significant digits) of each neuron's own value
    (structure search: the selected config's P0, Q, R, eta and beta)."""
    return _apply(config, space, values, relative=True)


def _apply(config: IdentifierConfig, space: Sequence[Dimension], values: Mapping[str, float],
           relative: bool) -> IdentifierConfig:
    changes: list[dict[str, float]] = [{} for _ in config.neurons]
    for dim in space:
        if dim.name not in values:
            raise fail("values", f"missing {dim.name!r}")
        v = _round(check_real(f"values[{dim.name!r}]", values[dim.name], positive=True))
        for i in dim.neurons:
            if not relative:
                changes[i][dim.param] = v
                continue
            own = getattr(config.neurons[i], dim.param)
            if isinstance(own, np.ndarray):
                raise fail(f"config.neurons[{i}].{dim.param}", "a factor applies to a scalar value, not an array")
            changes[i][dim.param] = float(own) * v
    neurons = tuple(replace(nr, **ch) if ch else nr for nr, ch in zip(config.neurons, changes))
    return config.replace(neurons=neurons)


# -- structure search --------------------------------------------------------------------------------------

STRUCTURE_SETTINGS = ("max_delay", "degree", "max_terms")
"""The settings of :func:`pyrhonn.structure.select` a structure search searches, in order."""


@dataclass(frozen=True)
class StructureSearch:
    """The selection settings :func:`tune` searches with ``structure=``.

    ``max_delay``, ``degree`` and ``max_terms`` are inclusive integer ranges
    ``(low, high)`` (low == high fixes a setting) of the deepest state tap,
    the largest product and the most terms per neuron of
    :func:`pyrhonn.structure.select`; the stopping rule ``criterion`` (and
    ``holdout`` for the held-out rule) picks each neuron's terms up to
    ``max_terms``. ``delay_step``, ``factors`` and ``activations`` are fixed
    (:class:`pyrhonn.structure.CandidateSpace`); the slope of S is searched by
    the tuning's beta, so the selection uses beta = 1.
    """

    max_delay: tuple[int, int] = (0, 4)
    degree: tuple[int, int] = (1, 2)
    max_terms: tuple[int, int] = (2, 16)
    delay_step: int = 1
    factors: tuple[str, ...] = ("S", "u", "1")
    activations: tuple[Activation, ...] = (Activation.BIPOLAR, Activation.LOGISTIC)
    criterion: Criterion = Criterion.EBIC
    holdout: float = 0.2

    def __post_init__(self) -> None:
        limits = {"max_delay": (0, 254), "degree": (1, 4), "max_terms": (1, 255)}
        for name, (lo_min, hi_max) in limits.items():
            r = getattr(self, name)
            if not isinstance(r, tuple) or len(r) != 2:
                raise fail(name, f"expected a range (low, high) of whole numbers, got {r!r}")
            low = check_int(f"{name}.low", r[0], lo_min, hi_max)
            high = check_int(f"{name}.high", r[1], lo_min, hi_max)
            if low > high:
                raise fail(name, f"low must be <= high, got ({low}, {high})")
        check_int("delay_step", self.delay_step, 1, 254)
        try:
            object.__setattr__(self, "criterion", Criterion(self.criterion))
        except ValueError:
            raise fail("criterion", f"expected one of {[c.value for c in Criterion]}, got {self.criterion!r}") from None
        h = check_real("holdout", self.holdout)
        if not 0.0 < h < 1.0:
            raise fail("holdout", f"expected a fraction in (0, 1), got {h!r}")
        self.space(self.max_delay[1], self.degree[1])  # factors and activations, checked by CandidateSpace

    def space(self, max_delay: int, degree: int) -> CandidateSpace:
        """The candidate space of one trial."""
        return CandidateSpace(max_delay=max_delay, delay_step=self.delay_step, degree=degree,
                              factors=self.factors, activations=self.activations, betas=(1.0,))

    def dimensions(self) -> tuple[tuple[str, int, int], ...]:
        """``(setting, low, high)`` of each searched setting, in :data:`STRUCTURE_SETTINGS` order."""
        return tuple((name, *getattr(self, name)) for name in STRUCTURE_SETTINGS)

    def check(self, config: IdentifierConfig) -> None:
        """Refuse settings beyond the compiled capacities or the data's inputs (``ValueError`` naming the field)."""
        caps = capacities(config.dtype)
        for name, value, cap in (("max_delay", self.max_delay[1], "RHONN_MAX_DELAY"),
                                 ("degree", self.degree[1], "RHONN_MAX_FACTORS"),
                                 ("degree", self.degree[1], "RHONN_MAX_POWER"),
                                 ("max_terms", self.max_terms[1], "RHONN_MAX_TERMS")):
            if value > caps[cap]:
                raise fail(f"structure.{name}", f"{value} exceeds the compiled capacity {cap} = {caps[cap]} "
                                                "(pyrhonn info)")
        if "u" in self.factors and config.n_inputs == 0:
            raise fail("structure.factors", "'u' asks for input factors but the data has no inputs")

    def to_dict(self) -> dict[str, Any]:
        return {"max_delay": list(self.max_delay), "degree": list(self.degree), "max_terms": list(self.max_terms),
                "delay_step": self.delay_step, "factors": list(self.factors),
                "activations": [a.value for a in self.activations], "criterion": self.criterion.value,
                "holdout": self.holdout}


class _Selector:
    """Each fold's selection for given settings, on the fold's training part, cached (thread-safe)."""

    def __init__(self, problem: _Problem, structure: StructureSearch) -> None:
        self.problem = problem
        self.structure = structure
        self._cache: dict[tuple[int, tuple[int, ...]], Selection | str] = {}
        self._lock = threading.Lock()

    def selection(self, fold: int, settings: Mapping[str, int]) -> Selection:
        key = (fold, tuple(settings[name] for name in STRUCTURE_SETTINGS))
        with self._lock:
            hit = self._cache.get(key)
        if hit is None:
            X, U, valid = self.problem.raw
            N = self.problem.folds[fold][0]
            sp = self.structure
            try:
                hit = select(X[:N], U[:N], valid[:N], space=sp.space(settings["max_delay"], settings["degree"]),
                             criterion=sp.criterion, max_terms=settings["max_terms"], holdout=sp.holdout)
            except ValueError as exc:
                hit = f"selection on samples 0..{N - 1} refused: {exc}"
            with self._lock:
                self._cache[key] = hit
        if isinstance(hit, str):
            raise TrialFailure(hit)
        return hit

    def configs(self, settings: Mapping[str, int]) -> list[IdentifierConfig]:
        """The selected config of every fold (its own P0, Q, R, w0; the problem's dtype)."""
        # the scalar P0 form: trials scale each neuron's P0 by a factor
        return [self.selection(f, settings).config(dtype=self.problem.dtype, p0_form="scalar")
                for f in range(len(self.problem.folds))]


# -- the study ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class TrialCounts:
    """Trials in the study by state: scored (COMPLETE), failed (PRUNED:
    the identifier stopped or diverged, or the selection refused the
    settings), errored (FAIL: interrupted or an unexpected error) and still
    RUNNING (e.g. left by a killed run, or run by another worker)."""

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
    (for the base config: those it has as scalars; in a structure search
    factors of the selected values), ``best_structure`` the selection
    settings of a structure search's best trial. ``top`` lists the five
    best scored trials of the study; ``counts`` counts every trial of the
    study, including those of earlier runs and of other workers;
    ``new_trials`` is how many this call ran.
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
    structure: StructureSearch | None = None
    best_structure: dict[str, int] = field(default_factory=dict)
    selection: Selection | None = None
    base_free_run: float = math.nan  #: the base config's held-out free-run score (free_run_score)
    best_free_run: float = math.nan  #: the written config's
    kept_base: str | None = None  #: why the best trial was not written, when the free-run guard kept the base

    def summary(self) -> dict[str, Any]:
        """A JSON-serialisable summary of the study and the result."""
        return {
            "objective": "mean over states of held-out one-step-ahead RMSE / std of the held-out targets "
                         "(pyrhonn.tuning)" + (", mean over folds" if len(self.split.folds) > 1 else ""),
            "split": self.split.to_dict(),
            "train_fraction": self.train_fraction,
            "per_neuron": self.per_neuron,
            "space": [d.to_dict() for d in self.space],
            "structure": None if self.structure is None else self.structure.to_dict(),
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
            "best_structure": dict(self.best_structure),
            "improved": self.improved,
            "free_run": {"definition": "mean over states of the held-out free-run RRSE, learning online up to "
                                       "the split, then the weights frozen (inf: diverged)",
                         "base": metrics.json_value(self.base_free_run), "written": metrics.json_value(self.best_free_run)},
            "kept_base": self.kept_base,
            "top_trials": [dict(t) for t in self.top],
        }


@dataclass(frozen=True)
class StudyStorage:
    """Where a study lives: ``kind`` is ``"journal"`` (an optuna journal
    file), ``"sqlite"`` or ``"postgresql"``; ``path`` is the file of a
    journal or SQLite study, ``url`` the SQLAlchemy URL of a database
    (the driver resolved), ``shown`` how messages name it (no password)."""

    kind: str
    shown: str
    path: Path | None = None
    url: str | None = None


_URL = re.compile(r"^[A-Za-z][A-Za-z0-9+.\-]*://")
_PG_DRIVERS = {"psycopg": "psycopg", "psycopg2": "psycopg2", "pg8000": "pg8000"}


def _storage_kind(path: Path) -> str:
    kind = STUDY_SUFFIXES.get(path.suffix.lower())
    if kind is None:
        raise fail("study_path", f"{str(path)!r}: unknown study file type {path.suffix!r}; use .log (optuna journal "
                                 "file), .db (SQLite) or a database URL (postgresql://user@host/db, "
                                 "sqlite:///path)")
    return kind


def _check_folder(shown: str, p: Path) -> None:
    if p.is_dir():
        raise fail("study_path", f"{shown!r} is a directory")
    parent = p.parent if str(p.parent) else Path(".")
    if not parent.is_dir():
        raise fail("study_path", f"{shown!r}: folder {str(parent)!r} does not exist")


def check_study_path(path: str | Path) -> Path:
    """The study file path, checked before any work: a known suffix, an
    existing folder, not a folder itself. Returns it as a Path."""
    if not isinstance(path, (str, Path)) or not str(path):
        raise fail("study_path", f"expected a file path, got {path!r}")
    p = Path(path)
    _storage_kind(p)
    _check_folder(str(p), p)
    return p


def _check_url(text: str) -> StudyStorage:
    from sqlalchemy.engine import make_url
    from sqlalchemy.exc import ArgumentError

    try:
        url = make_url(text)
    except (ArgumentError, ValueError) as exc:
        raise fail("study_path", f"{text!r} is not a database URL ({exc}); expected postgresql://user@host/db or "
                                 "sqlite:///path") from None
    shown = url.render_as_string(hide_password=True)
    backend = url.get_backend_name()
    if backend == "sqlite":
        if not url.database or url.database == ":memory:":
            raise fail("study_path", f"{shown!r} names no database file (sqlite:///relative/path.db or "
                                     "sqlite:////absolute/path.db); a study in memory is not kept")
        p = Path(url.database)
        _check_folder(shown, p)
        return StudyStorage("sqlite", shown, path=p, url=text)
    if backend == "postgresql":
        if not url.database:
            raise fail("study_path", f"{shown!r} names no database (postgresql://user@host/DATABASE)")
        if "+" in url.drivername:
            driver = url.get_driver_name()
        else:  # SQLAlchemy's default is psycopg2; take psycopg (3) when only it is installed
            driver = next((d for d in ("psycopg2", "psycopg") if importlib.util.find_spec(d) is not None), "psycopg")
            url = url.set(drivername=f"postgresql+{driver}")
        module = _PG_DRIVERS.get(driver)
        if module is None:
            raise fail("study_path", f"{shown!r}: driver {driver!r} is not supported; use postgresql:// or "
                                     "postgresql+psycopg://")
        if importlib.util.find_spec(module) is None:
            raise fail("study_path", f"{shown!r}: the PostgreSQL driver {module!r} is not installed "
                                     "(pip install 'psycopg[binary]')")
        return StudyStorage("postgresql", shown, url=url.render_as_string(hide_password=False))
    raise fail("study_path", f"{shown!r}: database {backend!r} is not supported; use postgresql://user@host/db or "
                             "sqlite:///path")


def check_study(spec: str | Path) -> StudyStorage:
    """Where the study named by ``spec`` lives, checked before any work.

    A string of the form ``scheme://...`` is a database URL:
    ``postgresql://user[:password]@host[:port]/database`` (the driver
    psycopg2 if installed, else psycopg; ``postgresql+psycopg://`` names
    it) or ``sqlite:///path``. Anything else is a file path whose suffix
    chooses the storage (:data:`STUDY_SUFFIXES`). ``ValueError`` names
    ``study_path`` otherwise.
    """
    if not isinstance(spec, (str, Path)) or not str(spec):
        raise fail("study_path", f"expected a file path or a database URL, got {spec!r}")
    if isinstance(spec, str) and _URL.match(spec):
        return _check_url(spec)
    p = check_study_path(spec)
    kind = _storage_kind(p)
    return StudyStorage(kind, str(p), path=p, url=f"sqlite:///{p.resolve()}" if kind == "sqlite" else None)


def _unusable(loc: StudyStorage | None, exc: BaseException) -> ValueError:
    text = str(exc).strip()
    reason = text.splitlines()[0] if text else type(exc).__name__
    if loc is not None and loc.kind == "postgresql":
        return fail("study_path", f"cannot use the database {loc.shown!r} ({reason})")
    shown = "<memory>" if loc is None else loc.shown
    return fail("study_path", f"{shown!r} is not a readable optuna study file ({reason})")


def _open_storage(loc: StudyStorage) -> Any:
    import optuna

    try:
        if loc.kind == "postgresql":
            return optuna.storages.RDBStorage(loc.url, engine_kwargs={"connect_args": {"connect_timeout": 10}})
        if loc.kind == "sqlite":
            return optuna.storages.RDBStorage(loc.url, engine_kwargs={"connect_args": {"timeout": 60}})
        try:
            from optuna.storages.journal import JournalFileBackend, JournalFileOpenLock
        except ImportError:  # optuna 3.x names (not tested here: this environment has optuna 5)
            from optuna.storages import JournalFileOpenLock  # type: ignore[attr-defined,no-redef]
            from optuna.storages import JournalFileStorage as JournalFileBackend  # type: ignore[no-redef]

        path = str(loc.path)
        backend = JournalFileBackend(path, lock_obj=JournalFileOpenLock(path))
        return optuna.storages.JournalStorage(backend)
    except Exception as exc:  # SQLAlchemy, JSON and optuna errors alike: not a usable study
        raise _unusable(loc, exc) from None


_LOCK_KEY = int.from_bytes(hashlib.sha256(STUDY_NAME.encode()).digest()[:8], "big", signed=True)


class _Claim:
    """Serialises "count the study's trials, then ask for one" (and joining
    the study) across this run's threads and every worker sharing the study:
    a PostgreSQL advisory lock, or ``flock`` on the study file."""

    def __init__(self, loc: StudyStorage | None) -> None:
        self._thread = threading.Lock()
        self._fd: int | None = None
        self._conn: Any = None
        self._engine: Any = None
        if loc is None:
            return
        if loc.kind == "postgresql":
            import sqlalchemy
            from sqlalchemy.pool import NullPool

            try:
                self._engine = sqlalchemy.create_engine(loc.url, poolclass=NullPool,
                                                        connect_args={"connect_timeout": 10})
                self._conn = self._engine.connect().execution_options(isolation_level="AUTOCOMMIT")
            except Exception as exc:
                self.close()
                raise _unusable(loc, exc) from None
        else:
            assert loc.path is not None
            try:
                self._fd = os.open(loc.path, os.O_RDWR | os.O_CREAT, 0o666)
            except OSError as exc:
                raise fail("study_path", f"{loc.shown!r}: cannot open ({exc.strerror or exc})") from None

    def _sql(self, statement: str) -> None:
        import sqlalchemy

        self._conn.execute(sqlalchemy.text(statement), {"k": _LOCK_KEY})

    def __enter__(self) -> "_Claim":
        self._thread.acquire()
        try:
            if self._conn is not None:
                self._sql("SELECT pg_advisory_lock(:k)")
            elif self._fd is not None:
                fcntl.flock(self._fd, fcntl.LOCK_EX)
        except BaseException:
            self._thread.release()
            raise
        return self

    def __exit__(self, *exc: object) -> None:
        try:
            if self._conn is not None:
                self._sql("SELECT pg_advisory_unlock(:k)")
            elif self._fd is not None:
                fcntl.flock(self._fd, fcntl.LOCK_UN)
        finally:
            self._thread.release()

    def close(self) -> None:
        if self._conn is not None:
            self._conn.close()
            self._conn = None
        if self._engine is not None:
            self._engine.dispose()
            self._engine = None
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None


def _sha(obj: Any) -> str:
    return hashlib.sha256(json.dumps(obj, sort_keys=True).encode()).hexdigest()


def _setup(config: IdentifierConfig, problem: _Problem, space: Sequence[Dimension], per_neuron: bool,
           structure: StructureSearch | None) -> dict[str, Any]:
    setup = {
        "format": "pyrhonn-tune",
        "version": 1,
        "config_sha256": _sha(config.to_dict()),
        "data_sha256": problem.data_hash,
        "n_samples": problem.split.n_samples,
        "train_fraction": problem.train_fraction,
        "per_neuron": per_neuron,
        "space": [d.to_dict() for d in space],
    }
    # Only when used, so that studies made before folds and structure search still resume.
    if len(problem.folds) > 1:
        setup["folds"] = len(problem.folds)
    if structure is not None:
        setup["structure"] = structure.to_dict()
    return setup


_SETUP_WHAT = {
    "format": "study format",
    "version": "study format version",
    "config_sha256": "base config (terms, tuning, dtype)",
    "data_sha256": "data",
    "n_samples": "number of samples",
    "train_fraction": "train fraction",
    "per_neuron": "shared / per-neuron search",
    "space": "search space (parameters or ranges)",
    "folds": "number of folds",
    "structure": "structure search settings",
}


def _check_setup(shown: str, stored: Any, setup: dict[str, Any]) -> None:
    if not isinstance(stored, dict):
        raise fail("study_path", f"{shown!r} holds a study {STUDY_NAME!r} that pyrhonn tune did not create")
    differ = [_SETUP_WHAT[k] for k in _SETUP_WHAT if stored.get(k) != setup.get(k)]
    if differ:
        raise fail("study_path", f"{shown!r} was made for a different tuning problem ({', '.join(differ)} "
                                 "differ); use a new study, or the same config, data and options")


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
    folds: int = 1,
    n_trials: int = 50,
    n_jobs: int = 1,
    batch: int = 1,
    seed: int = 0,
    per_neuron: bool = False,
    params: Sequence[str] = PARAMETERS,
    ranges: Mapping[str, tuple[float, float]] | None = None,
    structure: StructureSearch | None = None,
    study_path: str | Path | None = None,
    n_startup_trials: int = 10,
    progress: Progress | None = None,
    free_run_guard: bool = True,
) -> TuneResult:
    """Search P0, Q, R, eta and beta of ``config`` (and, with ``structure``,
    the selection settings) on ``(X, U, valid)``.

    The objective, the folds, the search space, structure search, failed
    trials, the study and parallel trials are described in the module docs.
    ``X``, ``U``, ``valid`` and ``truth`` are as for :func:`held_out_score`;
    the runs use ``config.dtype``. Trials run until the study holds
    ``n_trials`` (>= 1) trials in all, those of earlier runs and of other
    workers sharing the study included; ``n_jobs`` threads at a time, each
    running ``batch`` trials per call of the core (1..RHONN_MAX_POPULATION);
    ``progress``, if given, receives one line per finished trial. Bad
    arguments raise ``ValueError`` naming them, before any trial runs; a
    failing trial never raises.
    """
    if not isinstance(config, IdentifierConfig):
        raise fail("config", f"expected an IdentifierConfig, got {type(config).__name__}")
    n_trials = check_int("n_trials", n_trials, 1)
    n_jobs = check_int("n_jobs", n_jobs, 1)
    from .population import max_population

    batch = check_int("batch", batch, 1, max_population(config.dtype))
    seed = check_int("seed", seed, 0, 2**32 - 1)
    n_startup_trials = check_int("n_startup_trials", n_startup_trials, 0)
    if progress is not None and not callable(progress):
        raise fail("progress", "expected a callable or None")
    if not isinstance(free_run_guard, bool):
        raise fail("free_run_guard", f"expected a bool, got {free_run_guard!r}")
    if structure is not None and not isinstance(structure, StructureSearch):
        raise fail("structure", f"expected None or a StructureSearch, got {type(structure).__name__}")
    space = search_space(config, params=params, per_neuron=per_neuron, ranges=ranges, relative=structure is not None)
    problem = _Problem(config, X, U, valid, truth, train_fraction, folds)
    loc = None if study_path is None else check_study(study_path)
    selector = None
    if structure is not None:
        structure.check(config)
        selector = _Selector(problem, structure)
        low = {name: lo for name, lo, _ in structure.dimensions()}
        X64, U64, valid64 = problem.raw
        N = problem.folds[0][0]
        # Data defects (a constant column, too few rows) are errors, not failed trials: one selection first.
        select(X64[:N], U64[:N], valid64[:N], space=structure.space(low["max_delay"], low["degree"]),
               criterion=structure.criterion, max_terms=low["max_terms"], holdout=structure.holdout)

    base: Score | None
    base_failure: str | None = None
    try:
        base = problem.score(config)
    except TrialFailure as exc:
        base, base_failure = None, str(exc)

    import optuna
    from optuna.trial import TrialState

    setup = _setup(config, problem, space, per_neuron, structure)
    shown = "<memory>" if loc is None else loc.shown
    claim = _Claim(loc)
    try:
        with claim:  # joining is serialised too: two workers must not both create the tables or enqueue
            storage = None if loc is None else _open_storage(loc)
            try:
                study = optuna.create_study(study_name=STUDY_NAME, storage=storage, direction="minimize",
                                            load_if_exists=True)
                existing = study.get_trials(deepcopy=False)
                stored = study.user_attrs.get(_SETUP_ATTR)
                runs = study.user_attrs.get(_RUNS_ATTR, 0)
            except Exception as exc:
                raise _unusable(loc, exc) from None
            if existing or stored is not None:
                _check_setup(shown, stored, setup)
            else:
                study.set_user_attr(_SETUP_ATTR, setup)
                if structure is None and all(d.base is not None for d in space):
                    study.enqueue_trial({d.name: d.base for d in space}, user_attrs={"base": True})
            runs = runs if isinstance(runs, int) else 0
            study.set_user_attr(_RUNS_ATTR, runs + 1)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", optuna.exceptions.ExperimentalWarning)
            study.sampler = optuna.samplers.TPESampler(seed=(seed + runs) % 2**32, multivariate=True,
                                                       n_startup_trials=n_startup_trials,
                                                       constant_liar=n_jobs > 1 or batch > 1 or loc is not None)
        ran = _run_trials(study, claim, problem, config, space, selector, structure, n_trials, n_jobs, batch,
                          progress)
    except (json.JSONDecodeError, _storage_errors()) as exc:  # a journal cut short, a database gone mid-run
        raise _unusable(loc, exc) from None
    finally:
        claim.close()

    complete = [t for t in study.get_trials(deepcopy=False, states=(TrialState.COMPLETE,))]
    best_score: Score | None = None
    best_trial: int | None = None
    best_config = config
    best_values: dict[str, float] = {}
    best_structure: dict[str, int] = {}
    best_selection: Selection | None = None
    if complete:
        winner = min(complete, key=lambda t: (t.value, t.number))
        try:
            if selector is None:
                candidates = [problem.refit(apply_values(config, space, winner.params), config)]
                score = problem.score(candidates[0])
            else:
                settings = {name: int(winner.params[name]) for name in STRUCTURE_SETTINGS}
                candidates = [problem.refit(apply_factors(c, space, winner.params), c, problem.folds[f][0])
                              for f, c in enumerate(selector.configs(settings))]
                score = problem.score_folds(candidates)
        except TrialFailure:  # pragma: no cover - the C core and the selection are deterministic
            score = None
        if score is not None and (base is None or score.value < base.value):
            best_score, best_trial, best_config = score, winner.number, candidates[-1]
            best_values = {d.name: _round(winner.params[d.name]) for d in space}
            if selector is not None:
                best_structure = settings
                best_selection = selector.selection(len(problem.folds) - 1, settings)
    kept_base: str | None = None
    base_free, best_free = problem.free_run_score(config), math.nan
    if best_score is not None:
        best_free = problem.free_run_score(best_config)
        if free_run_guard and base_free < 1.0 and best_free > base_free * (1.0 + FREE_RUN_TOLERANCE):
            kept_base = (f"the best trial's held-out free run (mean RRSE {best_free:.4g}) is worse than the base "
                         f"config's ({base_free:.4g}): the base config is kept")
            best_score, best_trial, best_config = None, None, config
            best_values, best_structure, best_selection = {}, {}, None
    improved = best_score is not None
    if not improved:
        best_score = base
        best_values = {d.name: d.base for d in space if d.base is not None and structure is None}
    top = tuple({"trial": t.number, "objective": t.value,
                 "values": {name: (_round(v) if isinstance(v, float) else v) for name, v in t.params.items()}}
                for t in sorted(complete, key=lambda t: (t.value, t.number))[:5])
    return TuneResult(
        config=best_config, base=base, base_failure=base_failure, best=best_score, best_trial=best_trial,
        best_values=best_values, improved=improved, new_trials=ran, counts=_counts(study),
        split=problem.split, space=space, per_neuron=per_neuron, train_fraction=problem.train_fraction,
        seed=seed, study_name=STUDY_NAME, storage=None if loc is None else loc.shown, top=top,
        structure=structure, best_structure=best_structure, selection=best_selection,
        base_free_run=base_free, best_free_run=best_free if improved else base_free, kept_base=kept_base,
    )


def _storage_errors() -> type[BaseException]:
    from sqlalchemy.exc import SQLAlchemyError

    return SQLAlchemyError


def _run_trials(study: Any, claim: _Claim, problem: _Problem, config: IdentifierConfig,
                space: Sequence[Dimension], selector: _Selector | None, structure: StructureSearch | None,
                n_trials: int, n_jobs: int, batch: int, progress: Progress | None) -> int:
    """Run trials until the study holds ``n_trials``; returns how many this call ran.

    Each worker thread counts the study's trials (every state, those running
    elsewhere included) and asks for a new one while holding the claim, so
    workers sharing the study together stop at exactly ``n_trials``.
    """
    from optuna.trial import TrialState

    stop = threading.Event()
    lock = threading.Lock()
    ran = [0]

    worker_name = f"{socket.gethostname()}:{os.getpid()}"

    def suggested(trial: Any) -> IdentifierConfig:
        trial.set_user_attr("worker", worker_name)
        values = {d.name: trial.suggest_float(d.name, d.low, d.high, log=True) for d in space}
        return problem.refit(apply_values(config, space, values), config)

    def scored(trial: Any, score: Score) -> float:
        trial.set_user_attr("rmse", score.rmse.tolist())
        trial.set_user_attr("normalised_rmse", score.normalised.tolist())
        if len(score.folds) > 1:
            trial.set_user_attr("folds", list(score.folds))
        return score.value

    def selected(trial: Any) -> list[IdentifierConfig]:
        """A structure trial's configs, one per fold (TrialFailure: the selection refused its settings)."""
        trial.set_user_attr("worker", worker_name)
        assert structure is not None and selector is not None
        settings = {name: trial.suggest_int(name, lo, hi) for name, lo, hi in structure.dimensions()}
        values = {d.name: trial.suggest_float(d.name, d.low, d.high, log=True) for d in space}
        configs = [problem.refit(apply_factors(c, space, values), c, problem.folds[f][0])
                   for f, c in enumerate(selector.configs(settings))]
        trial.set_user_attr("terms", [sum(len(nr.terms) for nr in c.neurons) for c in configs])
        return configs

    def objective(trial: Any) -> float:
        if selector is None:
            score = problem.score(suggested(trial))
        else:
            score = problem.score_folds(selected(trial))
        return scored(trial, score)

    def claim_trial(fixed: Mapping[str, int] | None = None) -> Any:
        """A new trial, or None when the study is full; ``fixed``: parameters it takes as given."""
        with claim:
            if stop.is_set() or len(study.get_trials(deepcopy=False)) >= n_trials:
                return None
            if fixed is not None:  # enqueued and asked under one claim: no other worker takes it
                study.enqueue_trial(dict(fixed))
            return study.ask()

    def report(frozen: Any) -> None:
        with lock:
            ran[0] += 1
        if progress is None:
            return
        if frozen.state == TrialState.COMPLETE:
            what = f"score {frozen.value:.6g}"
        elif frozen.state == TrialState.PRUNED:
            what = f"failed ({frozen.user_attrs.get('failure', 'pruned')})"
        else:
            what = frozen.state.name.lower()
        try:
            best = f"best {study.best_value:.6g} (trial {study.best_trial.number})"
        except ValueError:
            best = "no scored trial yet"
        progress(f"trial {frozen.number} [{frozen.number + 1}/{n_trials}]: {what}; {best}")

    def batch_worker() -> None:
        """Ask up to ``batch`` trials, score their configs in population calls, tell each.

        In a structure search the trials after the first take the first's
        selection settings (so each fold's configs share a structure); a first
        trial whose selection is refused fails alone."""
        while not stop.is_set():
            trials: list[Any] = []
            prepared: list[Any] = []
            failed: dict[int, TrialFailure] = {}
            fixed: dict[str, int] | None = None
            try:
                while len(trials) < batch:
                    trial = claim_trial(fixed)
                    if trial is None:
                        break
                    trials.append(trial)
                    if selector is None:
                        prepared.append(suggested(trial))
                        continue
                    try:
                        prepared.append(selected(trial))
                    except TrialFailure as exc:
                        failed[len(trials) - 1] = exc
                        prepared.append(None)
                        if fixed is None:
                            break  # the drawn settings cannot be selected: not for the rest of a batch
                        continue
                    if fixed is None:
                        assert structure is not None
                        fixed = {name: int(trial.params[name]) for name, _, _ in structure.dimensions()}
            except BaseException:
                stop.set()
                for trial in trials:
                    study.tell(trial, state=TrialState.FAIL)
                raise
            if not trials:
                return
            told: list[Any] = []  # the trials told so far, in order: on an error the rest fail
            try:
                runnable = [k for k in range(len(trials)) if k not in failed]
                if selector is None:
                    scores = problem.score_many([prepared[k] for k in runnable])
                else:
                    scores = problem.score_folds_many([prepared[k] for k in runnable])
                outcomes: dict[int, Score | TrialFailure] = {**failed, **dict(zip(runnable, scores))}
                for k, trial in enumerate(trials):
                    outcome = outcomes[k]
                    if isinstance(outcome, TrialFailure):
                        trial.set_user_attr("failure", str(outcome))
                        told.append(study.tell(trial, state=TrialState.PRUNED))
                    else:
                        told.append(study.tell(trial, scored(trial, outcome)))
            except BaseException:
                stop.set()
                for trial in trials[len(told):]:
                    study.tell(trial, state=TrialState.FAIL)
                raise
            for frozen in told:
                report(frozen)

    def worker() -> None:
        if batch > 1:
            batch_worker()
            return
        while not stop.is_set():
            trial = claim_trial()
            if trial is None:
                return
            try:
                value = objective(trial)
            except TrialFailure as exc:
                trial.set_user_attr("failure", str(exc))
                frozen = study.tell(trial, state=TrialState.PRUNED)
            except BaseException:
                stop.set()
                study.tell(trial, state=TrialState.FAIL)
                raise
            else:
                frozen = study.tell(trial, value)
            report(frozen)

    if n_jobs == 1:
        worker()
    else:
        with ThreadPoolExecutor(max_workers=n_jobs) as pool:
            futures = [pool.submit(worker) for _ in range(n_jobs)]
            try:
                for f in futures:
                    f.result()
            except BaseException:
                stop.set()
                raise
    return ran[0]
