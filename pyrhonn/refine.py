"""Simulation error and parallel training: weights fitted through the model's own feedback.

The identifier learns in series-parallel form (eq. 12): its regressor reads
the *measured* states, and so does the least-squares fit of
:func:`pyrhonn.structure.select`. A model that predicts one step well can
still simulate badly, since in a free run (the parallel model) every error
is fed back. This module scores and fits the weights on the free run itself.

Free run of a frozen network over an experiment (:func:`free_run_of`): the
first ``K = D + 1`` samples (D the config's deepest delay) are stepped on
measurements, from K on every state the network reads is its own prediction,

    x̂(k+1) = W^T z(x̂(k), x̂(k-d), ..., u(k), u(k-d), ...),   k >= K,

exactly the core's step with learning off and every state marked not valid.
A free run *leaves the data's range* at the first sample where a prediction
is not finite or lies outside ``[min_j - span_j, max_j + span_j]`` of the
estimation data (span = max - min; :func:`pyrhonn.residuals.divergence_range`): it is reported as diverged there, and
its later samples are not scored as numbers.

Simulation-error refinement (:func:`refine`) minimises

    V(w) = sum over experiments e, states j, samples k >= K of
           ((x̂_j(k; w) - x_j(k)) / sigma_j)^2,

sigma_j the standard deviation of state j over the estimation data, over
every neuron's weights w at once (the states feed each other in a free
run); or, with ``objective="balanced"``,

    V(w) = F(w) / F(w_0) + O(w) / O(w_0),

F the free-run sum above and O the same sum over the one-step predictions
(the network reading the measured states), each relative to its value at
the starting weights w_0: a step that halves the free-run error pays for
at most doubling the one-step error, where the free-run objective alone
gives up any share of the one-step accuracy of least squares for a small
gain in simulation (the first-order form, around w_0, of the geometric
mean of the two errors by which :func:`pyrhonn.search.search` compares
its finalists). V is minimised by Levenberg-Marquardt (Marquardt's diagonal scaling) with the
Jacobian by forward differences, each column one free run in the C core.
This is the output-error (simulation-error) fit of nonlinear system
identification, the offline counterpart of training the recurrent network
with the derivatives of the predictions carried through time (Puskorius and
Feldkamp); it starts from the least-squares weights and changes only w0 of
the config: the online step is the paper's, unchanged. A sample outside the
data's range costs a fixed 10 sigma, so no step towards divergence pays.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, replace
from typing import Sequence

import numpy as np

from .config import IdentifierConfig
from .experiments import Experiment
from .identifier import Identifier
from .residuals import divergence_range
from .simulation import simulate
from .validation import check_int, fail

__all__ = ["DataRange", "FreeRun", "OBJECTIVES", "Refinement", "free_run_of", "refine"]

#: What one sample outside the data's range costs in V, per state, in standard deviations.
OUT_OF_RANGE = 10.0
#: What :func:`refine` minimises: the free-run error, or the free-run and one-step errors each
#: relative to their values at the starting weights (module docs).
OBJECTIVES = ("free_run", "balanced")


@dataclass(frozen=True)
class DataRange:
    """Per state: the band a free run must stay in and the scale of its errors."""

    low: np.ndarray
    high: np.ndarray
    sigma: np.ndarray

    @classmethod
    def of(cls, experiments: Sequence[Experiment]) -> DataRange:
        X, valid = np.vstack([ex.X for ex in experiments]), np.vstack([ex.valid for ex in experiments])
        low, high = divergence_range(X, valid)
        sigma = np.nanstd(np.where(valid, X, np.nan), axis=0)
        return cls(low=low, high=high, sigma=np.where(sigma > 0, sigma, 1.0))


@dataclass(frozen=True)
class FreeRun:
    """A frozen network over one experiment, aligned with its samples (row k estimates x(k)).

    ``one_step`` and ``free_run`` are (T, n) float64, NaN where there is no
    estimate (the free run before ``start`` and from ``left_range`` on);
    ``left_range`` is the first sample whose free-run prediction was not
    finite or outside the data's range, None if it stayed in.
    """

    one_step: np.ndarray
    free_run: np.ndarray
    start: int
    left_range: int | None


def first_sample(config: IdentifierConfig, n_samples: int) -> int:
    """K: the first sample a free run predicts on its own (the taps before it read measurements)."""
    return min(config.max_delay + 1, n_samples - 1)


def _frozen(identifier: Identifier, experiment: Experiment, data_range: DataRange) -> FreeRun:
    config = identifier.config
    X, U = experiment.frozen_inputs(config.dtype)
    K = first_sample(config, experiment.n_samples)
    with np.errstate(all="ignore"):
        sim = simulate(identifier, X, U if config.n_inputs else None, experiment.valid, free_run_from=K)
    assert sim.free_run is not None
    fr = sim.free_run.astype(np.float64)
    out = ~np.isfinite(fr[K:]) | (fr[K:] < data_range.low) | (fr[K:] > data_range.high)
    left = None
    if out.any():
        left = K + int(np.argmax(out.any(axis=1)))
        fr[left:] = np.nan
    return FreeRun(one_step=sim.one_step.astype(np.float64), free_run=fr, start=K, left_range=left)


def free_run_of(config: IdentifierConfig, experiment: Experiment, data_range: DataRange) -> FreeRun:
    """The config's network, weights frozen at w0, over ``experiment`` (see the module docs)."""
    ident = Identifier(config)
    ident.learning = False
    return _frozen(ident, experiment, data_range)


