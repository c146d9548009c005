"""Tuning judged on validation recordings kept apart from the data that learns.

With validation experiments, a trial of :func:`pyrhonn.tuning.tune` is
scored in two stages:

1. **Learning** on the estimation experiments only: the candidate config's
   identifier runs online through each estimation experiment in turn (the
   identifier restarted at each boundary: no delayed tap reads across two
   recordings; weights and covariances carry over), so that it ends with
   the weights it learnt there. A trial that changes beta starts from w0
   refitted on the estimation rows (:func:`pyrhonn.regressors.refit_w0`).
2. **Scoring** on the validation experiments with those weights frozen
   (the learnt weights become w0 of a copy of the config that never
   learns): each validation experiment is its own run, started afresh
   (:func:`pyrhonn.search.validate`, as ``pyrhonn select`` scores). The
   objective (:class:`~pyrhonn.tuning_objective.Objective`) is, per state,
   the RRSE (RMSE / std of the validation samples, pooled over the
   validation experiments) of the one-step prediction, of the free run, of
   the k-step prediction, or the geometric mean of the one-step and the
   free-run figures (``mix``); a trial scores the mean over the states.

Nothing is learnt from a validation sample: the validation experiments are
only simulated with frozen weights. A free run (``free-run``, ``mix``) or
a k-step prediction that leaves the estimation data's range
(:func:`pyrhonn.residuals.divergence_range`) fails the trial, naming the
experiment and the sample.
"""
from __future__ import annotations

import hashlib
import math
from dataclasses import replace
from typing import Sequence

import numpy as np

from .config import IdentifierConfig
from .experiments import Experiment, merge
from .identifier import Identifier
from .refine import DataRange, first_sample
from .regressors import refit_w0
from .search import Validation, validate
from .simulation import scores, simulate
from .tuning_objective import Objective, Score, Split, TrialFailure, scored_each
from .validation import fail

__all__ = ["learnt", "validated_score"]


def learnt(config: IdentifierConfig, estimation: Sequence[Experiment]) -> IdentifierConfig:
    """``config`` with w0 the weights its identifier learnt online through ``estimation`` (restarted at
    each boundary); :class:`TrialFailure` when the core refuses the config or the run stops."""
    try:
        ident = Identifier(config)
    except ValueError as exc:
        raise TrialFailure(f"config rejected: {exc}") from None
    for e, ex in enumerate(estimation):
        if e:
            ident.restart()
        X, U = ex.frozen_inputs(config.dtype)
        try:
            ident.run(X, U if config.n_inputs else None, ex.valid)
        except ValueError as exc:  # IdentifierError
            raise TrialFailure(f"identifier stopped learning on {ex.name}: {exc}") from None
    weights = [np.asarray(w, dtype=np.float64) for w in ident.weights]
    if not all(np.all(np.isfinite(w)) for w in weights):
        raise TrialFailure("the learnt weights are not finite")
    return config.replace(neurons=tuple(replace(nr, w0=w) for nr, w in zip(config.neurons, weights)))


def _k_step(config: IdentifierConfig, validation: Sequence[Experiment], data_range: DataRange,
            horizon: int) -> tuple[np.ndarray, np.ndarray]:
    """Per state (RMSE, RRSE) of the frozen H-step prediction, pooled over the validation experiments."""
    n = config.n_states
    se, ns, sums, sums2 = np.zeros(n), np.zeros(n), np.zeros(n), np.zeros(n)
    for ex in validation:
        ident = Identifier(config)
        ident.learning = False
        X, U = ex.frozen_inputs(config.dtype)
        with np.errstate(all="ignore"):
            sim = simulate(ident, X, U if config.n_inputs else None, ex.valid, steps=horizon)
        assert sim.ahead is not None
        ahead = sim.ahead.astype(np.float64)
        mask = ex.valid.copy()
        mask[: min(first_sample(config, ex.n_samples) + horizon - 1, ex.n_samples)] = False
        out = mask & (~np.isfinite(ahead) | (ahead < data_range.low) | (ahead > data_range.high))
        if out.any():
            k = int(np.argmax(out.any(axis=1)))
            raise TrialFailure(f"{ex.name}: {horizon}-step prediction left the data's range at sample {k}")
        sc = scores(np.where(ex.valid, ex.X, 0.0), ahead, mask)
        se += np.where(sc.scored > 0, sc.rmse ** 2 * sc.scored, 0.0)
        x = np.where(mask, ex.X, 0.0)
        sums += x.sum(axis=0)
        sums2 += (x ** 2).sum(axis=0)
        ns += mask.sum(axis=0)
    ns = np.maximum(ns, 1)
    dev = np.maximum(sums2 - sums ** 2 / ns, 1e-300)
    return np.sqrt(se / ns), np.sqrt(se / dev)


