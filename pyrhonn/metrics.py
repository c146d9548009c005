"""Error metrics of the paper's Tables 1-7, per state.

For truth x and estimate xhat, both (T, n), the error of state j at sample k
is e_kj = x_kj - xhat_kj, and every metric is taken over the samples
k = warmup, ..., T-1 (all samples by default, as the paper), giving (n,).

- :func:`rmse`: sqrt(mean_k e_kj^2).
- :func:`absolute_deviation`: mean_k |e_kj - mean_k e_kj|, the *mean absolute
  deviation of the error about its mean*.
- :func:`rrse`: sqrt(sum_k e_kj^2 / sum_k (x_kj - mean_k x_kj)^2), the root
  relative squared error: the RMSE over the standard deviation of the truth,
  so 1 is what predicting the mean scores and 0 is perfect; comparable
  across states and data sets of different scales (the figure structure
  selection and the identification literature quote). NaN for a state
  whose truth is constant over the samples (the ratio is undefined).

Why this definition of "absolute deviation" (the paper does not define it):
the paper's simulations were run in MATLAB 2013a, whose Statistics Toolbox
``mad(e)`` returns exactly mean(abs(e - mean(e))) by default (flag 0; flag 1
is the median absolute deviation about the median). The definition is also
consistent with every table: it never exceeds the RMSE (by Jensen, it is at
most the standard deviation, which is at most the RMSE), and it is what
"the absolute deviation of the error" most directly names. It measures the
spread of the error and ignores a constant bias, which the RMSE does include.
Ratios in the paper's tables (e.g. 0.199/0.324 in Tables 1-2, far below
sqrt(2/pi) ~ 0.80 in Table 5) therefore say how bias- or spike-dominated each
error is. It is NOT the mean absolute error mean(|e|), nor the median
absolute deviation, nor scaled by 1.4826.

Inputs must be float numpy arrays of identical shape (T, n) with T > warmup,
with no NaN or infinity; anything else raises ValueError naming the argument.
Errors up to the float64 limit give finite metrics (taken on e / max|e| when
e^2 would overflow); truth and estimate beyond float64 apart give inf.
Nothing is reshaped: pass a single state as ``x[:, None]``.
"""
from __future__ import annotations

import math
from typing import Callable

import numpy as np

__all__ = ["absolute_deviation", "errors", "json_value", "rmse", "rrse"]

_SQUARE_SAFE = 1e150  #: |e| up to this squares and sums without overflow (float64 max is 1.8e308)


def errors(truth: np.ndarray, estimate: np.ndarray, warmup: int = 0) -> np.ndarray:
    """The validated error e = truth - estimate over samples warmup..T-1, (T - warmup, n)."""
    for name, a in (("truth", truth), ("estimate", estimate)):
        if not isinstance(a, np.ndarray):
            raise ValueError(f"{name}: expected a numpy array of shape (T, n), got {type(a).__name__}")
        if a.dtype.kind != "f":
            raise ValueError(f"{name}: expected a floating-point array, got dtype {a.dtype}")
        if a.ndim != 2:
            raise ValueError(f"{name}: expected shape (T, n), got {a.shape} (use x[:, None] for one state)")
    if truth.shape != estimate.shape:
        raise ValueError(f"estimate: shape {estimate.shape} differs from truth shape {truth.shape}")
    if isinstance(warmup, bool) or not isinstance(warmup, (int, np.integer)):
        raise ValueError(f"warmup: expected an integer number of samples, got {type(warmup).__name__} {warmup!r}")
    T, n = truth.shape
    if n < 1:
        raise ValueError("truth: needs at least one state (n >= 1)")
    if not 0 <= warmup < T:
        raise ValueError(f"warmup: must be in 0..{T - 1} for T = {T} samples, got {int(warmup)}")
    for name, a in (("truth", truth), ("estimate", estimate)):
        bad = ~np.isfinite(a)
        if np.any(bad):
            k, j = (int(i) for i in np.argwhere(bad)[0])
            raise ValueError(f"{name}[{k}, {j}]: must be finite, got {a[k, j]!r}")
    with np.errstate(over="ignore"):  # a difference beyond float64 is an infinite error, said by the result
        error: np.ndarray = (truth[warmup:] - estimate[warmup:]).astype(np.float64, copy=False)
    return error


def rmse(truth: np.ndarray, estimate: np.ndarray, warmup: int = 0) -> np.ndarray:
    """Root-mean-square error per state: sqrt(mean_k (x_kj - xhat_kj)^2), (n,).

    ``warmup`` samples at the start are excluded (default 0: all samples).
    """
    return _scaled(lambda e: np.sqrt(np.mean(e * e, axis=0)), errors(truth, estimate, warmup))


def absolute_deviation(truth: np.ndarray, estimate: np.ndarray, warmup: int = 0) -> np.ndarray:
    """Mean absolute deviation of the error about its mean, per state, (n,).

    With e_j = x_j - xhat_j over samples k = warmup..T-1 (count K):
    AD_j = (1/K) sum_k |e_kj - ebar_j|,  ebar_j = (1/K) sum_k e_kj.
    Equal to MATLAB's ``mad(e, 0)``; see the module docstring for why.
    """
    return _scaled(lambda e: np.mean(np.abs(e - np.mean(e, axis=0)), axis=0), errors(truth, estimate, warmup))


def rrse(truth: np.ndarray, estimate: np.ndarray, warmup: int = 0) -> np.ndarray:
    """Root relative squared error per state, (n,):

        RRSE_j = sqrt( sum_k e_kj^2 / sum_k (x_kj - xbar_j)^2 ),  k = warmup..T-1

    NaN where the truth is constant over those samples (a zero denominator).
    """
    e = errors(truth, estimate, warmup)
    x = truth[warmup:].astype(np.float64)
    spread = x - np.mean(x, axis=0)
    num = _scaled(lambda a: np.sqrt(np.mean(a * a, axis=0)), e)
    den = _scaled(lambda a: np.sqrt(np.mean(a * a, axis=0)), spread)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(den > 0, num / np.where(den > 0, den, 1.0), np.nan)


def _scaled(metric: Callable[[np.ndarray], np.ndarray], e: np.ndarray) -> np.ndarray:
    """``metric(e)`` for a metric that scales with |e| (both here do). Errors
    beyond 1e150 would overflow in e^2 or in a sum although the metric itself
    fits float64: then it is taken on e / peak and scaled back; an infinite
    error (truth and estimate beyond float64 apart) gives inf."""
    peak = np.max(np.abs(e), axis=0)
    if not np.any(peak > _SQUARE_SAFE):
        return metric(e)  # the plain formula, bit for bit, in every ordinary case
    with np.errstate(over="ignore", invalid="ignore"):
        scale = np.where((peak > 0) & np.isfinite(peak), peak, 1.0)
        out = scale * metric(e / scale)
    return np.where(np.isfinite(peak), out, np.inf)


def json_value(v: float) -> float | str | None:
    """A metric as the reports' JSON writes it: None where nothing was scored
    (NaN), the string "inf" where the model diverged (JSON has no infinity)."""
    if math.isnan(v):
        return None
    return "inf" if math.isinf(v) else float(v)
