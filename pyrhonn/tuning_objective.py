"""The objective of the tuning search: a trajectory split into a training
part and held-out folds, and a config's held-out one-step-ahead score on
it (:func:`held_out_score`). :mod:`pyrhonn.tuning` defines it exactly
(The objective, Blocked cross-validation)."""
from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass
from typing import Any, Callable, Sequence

import numpy as np

from . import metrics
from .config import IdentifierConfig
from .identifier import Identifier, IdentifierError
from .regressors import refit_w0
from .residuals import divergence_range
from .simulation import scores, simulate
from .validation import check_int, check_real, fail

__all__ = ["DEFAULT_OBJECTIVE", "DEFAULT_TRAIN_FRACTION", "DIVERGED", "OBJECTIVES", "Objective", "Score", "Split",
           "TrialFailure", "fold_bounds", "held_out_score", "split_point"]

DEFAULT_TRAIN_FRACTION = 0.6


DIVERGED = 1e3
"""A trial whose RMSE_j / s_j exceeds this for some state has diverged (it fails)."""


class TrialFailure(Exception):
    """A candidate config that cannot be scored (the identifier stopped or diverged)."""


#: The kinds of held-out error a trial can be scored on (:class:`Objective`).
OBJECTIVES = ("one-step", "free-run", "k-step", "mix")


@dataclass(frozen=True)
class Objective:
    """What a trial is scored on over the held-out (or validation) samples.

    ``one-step``: the one-step-ahead prediction (on a single file's held-out
    part with learning on, as the identifier runs online; on validation
    recordings with the weights frozen). ``free-run``: the network fed its
    own predictions, weights frozen after learning. ``k-step`` (``horizon``
    H >= 2): each sample predicted H steps ahead from measured samples,
    weights frozen. ``mix``: per state the geometric mean of the one-step
    and the free-run figures (a halving of one that doubles the other is
    neutral). A frozen free run or branch that leaves the data's range fails
    the trial, naming the sample.
    """

    kind: str = "one-step"
    horizon: int | None = None

    def __post_init__(self) -> None:
        if self.kind not in OBJECTIVES:
            raise fail("objective", f"expected one of one-step, free-run, k-step:H, mix; got {self.kind!r}")
        if self.kind == "k-step":
            check_int("objective.horizon", self.horizon, 2)
        elif self.horizon is not None:
            raise fail("objective.horizon", f"only for k-step, got {self.horizon!r} for {self.kind}")

    @classmethod
    def parse(cls, text: object) -> Objective:
        """``one-step``, ``free-run``, ``k-step:H`` (H >= 2) or ``mix``; ValueError naming ``objective``."""
        if isinstance(text, Objective):
            return text
        if not isinstance(text, str):
            raise fail("objective", f"expected a string such as free-run or k-step:10, got {type(text).__name__}")
        kind, colon, h = text.strip().partition(":")
        if kind == "k-step":
            try:
                horizon = int(h) if colon else -1
            except ValueError:
                horizon = -1
            if horizon < 2:
                raise fail("objective", f"expected k-step:H with a whole number H >= 2, got {text!r}")
            return cls(kind, horizon)
        if colon:
            raise fail("objective", f"only k-step takes :H, got {text!r}")
        return cls(kind)

    def __str__(self) -> str:
        return f"k-step:{self.horizon}" if self.kind == "k-step" else self.kind

    @property
    def frozen(self) -> bool:
        """Whether the scored predictions are made with the weights frozen after learning."""
        return self.kind != "one-step"


#: The default objective; see the tuning docs for the measured figure behind it.
DEFAULT_OBJECTIVE = Objective("one-step")


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


def scored_each(score: Callable[[IdentifierConfig], Score],
                configs: Sequence[IdentifierConfig]) -> list[Score | TrialFailure]:
    """``score`` of each config in turn, or the :class:`TrialFailure` it raised."""
    outcomes: list[Score | TrialFailure] = []
    for config in configs:
        try:
            outcomes.append(score(config))
        except TrialFailure as exc:
            outcomes.append(exc)
    return outcomes


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
                 truth: np.ndarray | None, train_fraction: float, folds: int = 1,
                 objective: Objective = DEFAULT_OBJECTIVE) -> None:
        if not isinstance(objective, Objective):
            raise fail("objective", f"expected an Objective, got {type(objective).__name__}")
        self.objective = objective
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
        if objective.frozen and len(self.folds) > 1:
            raise fail("objective", f"{objective} scores the held-out part with the weights frozen at the split: "
                                    "only with folds = 1")
        self.range = divergence_range(X[:self.n_train], valid_mask[:self.n_train])
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

    def _frozen_error(self, config: IdentifierConfig) -> tuple[np.ndarray, np.ndarray]:
        """(RMSE_j, RMSE_j / s_j) of the frozen objective (free run, k-step or mix) over the held-out part:
        learning online up to the split, then the weights frozen (:mod:`pyrhonn.simulation`)."""
        N, E = self.folds[0]
        kind, H = self.objective.kind, self.objective.horizon
        X = np.where(np.isfinite(self.X), self.X, 0.0).astype(self.dtype)
        try:
            ident = Identifier(config)
        except ValueError as exc:
            raise TrialFailure(f"config rejected: {exc}") from None
        try:
            with np.errstate(all="ignore"):
                sim = simulate(ident, X[:E], self.U[:E] if config.n_inputs else None,
                               None if self.valid is None else self.valid[:E], free_run_from=N, steps=H)
        except ValueError as exc:  # IdentifierError: the learning part stopped
            raise TrialFailure(f"identifier stopped: {exc}") from None
        what = "free run" if kind != "k-step" else f"{H}-step prediction"
        est = sim.ahead if kind == "k-step" else sim.free_run
        assert est is not None
        est = est.astype(np.float64)
        held = est[N:E]
        out = ~np.isfinite(held) | (held < self.range[0]) | (held > self.range[1])
        if out.any():
            k = N + int(np.argmax(out.any(axis=1)))
            raise TrialFailure(f"held-out {what} left the data's range at sample {k}")
        rmse, normalised = self._fold_error(0, est[1:])  # est[k] estimates x(k); _fold_error reads row k-1
        if kind == "mix":
            one_rmse, one_norm = self._fold_error(0, self._run(config, E))
            rmse, normalised = np.sqrt(rmse * one_rmse), np.sqrt(normalised * one_norm)
        return rmse, normalised

    def score(self, config: IdentifierConfig) -> Score:
        """The objective of ``config`` (one run serves every fold); :class:`TrialFailure` when it cannot be scored."""
        if self.objective.frozen:
            return self._combine([self._frozen_error(config)])
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
        if self.objective.frozen:  # a simulation per config: no population call
            return scored_each(self.score, configs)
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
