"""Validation of an identifier: one-step, free-run (parallel model) and k-step-ahead prediction.

An identifier trained in series-parallel form (eq. 12) predicts x̂(k+1) from
the *measured* x(k), x(k-d) and u: that is its one-step-ahead prediction,
and a small one-step error says little about whether the network has learnt
the plant (a network that copies x(k) already scores well on a slow plant).
The stricter tests feed the network its own outputs:

- **free run** (simulation, the parallel model): from sample K on the weights
  are frozen and every state the network reads is its own prediction,

      x̂(k+1) = W^T z(x̂(k), x̂(k-d), ..., u(k), u(k-d), ...),   k >= K,

  started from the measured past: x̂(K) is the one-step prediction made at
  sample K-1 from measurements, and the taps before K read measured values.
  The inputs are always the measured ones. In the core this is exactly a
  step with learning off and every state marked not valid (the dropout rule
  of ``rhonn.h``: a missing state is replaced by its prediction).
- **k-step-ahead** (h steps): for every sample k, the network as it is after
  learning x(k) runs h-1 further samples on its own outputs without
  learning, giving x̂(k+h | k); then the real x(k+1) is learnt and the next
  branch starts. h = 1 is the one-step prediction.

Row convention. Every array here is aligned with the measurements: row k
holds an estimate of x(k) (NaN where there is none), as ``pyrhonn identify``'s
``predictions.csv`` does. :meth:`Identifier.run` instead returns the
streaming convention of the firmware, row t = x̂(t+1), the output of the step
at sample t; ``one_step`` here is ``np.vstack([x̂(0), run(...)[:-1]])``.

Errors of the free run are the ones that count for a model; one-step errors
of a network that keeps learning online are the ones that count for an
identifier in a loop. :func:`scores` gives both, as RMSE and RRSE.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .identifier import Identifier
from .metrics import rmse, rrse
from .validation import check_int

__all__ = ["Scores", "Simulation", "simulate", "free_run", "steps_ahead", "scores"]


@dataclass(frozen=True)
class Simulation:
    """What :func:`simulate` returns; every (T, n) array is aligned with the data (row k estimates x(k)).

    Attributes
    ----------
    one_step : ndarray (T, n)
        x̂(k), the prediction of sample k made at sample k-1 from measured
        values: learning online (as the identifier's switch says) before
        ``free_run_from``, with the weights frozen from it on. Row 0 is the
        prediction the identifier held before the call (the config's x0 for
        a fresh one).
    next_prediction : ndarray (n,)
        x̂(T), the one-step prediction beyond the last sample.
    free_run : ndarray (T, n) or None
        The parallel model's x̂(k) for k >= ``free_run_from`` (NaN before it
        and, if it diverged, from ``free_run_diverged`` on); None without a
        free run.
    free_run_diverged : int or None
        The first row the free run could not reach (its prediction was not
        finite at the identifier's dtype), None if it ran to the end.
    ahead : ndarray (T, n) or None
        x̂(k | k - steps): NaN in the first ``steps`` rows and where a branch
        diverged; None when ``steps`` was not asked for.
    free_run_from, steps : int or None
        The settings of the call.
    """

    one_step: np.ndarray
    next_prediction: np.ndarray
    free_run: np.ndarray | None
    free_run_diverged: int | None
    ahead: np.ndarray | None
    free_run_from: int | None
    steps: int | None


def simulate(identifier: Identifier, X: np.ndarray, U: np.ndarray | None = None, valid: np.ndarray | None = None,
             *, free_run_from: int | None = None, steps: int | None = None) -> Simulation:
    """Run ``identifier`` over a trajectory and validate it; see the module docs.

    Parameters
    ----------
    identifier:
        Any :class:`~pyrhonn.Identifier`, fresh or mid-run: the trajectory
        continues from its state. It learns the samples before
        ``free_run_from`` when its ``learning`` switch is on.
    X, U, valid:
        As :meth:`Identifier.run`: ``X`` (T, n) and ``U`` (T, m) of the
        identifier's dtype, ``valid`` None or bool (T, n).
    free_run_from:
        K in 0..T-1: samples 0..K-1 are stepped as by ``run`` (learning
        online), and from sample K on the weights are frozen; the free run
        starts there. None: no free run, every sample stepped as by ``run``.
    steps:
        h >= 1: also the h-step-ahead prediction of every sample.

    Afterwards the identifier is where the one-step pass left it (learnt up
    to ``free_run_from``, then stepped on measured values with the weights
    frozen), with its ``learning`` switch as it was. If a step of that pass
    fails, ``IdentifierError`` names the sample and the identifier is as it
    was before the call; a free run or a branch that diverges is a result
    (NaN rows, ``free_run_diverged``), not an error.
    """
    if not isinstance(identifier, Identifier):
        raise ValueError(f"identifier: expected a pyrhonn Identifier, got {type(identifier).__name__}")
    Xc, Uc, Vc = identifier._checked_trajectory(X, U, valid)
    T, n = Xc.shape
    if T == 0:
        raise ValueError("X: no samples (T = 0)")
    K = T if free_run_from is None else check_int("free_run_from", free_run_from, 0, T - 1)
    h = None if steps is None else check_int("steps", steps, 1)
    dtype = Xc.dtype
    out = np.full((T, n), np.nan, dtype=dtype)  # run convention: row t = x̂(t+1)
    branch_ahead = h if h is not None and h >= 2 else 0
    ahead = np.full((T, n), np.nan, dtype=dtype) if h is not None else None
    free: np.ndarray | None = None
    diverged: int | None = None
    with identifier._lock:
        start = identifier._checkpoint()
        learning = identifier.learning
        x0 = identifier.prediction
        try:
            done, status = identifier._pass(Xc, Uc, Vc, 0, K, out, ahead=branch_ahead, ahead_out=ahead)
            if status:
                _fail(identifier, status, Xc, Uc, Vc, done)
            if K < T:
                identifier.learning = False
                at_k = identifier._checkpoint()
                free_out = np.full((T, n), np.nan, dtype=dtype)
                done, status = identifier._pass(Xc, Uc, np.zeros((T, n), dtype=np.bool_), K, T, free_out)
                free = np.full((T, n), np.nan, dtype=dtype)
                free[K] = x0 if K == 0 else out[K - 1]
                free[K + 1:] = free_out[K:-1]  # rows the pass did not reach stay NaN
                if status:
                    diverged = K + 1 + done
                identifier._rollback(at_k)
                done, status = identifier._pass(Xc, Uc, Vc, K, T, out, ahead=branch_ahead, ahead_out=ahead)
                if status:
                    _fail(identifier, status, Xc, Uc, Vc, K + done)
                identifier.learning = learning
        except BaseException:
            identifier._rollback(start)
            raise
    one_step = np.vstack([x0[None, :], out[:-1]])
    if h == 1:
        assert ahead is not None
        ahead[1:] = out[:-1]
    return Simulation(one_step=one_step, next_prediction=out[-1].copy(), free_run=free,
                      free_run_diverged=diverged, ahead=ahead, free_run_from=free_run_from, steps=h)


def _fail(identifier: Identifier, status: int, X: np.ndarray, U: np.ndarray, V: np.ndarray | None, row: int) -> None:
    """Raise the step error of ``row`` (the caller rolls the identifier back)."""
    identifier._raise_step_error(status, X, U, V, row, single=False, neuron=int(identifier._net.fault_neuron))


def free_run(identifier: Identifier, X: np.ndarray, U: np.ndarray | None = None, valid: np.ndarray | None = None,
             *, start: int) -> np.ndarray:
    """The parallel model's x̂(k), aligned with X: :func:`simulate`'s ``free_run`` from ``start``."""
    result = simulate(identifier, X, U, valid, free_run_from=start)
    assert result.free_run is not None
    return result.free_run


def steps_ahead(identifier: Identifier, X: np.ndarray, U: np.ndarray | None = None,
                valid: np.ndarray | None = None, *, steps: int, frozen_from: int | None = None) -> np.ndarray:
    """x̂(k | k - steps), aligned with X: :func:`simulate`'s ``ahead``, the
    weights learning online before ``frozen_from`` and frozen from it on."""
    result = simulate(identifier, X, U, valid, free_run_from=frozen_from, steps=steps)
    assert result.ahead is not None
    return result.ahead


@dataclass(frozen=True)
class Scores:
    """Per-state errors of one estimate over the scored samples; NaN where none is scored."""

    rmse: np.ndarray
    rrse: np.ndarray
    scored: np.ndarray   #: samples scored per state
    missing: np.ndarray  #: scored samples without an estimate (a diverged free run or branch)


def scores(X: np.ndarray, estimate: np.ndarray, mask: np.ndarray) -> Scores:
    """RMSE and RRSE (:mod:`pyrhonn.metrics`) of ``estimate`` against ``X``, both (T, n) float,
    per state over the rows where ``mask`` (bool (T, n)) is True. A scored row whose estimate
    is NaN (the model diverged before it) makes that state's errors infinite and is counted
    in ``missing``."""
    for name, a in (("X", X), ("estimate", estimate)):
        if not isinstance(a, np.ndarray) or a.dtype.kind != "f" or a.ndim != 2:
            raise ValueError(f"{name}: expected a 2-D floating numpy array")
    if estimate.shape != X.shape:
        raise ValueError(f"estimate: shape {estimate.shape} differs from X shape {X.shape}")
    if not isinstance(mask, np.ndarray) or mask.dtype != np.bool_ or mask.shape != X.shape:
        raise ValueError(f"mask: expected a bool array of shape {X.shape}")
    n = X.shape[1]
    r, rr = np.full(n, np.nan), np.full(n, np.nan)
    scored = mask.sum(axis=0)
    missing = (mask & ~np.isfinite(estimate)).sum(axis=0)
    for j in range(n):
        rows = mask[:, j]
        if not rows.any():
            continue
        if missing[j]:
            r[j] = rr[j] = np.inf
            continue
        x = X[rows, j][:, None].astype(np.float64)
        xh = estimate[rows, j][:, None].astype(np.float64)
        r[j] = rmse(x, xh)[0]
        rr[j] = rrse(x, xh)[0]
    return Scores(rmse=r, rrse=rr, scored=scored, missing=missing)
