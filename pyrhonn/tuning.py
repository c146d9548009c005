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

This module is the search itself (:func:`tune`, :class:`TuneResult`) and
the definition of everything it does, below; its parts live in modules of
their own, whose names it re-exports: :mod:`pyrhonn.tuning_objective` (the
split, the folds and the objective), :mod:`pyrhonn.tuning_space` (the search
space), :mod:`pyrhonn.tuning_structure` (structure search) and
:mod:`pyrhonn.tuning_study` (where a study lives, and its lock).

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
Each searched value is a scalar. A scalar P0 or Q becomes ``value * I`` (as
in the paper's eq. 20); a diagonal or matrix of the base config (``select``
writes P0 as the fit's covariance of the weights) is scaled so that the
geometric mean of its diagonal is the value, keeping its shape: the weights'
own uncertainties and the matrix's conditioning, which keep a few learning
steps from moving the directions the fit determined well. A parameter that
is not searched keeps the base config's value (arrays too).
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
the base config itself when no trial beats it on the objective (and
:attr:`TuneResult.kept_base` says so when the best trial was not the base).

Other objectives and validation experiments (``objective``, ``validation``)
----------------------------------------------------------------------------
``objective`` (:class:`~pyrhonn.tuning_objective.Objective`, default
``one-step``) is ``one-step``, ``free-run``, ``k-step:H`` or ``mix``. On
one trajectory (folds = 1), a frozen objective learns online up to the
split and then scores the held-out part with the weights frozen: the free
run, the H-step-ahead prediction, or (``mix``) per state the geometric mean
of the free-run figure and the one-step figure above; a free run or
prediction that leaves the training part's range
(:func:`pyrhonn.residuals.divergence_range`) fails the trial, naming the
sample. With ``validation`` experiments (:class:`pyrhonn.experiments.Experiment`),
``(X, U, valid)`` is the estimation data only (named ``estimation_name``,
starting at sample ``estimation_first`` of its file), ``train_fraction`` is
not used, and every trial learns on it and is scored on the validation
experiments with its weights frozen (:mod:`pyrhonn.tuning_validation`).
With a frozen objective the free-run guard does not apply: the choice
itself compared the best trial and the base on the objective.

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

import hashlib
import json
import math
import os
import socket
import threading
import warnings
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from . import metrics
from .config import IdentifierConfig
from .structure import Selection, select
from .validation import check_int, fail
from .experiments import Experiment
from .tuning_objective import (DEFAULT_OBJECTIVE, DEFAULT_TRAIN_FRACTION, DIVERGED, OBJECTIVES, Objective, Score, Split,
                               TrialFailure, _Problem, _check_trajectory, fold_bounds, held_out_score,
                               split_point)
from .tuning_space import (DEFAULT_FACTORS, PARAMETERS, Q_OVER_P0, SIGNIFICANT_DIGITS, Dimension, _round,
                           apply_factors, apply_values, search_space)
from .tuning_structure import STRUCTURE_SETTINGS, StructureSearch, _Selector
from .tuning_validation import _Validated
from .tuning_study import STUDY_NAME, STUDY_SUFFIXES, StudyStorage, _Claim, _open_storage, _unusable, check_study, \
    check_study_path

__all__ = [
    "DEFAULT_FACTORS",
    "DEFAULT_OBJECTIVE",
    "DEFAULT_TRAIN_FRACTION",
    "DIVERGED",
    "Dimension",
    "OBJECTIVES",
    "Objective",
    "PARAMETERS",
    "Q_OVER_P0",
    "SIGNIFICANT_DIGITS",
    "STRUCTURE_SETTINGS",
    "STUDY_NAME",
    "STUDY_SUFFIXES",
    "Score",
    "Split",
    "StructureSearch",
    "StudyStorage",
    "TrialCounts",
    "TrialFailure",
    "TuneResult",
    "apply_factors",
    "apply_values",
    "check_study",
    "check_study_path",
    "fold_bounds",
    "held_out_score",
    "search_space",
    "split_point",
    "tune",
]

_SETUP_ATTR = "pyrhonn_setup"
_RUNS_ATTR = "pyrhonn_runs"

Progress = Callable[[str], None]


#: The free-run guard: a best trial whose held-out free run is worse than the base config's by more than
#: this fraction is not written (the base config is kept, and the result says why). It applies where the
#: base's free run means something (mean RRSE < 1, better than the held-out mean): a chaotic plant's free
#: run leaves the measurements whatever the tuning, and cannot judge one.
FREE_RUN_TOLERANCE = 0.05


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
    kept_base: str | None = None  #: why the best trial was not written, when a guard kept the base
    objective: str = "one-step"  #: what trials were scored on (:class:`Objective`)
    fit_rows: tuple[str, ...] = ()  #: with validation experiments: the rows that learnt
    validation_rows: tuple[str, ...] = ()  #: the validation experiments' rows, that only scored

    def summary(self) -> dict[str, Any]:
        """A JSON-serialisable summary of the study and the result."""
        if self.validation_rows:
            what = (f"mean over states of the {self.objective} RRSE on the validation experiments, weights "
                    "learnt online on the estimation experiments then frozen (pyrhonn.tuning_validation)")
        elif self.objective == "one-step":
            what = ("mean over states of held-out one-step-ahead RMSE / std of the held-out targets "
                    "(pyrhonn.tuning)" + (", mean over folds" if len(self.split.folds) > 1 else ""))
        else:
            what = (f"mean over states of the held-out {self.objective} RMSE / std of the held-out targets, "
                    "weights frozen at the split (pyrhonn.tuning)")
        return {
            "objective": what,
            "objective_kind": self.objective,
            "fit_rows": list(self.fit_rows),
            "validation_rows": list(self.validation_rows),
            "split": None if self.validation_rows else self.split.to_dict(),
            "train_fraction": metrics.json_value(self.train_fraction),
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
            "free_run": {"definition": "mean over states of the free-run RRSE on the validation experiments, "
                                       "weights learnt on the estimation experiments then frozen (inf: diverged)"
                         if self.validation_rows else
                         "mean over states of the held-out free-run RRSE, learning online up to "
                         "the split, then the weights frozen (inf: diverged)",
                         "base": metrics.json_value(self.base_free_run), "written": metrics.json_value(self.best_free_run)},
            "kept_base": self.kept_base,
            "top_trials": [dict(t) for t in self.top],
        }


def _sha(obj: Any) -> str:
    return hashlib.sha256(json.dumps(obj, sort_keys=True).encode()).hexdigest()


def _setup(config: IdentifierConfig, problem: _Problem | _Validated, space: Sequence[Dimension], per_neuron: bool,
           structure: StructureSearch | None) -> dict[str, Any]:
    setup = {
        "format": "pyrhonn-tune",
        "version": 1,
        "config_sha256": _sha(config.to_dict()),
        "data_sha256": problem.data_hash,
        "n_samples": problem.split.n_samples,
        "train_fraction": None if math.isnan(problem.train_fraction) else problem.train_fraction,
        "per_neuron": per_neuron,
        "space": [d.to_dict() for d in space],
    }
    # Only when used, so that studies made before folds and structure search still resume.
    if len(problem.folds) > 1:
        setup["folds"] = len(problem.folds)
    if structure is not None:
        setup["structure"] = structure.to_dict()
    if problem.objective != DEFAULT_OBJECTIVE:
        setup["objective"] = str(problem.objective)
    if isinstance(problem, _Validated):
        setup["validation"] = problem.validation_rows
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
    "objective": "objective",
    "validation": "validation experiments",
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
    objective: str | Objective = DEFAULT_OBJECTIVE,
    validation: Sequence[Experiment] = (),
    estimation_name: str = "estimation",
    estimation_first: int = 0,
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
    goal = Objective.parse(objective)
    if structure is not None and goal.frozen:
        raise fail("objective", f"{goal}: structure search scores one step ahead only")
    problem: _Problem | _Validated
    if isinstance(validation, Experiment) or not isinstance(validation, (list, tuple)):
        raise fail("validation", f"expected a list of Experiment, got {type(validation).__name__}")
    if validation:
        if truth is not None:
            raise fail("truth", "not with validation experiments (they are scored on their measurements)")
        if structure is not None:
            raise fail("structure", "structure search is not available with validation experiments")
        if check_int("folds", folds, 1) != 1:
            raise fail("folds", "not with validation experiments (they are the held-out data)")
        if not isinstance(estimation_name, str):
            raise fail("estimation_name", f"expected a string, got {type(estimation_name).__name__}")
        check_int("estimation_first", estimation_first, 0)
        X, U, valid, _ = _check_trajectory(config, X, U, valid, None)
        mask = np.ones(X.shape, dtype=bool) if valid is None else valid
        est = Experiment(np.where(mask, X, np.nan), U, mask, name=estimation_name, first=estimation_first)
        problem = _Validated(config, [est], list(validation), goal)
    else:
        problem = _Problem(config, X, U, valid, truth, train_fraction, folds, goal)
    loc = None if study_path is None else check_study(study_path)
    selector = None
    if structure is not None:
        structure.check(config)
        assert isinstance(problem, _Problem)  # refused with validation experiments above
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
    kept: str | None = None
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
        if (score is not None and base is not None and score.value >= base.value
                and not winner.user_attrs.get("base", False)):
            kept = (f"the best trial's held-out {goal} score ({score.value:.4g}) is not better than the base "
                    f"config's ({base.value:.4g}): the base config is kept")
        if score is not None and (base is None or score.value < base.value):
            best_score, best_trial, best_config = score, winner.number, candidates[-1]
            best_values = {d.name: _round(winner.params[d.name]) for d in space}
            if selector is not None:
                best_structure = settings
                best_selection = selector.selection(len(problem.folds) - 1, settings)
    kept_base: str | None = kept
    base_free, best_free = problem.free_run_score(config), math.nan
    if best_score is not None:
        best_free = problem.free_run_score(best_config)
        # With a frozen objective the choice itself compared base and best on it (above).
        if free_run_guard and not goal.frozen and base_free < 1.0 and best_free > base_free * (1.0 + FREE_RUN_TOLERANCE):
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
        objective=str(goal), fit_rows=tuple(problem.fit_rows) if isinstance(problem, _Validated) else (),
        validation_rows=tuple(problem.validation_rows) if isinstance(problem, _Validated) else (),
    )


def _storage_errors() -> type[BaseException]:
    from sqlalchemy.exc import SQLAlchemyError

    return SQLAlchemyError


def _run_trials(study: Any, claim: _Claim, problem: _Problem | _Validated, config: IdentifierConfig,
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