def validated_score(config: IdentifierConfig, estimation: Sequence[Experiment], validation: Sequence[Experiment],
                    objective: Objective, data_range: DataRange | None = None) -> tuple[Score, Validation]:
    """The objective of ``config`` learnt on ``estimation`` and frozen on ``validation`` (see the module
    docs), with the frozen model's one-step and free-run figures; :class:`TrialFailure` when it cannot be
    scored (the identifier stopped, or the objective's simulation left the data's range)."""
    data_range = DataRange.of(estimation) if data_range is None else data_range
    frozen = learnt(config, estimation)
    checked = validate(frozen, validation, data_range)
    kind = objective.kind
    if kind in ("free-run", "mix") and checked.left_range is not None:
        name, k = checked.left_range
        raise TrialFailure(f"{name}: free run left the data's range at sample {k}")
    if kind == "one-step":
        rmse, rrse = checked.one_rmse, checked.one_rrse
    elif kind == "free-run":
        rmse, rrse = checked.free_rmse, checked.free_rrse
    elif kind == "mix":
        rmse, rrse = np.sqrt(checked.one_rmse * checked.free_rmse), np.sqrt(checked.one_rrse * checked.free_rrse)
    else:
        assert objective.horizon is not None
        rmse, rrse = _k_step(frozen, validation, data_range, objective.horizon)
    if not (np.all(np.isfinite(rmse)) and np.all(np.isfinite(rrse))):
        raise TrialFailure(f"the {objective} error on the validation data is not finite")
    scale = np.where(rrse > 0, rmse / np.where(rrse > 0, rrse, 1.0), 1.0)
    value = float(np.mean(rrse))
    return Score(value, rmse.copy(), scale, rrse.copy(), (value,)), checked


class _Validated:
    """The tuning problem of estimation and validation experiments (the interface of
    :class:`pyrhonn.tuning_objective._Problem` that :func:`pyrhonn.tuning.tune` uses; read only)."""

    def __init__(self, config: IdentifierConfig, estimation: Sequence[Experiment],
                 validation: Sequence[Experiment], objective: Objective) -> None:
        if not isinstance(objective, Objective):
            raise fail("objective", f"expected an Objective, got {type(objective).__name__}")
        for name, exps in (("estimation", estimation), ("validation", validation)):
            if not exps:
                raise fail(name, "expected at least one experiment")
            for e, ex in enumerate(exps):
                if not isinstance(ex, Experiment):
                    raise fail(f"{name}[{e}]", f"expected an Experiment, got {type(ex).__name__}")
                if (ex.X.shape[1], ex.U.shape[1]) != (config.n_states, config.n_inputs):
                    raise fail(f"{name}[{e}]", f"{ex.name} has {ex.X.shape[1]} states and {ex.U.shape[1]} inputs; "
                                               f"the config has {config.n_states} and {config.n_inputs}")
        self.estimation, self.validation = list(estimation), list(validation)
        self.objective = objective
        self.dtype = config.dtype
        self.n_states = config.n_states
        X, U, valid, self.starts = merge(self.estimation)
        self.raw = (X, U, valid)
        T = X.shape[0]
        self.n_train = T
        self.train_fraction = math.nan
        self.folds = ((T, T),)
        self.data_range = DataRange.of(self.estimation)
        scored = np.sum([ex.valid.sum(axis=0) for ex in self.validation], axis=0)
        self.split = Split(int(T), int(T), tuple(int(c) for c in scored), ())
        digest = hashlib.sha256()
        for part, exps in (("estimation", self.estimation), ("validation", self.validation)):
            digest.update(part.encode())
            for ex in exps:
                for a in (np.where(ex.valid, ex.X, 0.0), ex.U, ex.valid):
                    digest.update(np.ascontiguousarray(a).tobytes())
                    digest.update(repr(a.shape).encode())
        digest.update(str(objective).encode())
        self.data_hash = digest.hexdigest()

    @property
    def fit_rows(self) -> list[str]:
        return [f"{ex.name} rows {ex.rows}" for ex in self.estimation]

    @property
    def validation_rows(self) -> list[str]:
        return [f"{ex.name} rows {ex.rows}" for ex in self.validation]

    def refit(self, config: IdentifierConfig, reference: IdentifierConfig, end: int | None = None) -> IdentifierConfig:
        """``config`` with w0 refitted on the estimation rows where its beta or activation differs."""
        X, U, valid = self.raw
        return refit_w0(config, X, U, valid, self.n_train if end is None else end, reference)

    def score(self, config: IdentifierConfig) -> Score:
        return validated_score(config, self.estimation, self.validation, self.objective, self.data_range)[0]

    def score_many(self, configs: Sequence[IdentifierConfig]) -> list[Score | TrialFailure]:
        return scored_each(self.score, configs)

    def score_folds(self, configs: Sequence[IdentifierConfig]) -> Score:
        """One fold: the validation experiments (structure search does not run on them)."""
        return self.score(configs[-1])

    def score_folds_many(self, trials: Sequence[Sequence[IdentifierConfig]]) -> list[Score | TrialFailure]:
        return self.score_many([configs[-1] for configs in trials])

    def free_run_score(self, config: IdentifierConfig) -> float:
        """The mean free-run RRSE on the validation experiments after learning on the estimation
        experiments (inf when the identifier stops or the free run leaves the data's range)."""
        try:
            checked = validated_score(config, self.estimation, self.validation, Objective("one-step"),
                                      self.data_range)[1]
        except TrialFailure:
            return math.inf
        return checked.score