@dataclass(frozen=True)
class Refinement:
    """What :func:`refine` returns: the config with refined w0 and how it got there."""

    config: IdentifierConfig
    cost_before: float  #: the free-run mean squared error at the starting weights, per scored sample and state
    cost_after: float  #: the same at the refined weights
    iterations: int
    evaluations: int  #: free runs of the whole estimation data
    seconds: float
    stopped: str  #: why it stopped
    objective: str = "free_run"  #: what was minimised (:data:`OBJECTIVES`)
    one_step_before: float = float("nan")  #: the one-step mean squared error at the starting weights, in state variances
    one_step_after: float = float("nan")  #: the same at the refined weights


class _Model:
    """The residual r(w) of every neuron's weights at once, over the estimation data: the free-run
    errors, and with ``balanced`` the one-step errors beside them, each part divided by its norm at
    the starting weights (set by :meth:`start`)."""

    def __init__(self, config: IdentifierConfig, experiments: Sequence[Experiment], data_range: DataRange,
                 balanced: bool = False) -> None:
        self.config = config
        self.range = data_range
        self.experiments = list(experiments)
        self.idents = [Identifier(config) for _ in self.experiments]
        self.sizes = [nr.n_terms for nr in config.neurons]
        self.evaluations = 0
        self.balanced = balanced
        self.scale = (1.0, 1.0)  # the free-run and one-step parts' divisors
        self.parts = (np.zeros(0), np.zeros(0))  # the unscaled errors of the last evaluation

    def start(self, theta: np.ndarray) -> np.ndarray:
        """The residual at the starting weights, which set the scale of the parts."""
        free, one = self.errors(theta)
        if self.balanced:
            self.scale = (max(float(np.linalg.norm(free)), 1e-150), max(float(np.linalg.norm(one)), 1e-150))
        return self.joined(free, one)

    def split(self, theta: np.ndarray) -> list[np.ndarray]:
        return np.split(theta, np.cumsum(self.sizes)[:-1])

    def errors(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The free-run and one-step errors in state standard deviations, over every scored sample."""
        self.evaluations += 1
        free, one = [], []
        ws = self.split(theta)
        for ident, ex in zip(self.idents, self.experiments):
            ident.reset()
            ident.learning = False
            for i, w in enumerate(ws):
                ident.set_weights(i, w.astype(ident.dtype))
            run = _frozen(ident, ex, self.range)
            mask = ex.valid.copy()
            mask[: run.start] = False
            x = np.where(ex.valid, ex.X, 0.0)
            with np.errstate(invalid="ignore", over="ignore"):
                e = (run.free_run - x) / self.range.sigma
                o = (run.one_step - x) / self.range.sigma
            free.append(np.where(np.isfinite(e), e, OUT_OF_RANGE)[mask])
            one.append(np.where(np.isfinite(o), o, OUT_OF_RANGE)[mask])
        self.parts = (np.concatenate(free), np.concatenate(one))
        return self.parts

    def joined(self, free: np.ndarray, one: np.ndarray) -> np.ndarray:
        return np.concatenate([free / self.scale[0], one / self.scale[1]]) if self.balanced else free

    def residual(self, theta: np.ndarray) -> np.ndarray:
        return self.joined(*self.errors(theta))


def refine(config: IdentifierConfig, experiments: Sequence[Experiment], data_range: DataRange | None = None, *,
           max_iterations: int = 30, max_evaluations: int = 3000, objective: str = "free_run") -> Refinement:
    """Refine every neuron's w0 of ``config`` on the free-run error over ``experiments``
    (``objective="balanced"``: on the free-run and one-step errors together, see the module docs).

    Levenberg-Marquardt on V(w) (module docs), started from the config's w0,
    at most ``max_iterations`` Jacobians and ``max_evaluations`` free runs
    of the data; it stops earlier when an iteration lowers V by less than
    1e-6 of it. The result's config differs from ``config`` in w0 only and
    never costs more than it.
    """
    if not isinstance(config, IdentifierConfig):
        raise fail("config", f"expected an IdentifierConfig, got {type(config).__name__}")
    check_int("max_iterations", max_iterations, 0)
    check_int("max_evaluations", max_evaluations, 1)
    if objective not in OBJECTIVES:
        raise fail("objective", f"expected one of {list(OBJECTIVES)}, got {objective!r}")
    exps = list(experiments)
    if not exps or not all(isinstance(ex, Experiment) for ex in exps):
        raise fail("experiments", "expected a non-empty list of Experiment")
    data_range = DataRange.of(exps) if data_range is None else data_range
    t0 = time.perf_counter()
    model = _Model(config, exps, data_range, balanced=objective == "balanced")
    theta = np.concatenate([nr.w0_vector() for nr in config.neurons]).astype(np.float64)
    r = model.start(theta)
    free0, one0 = best = model.parts
    n_res = max(free0.size, 1)
    cost = float(r @ r)
    cost0 = cost
    lam = 1e-3
    it = 0
    stopped = "max_iterations"
    while it < max_iterations:
        if model.evaluations + theta.size + 1 > max_evaluations:
            stopped = "max_evaluations"
            break
        it += 1
        J = np.empty((r.size, theta.size))
        for c in range(theta.size):
            h = 1e-6 * max(abs(theta[c]), 1e-3 * float(np.max(np.abs(theta))), 1e-9)
            tc = theta.copy()
            tc[c] += h
            J[:, c] = (model.residual(tc) - r) / h
        g = J.T @ r
        H = J.T @ J
        d = np.maximum(np.diag(H), 1e-12 * max(float(np.max(np.diag(H))), 1e-300))
        improved = False
        while model.evaluations < max_evaluations and lam < 1e10:
            try:
                step = np.linalg.solve(H + lam * np.diag(d), -g)
            except np.linalg.LinAlgError:
                lam *= 4.0
                continue
            r_new = model.residual(theta + step)
            c_new = float(r_new @ r_new)
            if np.isfinite(c_new) and c_new < cost:
                gain = cost - c_new
                theta, r, cost, best = theta + step, r_new, c_new, model.parts
                lam = max(lam / 3.0, 1e-12)
                improved = True
                break
            lam *= 4.0
        if not improved:
            stopped = "no step lowers the error"
            break
        if gain <= 1e-6 * cost:
            stopped = "converged"
            break
    ws = model.split(theta)
    neurons = tuple(replace(nr, w0=w.copy()) for nr, w in zip(config.neurons, ws))
    out = config.replace(neurons=neurons) if cost < cost0 else config
    free1, one1 = best
    return Refinement(config=out, cost_before=float(free0 @ free0) / n_res, cost_after=float(free1 @ free1) / n_res,
                      iterations=it, evaluations=model.evaluations, seconds=time.perf_counter() - t0, stopped=stopped,
                      objective=objective, one_step_before=float(one0 @ one0) / n_res,
                      one_step_after=float(one1 @ one1) / n_res)
