"""Residual analysis of a model's one-step prediction errors, as MATLAB's ``resid``; fit and divergence as ``compare``.

A model that has captured the plant leaves one-step residuals
e(k) = x(k) - x̂(k | k-1) that are white (no correlation with their own
past) and independent of the inputs (nothing the inputs explain is left in
them). This module tests both, from sample estimates of the correlation
functions, and gives the two figures MATLAB's ``compare`` reports.

Stretches and gaps
------------------
A residual series may have gaps: samples whose measurement is not valid,
samples whose prediction read something other than measurements, and the
boundaries between separate experiments. Every function here takes the
residual as its **contiguous stretches** (a 1-D array, or a sequence of
1-D arrays, one per stretch; :func:`stretches` cuts a series at its gaps)
and never forms a product across a gap: a pair (k, k + tau) enters the
estimates only when both samples lie in the same stretch. The stretches are
pooled: one mean and one normalisation over all of them.

Correlation estimates
---------------------
For stretches s = 1..S of lengths N_s, N = sum_s N_s pooled samples, the
pooled means ebar = (1/N) sum_s sum_k e_s[k] (ubar likewise) and lags tau:

    c_ee(tau) = (1/N) sum_s sum_{k=0}^{N_s-1-tau} (e_s[k] - ebar) (e_s[k+tau] - ebar),   tau = 0..L
    r_ee(tau) = c_ee(tau) / c_ee(0)

    c_ue(tau) = (1/N) sum_s sum_{k: 0 <= k, k+tau < N_s} (u_s[k] - ubar) (e_s[k+tau] - ebar),   tau = -L..L
    r_ue(tau) = c_ue(tau) / sqrt(c_uu(0) c_ee(0))

the biased estimator (divided by N, not by the pair count), as MATLAB's
``xcorr(..., 'biased')`` and ``resid``: |r| <= 1 always (Cauchy-Schwarz),
and a lag that no stretch is long enough to hold gives r = 0. r_ue(tau)
with tau > 0 correlates the input with later residuals (input effects the
model misses); tau < 0 correlates it with earlier residuals (typically
output feedback into the input, a closed loop). Swapping the two series
mirrors the lags: r_eu(tau) = r_ue(-tau). A residual (or input) that is
constant has no correlation: the values are NaN and the test no verdict.

The test
--------
Under the null hypothesis that e is white noise independent of u, each
r_ee(tau) (tau != 0) and each r_ue(tau) is approximately normal with mean 0
and variance 1/N (for r_ue: sum_k r_uu(k) r_ee(k) / N = 1/N, since
r_ee(k) = 0 for k != 0), so it lies within the 99 % confidence bound

    +- z / sqrt(N),   z = 2.576 (the 0.995 quantile of the standard normal)

with probability 0.99 (the biased estimator's variance (N - tau)/N^2 is
smaller, so the bound is, if anything, conservative, the more so with many
short stretches). Of M tested lags (L for the autocorrelation, lag 0 being
1 by definition; 2L + 1 for each cross-correlation) about 1 % fall outside
by chance. The verdict rejects the null hypothesis when either

- **too many lags** fall outside: more than ``allowed``, the smallest count
  with P(Binomial(M, 0.01) > allowed) <= 0.005 (:func:`allowed_outside`;
  the lags taken as independent, as they nearly are under the null). For
  L = 25: more than 2 of the 25 autocorrelation lags, more than 3 of the 51
  cross-correlation lags. This catches a correlation spread over many lags;
- or **one lag is far outside**: max |r| beyond the family-wise bound
  z_M / sqrt(N), z_M = Phi^-1(1 - 0.005 / (2 M)) (Bonferroni over the M
  lags, :func:`peak_bound`; 3.72 for M = 25, 3.90 for M = 51). This catches
  a strong correlation at a single lag (a missed input term at one delay),
  which the count alone would let pass.

Each rule falsely rejects a white residual with probability at most about
0.5 % (about: the lags are only nearly normal and independent under the
null), so the verdict does at most about 1 % of the time (the union bound);
the residual is "white" / "independent of the input" unless it rejects.

Fit and divergence
------------------
- :func:`fit_percent`: the NRMSE fit of MATLAB's ``compare``,
  fit = 100 (1 - ||x - x̂|| / ||x - xbar||) = 100 (1 - RRSE) per state
  (RRSE of :mod:`pyrhonn.metrics`): 100 is perfect, 0 is what the mean of
  the data scores, and it is negative for a model worse than the mean.
- :func:`departure`: where a simulated state leaves the data's range far, the
  measured range [lo, hi] widened by its span on both sides (see
  :func:`divergence_range`), or stops being finite: a diverged simulation,
  whose error figures would only measure how far it went.

All functions take numpy floating arrays, never reshape or coerce silently
(an integer or non-finite input is a ValueError naming the argument), and
compute in float64.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from statistics import NormalDist
from typing import Sequence

import numpy as np

from .metrics import rrse

__all__ = ["CONFIDENCE", "Z_99", "CorrelationTest", "allowed_outside", "autocorrelation", "confidence_bound",
           "cross_correlation", "departure", "divergence_range", "fit_percent", "independence_test",
           "peak_bound", "stretches", "usable_residuals", "whiteness_test"]

CONFIDENCE = 0.99  #: the confidence level of the bound and of the verdict
Z_99 = 2.576       #: the standard normal's 0.995 quantile: a two-sided 99 % bound is +- Z_99 / sqrt(N)
_P_OUTSIDE = 1.0 - CONFIDENCE  #: the chance of one lag falling outside the bound under the null
_ALPHA_RULE = _P_OUTSIDE / 2   #: each of the verdict's two rules rejects a white residual at most this often


Series = np.ndarray | Sequence[np.ndarray]


def _pieces(name: str, x: Series) -> list[np.ndarray]:
    """The stretches of ``x`` (one 1-D array, or a sequence of them) as float64, checked."""
    parts = [x] if isinstance(x, np.ndarray) else list(x)
    out: list[np.ndarray] = []
    for s, a in enumerate(parts):
        where = name if isinstance(x, np.ndarray) else f"{name}[{s}]"
        if not isinstance(a, np.ndarray):
            raise ValueError(f"{where}: expected a 1-D numpy array, got {type(a).__name__}")
        if a.dtype.kind != "f":
            raise ValueError(f"{where}: expected a floating-point array, got dtype {a.dtype}")
        if a.ndim != 1:
            raise ValueError(f"{where}: expected a 1-D array (one stretch), got shape {a.shape}")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"{where}[{int(np.flatnonzero(~np.isfinite(a))[0])}]: must be finite")
        out.append(a.astype(np.float64, copy=False))
    if not sum(a.size for a in out):
        raise ValueError(f"{name}: no samples")
    return out


def _check_lags(lags: int) -> int:
    if isinstance(lags, bool) or not isinstance(lags, (int, np.integer)):
        raise ValueError(f"lags: expected an integer, got {type(lags).__name__} {lags!r}")
    if lags < 1:
        raise ValueError(f"lags: must be >= 1, got {int(lags)}")
    return int(lags)


def _padded(parts: list[np.ndarray], lags: int) -> tuple[np.ndarray, int]:
    """The pooled de-meaned stretches laid end to end, each followed by ``lags`` zeros, and N:
    a product across two stretches then always meets a zero, so a plain lagged dot product
    sums exactly the pairs inside the stretches."""
    n = sum(a.size for a in parts)
    mean = sum(float(np.sum(a)) for a in parts) / n
    gap = np.zeros(lags)
    return np.concatenate([piece for a in parts for piece in (a - mean, gap)]), n


def _lagged(a: np.ndarray, b: np.ndarray, tau: int) -> float:
    """sum_k a[k] b[k + tau] over the k where both exist (a, b of equal length)."""
    if tau >= 0:
        return float(np.dot(a[:a.size - tau], b[tau:]))
    return float(np.dot(a[-tau:], b[:b.size + tau]))


def stretches(x: np.ndarray, usable: np.ndarray) -> list[np.ndarray]:
    """The runs of consecutive samples of ``x`` (T,) where ``usable`` (T,) bool is True, in order."""
    if not isinstance(x, np.ndarray) or x.ndim != 1 or x.dtype.kind != "f":
        raise ValueError("x: expected a 1-D floating-point numpy array")
    if not isinstance(usable, np.ndarray) or usable.dtype != np.bool_ or usable.shape != x.shape:
        raise ValueError(f"usable: expected a bool array of shape {x.shape}")
    edges = np.flatnonzero(np.diff(np.r_[0, usable.astype(np.int8), 0]))
    return [x[a:b] for a, b in zip(edges[::2], edges[1::2])]


def usable_residuals(valid: np.ndarray, first: int, depth: int) -> np.ndarray:
    """Bool (T, n): where the one-step residual e_i(k) = x_i(k) - x̂_i(k | k-1) is a pure one-step error.

    Row k is usable for state i when k >= ``first``, x_i(k) is valid (a target
    exists) and every state was valid in rows k-1-depth .. k-1, the samples
    the prediction x̂(k) read with a deepest tap of ``depth`` (a missing state
    is replaced by its own prediction, which would make x̂(k) a longer-range
    prediction). A dropout at row g therefore removes rows g .. g+depth+1.
    """
    if not isinstance(valid, np.ndarray) or valid.dtype != np.bool_ or valid.ndim != 2:
        raise ValueError("valid: expected a 2-D bool numpy array (T, n)")
    T = valid.shape[0]
    for name, v in (("first", first), ("depth", depth)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 0:
            raise ValueError(f"{name}: expected an integer >= 0, got {v!r}")
    all_valid = valid.all(axis=1).astype(np.int64)
    window = int(depth) + 1
    done = np.r_[0, np.cumsum(all_valid)]  # done[k] = fully valid rows among 0..k-1
    taps_ok = np.zeros(T, dtype=np.bool_)
    for_k = np.arange(window, T)         # rows k - window .. k - 1 exist
    taps_ok[for_k] = done[for_k] - done[for_k - window] == window
    usable = valid & taps_ok[:, None]
    usable[:int(first)] = False
    return usable


def autocorrelation(e: Series, lags: int) -> np.ndarray:
    """r_ee(tau) for tau = 0..lags, (lags + 1,) float64 (the module's formula); NaN if e is constant."""
    L = _check_lags(lags)
    z, n = _padded(_pieces("e", e), L)
    c = np.array([_lagged(z, z, tau) for tau in range(L + 1)]) / n
    if not c[0] > 0:
        return np.full(L + 1, np.nan)
    r: np.ndarray = c / c[0]
    return r


def cross_correlation(u: Series, e: Series, lags: int) -> np.ndarray:
    """r_ue(tau) for tau = -lags..lags, (2 lags + 1,) float64, entry lags + tau holding r_ue(tau)
    (the module's formula); NaN if either series is constant. ``u`` and ``e`` are cut into
    the same stretches (equal lengths)."""
    L = _check_lags(lags)
    up, ep = _pieces("u", u), _pieces("e", e)
    if [a.size for a in up] != [a.size for a in ep]:
        raise ValueError(f"u: stretch lengths {[a.size for a in up]} differ from e's {[a.size for a in ep]}")
    zu, n = _padded(up, L)
    ze, _ = _padded(ep, L)
    cuu, cee = float(np.dot(zu, zu)) / n, float(np.dot(ze, ze)) / n
    if not (cuu > 0 and cee > 0):
        return np.full(2 * L + 1, np.nan)
    c = np.array([_lagged(zu, ze, tau) for tau in range(-L, L + 1)]) / n
    return c / math.sqrt(cuu * cee)


def confidence_bound(n: int, z: float = Z_99) -> float:
    """z / sqrt(n): the bound on a normalised correlation estimate of n white samples (99 % by default)."""
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise ValueError(f"n: expected a sample count >= 1, got {n!r}")
    return float(z) / math.sqrt(int(n))


def allowed_outside(n_lags: int, p: float = _P_OUTSIDE, alpha: float = _ALPHA_RULE) -> int:
    """The smallest m with P(Binomial(n_lags, p) > m) <= alpha: more lags than m outside the bound
    reject the null hypothesis at level alpha (the module docs)."""
    if isinstance(n_lags, bool) or not isinstance(n_lags, (int, np.integer)) or n_lags < 1:
        raise ValueError(f"n_lags: expected an integer >= 1, got {n_lags!r}")
    tail = 1.0  # P(X > m - 1) = P(X >= m)
    for m in range(int(n_lags) + 1):
        tail -= math.comb(int(n_lags), m) * p ** m * (1.0 - p) ** (int(n_lags) - m)  # now P(X > m)
        if tail <= alpha:
            return m
    return int(n_lags)


def peak_bound(n: int, n_lags: int, alpha: float = _ALPHA_RULE) -> float:
    """z_M / sqrt(n), z_M = Phi^-1(1 - alpha / (2 M)) for M = ``n_lags``: under the null hypothesis
    every one of M normalised correlations of n samples lies within it with probability >= 1 - alpha
    (Bonferroni)."""
    if isinstance(n_lags, bool) or not isinstance(n_lags, (int, np.integer)) or n_lags < 1:
        raise ValueError(f"n_lags: expected an integer >= 1, got {n_lags!r}")
    return confidence_bound(n, NormalDist().inv_cdf(1.0 - alpha / (2 * int(n_lags))))


@dataclass(frozen=True)
class CorrelationTest:
    """One whiteness or independence test (the module docs).

    Attributes
    ----------
    lags : ndarray of int
        The lags of ``values``: 0..L (autocorrelation) or -L..L (cross-correlation).
    values : ndarray
        The normalised correlation at those lags (NaN where undefined).
    n : int
        Pooled samples N; ``stretches`` their count.
    bound : float
        z / sqrt(N).
    tested : int
        Lags tested against the bound (L, lag 0 left out; or 2L + 1).
    outside : int
        Tested lags with |value| > bound; ``fraction`` = outside / tested.
    allowed : int
        :func:`allowed_outside` (tested).
    peak_lag, peak : int, float
        The tested lag of largest |value|, and that value (NaN when undefined).
    peak_bound : float
        :func:`peak_bound` (N, tested).
    passed : bool or None
        outside <= allowed and |peak| <= peak_bound (white / independent); None when undefined
        (a constant series).
    """

    lags: np.ndarray
    values: np.ndarray
    n: int
    stretches: int
    bound: float
    tested: int
    outside: int
    fraction: float
    allowed: int
    peak_lag: int
    peak: float
    peak_bound: float
    passed: bool | None


def _test(lags: np.ndarray, values: np.ndarray, tested: np.ndarray, n: int, count: int) -> CorrelationTest:
    bound = confidence_bound(n)
    m = int(tested.sum())
    allowed, far = allowed_outside(m), peak_bound(n, m)
    if not np.all(np.isfinite(values)):
        return CorrelationTest(lags=lags, values=values, n=n, stretches=count, bound=bound, tested=m, outside=0,
                               fraction=0.0, allowed=allowed, peak_lag=int(lags[tested][0]), peak=math.nan,
                               peak_bound=far, passed=None)
    magnitude = np.abs(values[tested])
    outside = int(np.sum(magnitude > bound))
    at = int(np.argmax(magnitude))
    peak = float(values[tested][at])
    return CorrelationTest(lags=lags, values=values, n=n, stretches=count, bound=bound, tested=m, outside=outside,
                           fraction=outside / m, allowed=allowed, peak_lag=int(lags[tested][at]), peak=peak,
                           peak_bound=far, passed=outside <= allowed and abs(peak) <= far)


def whiteness_test(e: Series, lags: int) -> CorrelationTest:
    """Is the residual white? r_ee over lags 0..L, lags 1..L tested against the 99 % bound."""
    L = _check_lags(lags)
    parts = _pieces("e", e)
    n = sum(a.size for a in parts)
    lag = np.arange(L + 1)
    return _test(lag, autocorrelation(parts, L), lag > 0, n, len(parts))


def independence_test(u: Series, e: Series, lags: int) -> CorrelationTest:
    """Is the residual independent of the input? r_ue over lags -L..L, all tested against the 99 % bound."""
    L = _check_lags(lags)
    up, ep = _pieces("u", u), _pieces("e", e)
    n = sum(a.size for a in ep)
    lag = np.arange(-L, L + 1)
    return _test(lag, cross_correlation(up, ep, L), np.ones(lag.size, dtype=np.bool_), n, len(ep))


def fit_percent(truth: np.ndarray, estimate: np.ndarray) -> np.ndarray:
    """NRMSE fit per state, (n,): 100 (1 - ||x_j - x̂_j|| / ||x_j - mean(x_j)||) = 100 (1 - RRSE_j),
    over all T rows of ``truth`` and ``estimate`` (T, n) float, finite; NaN for a constant truth."""
    return 100.0 * (1.0 - rrse(truth, estimate))


def divergence_range(X: np.ndarray, valid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per state, the range a simulation may wander in before it counts as diverged, (n,) each:

        [lo - w, hi + w],  lo, hi = min and max of the valid measurements of the state,
        w = hi - lo (its span), or max(|lo|, |hi|, 1) where the state never moves (w = 0).

    A state with no valid measurement has the whole real line.
    """
    if not isinstance(X, np.ndarray) or X.ndim != 2 or X.dtype.kind != "f":
        raise ValueError("X: expected a 2-D floating-point numpy array (T, n)")
    if not isinstance(valid, np.ndarray) or valid.dtype != np.bool_ or valid.shape != X.shape:
        raise ValueError(f"valid: expected a bool array of shape {X.shape}")
    n = X.shape[1]
    low, high = np.full(n, -np.inf), np.full(n, np.inf)
    for j in range(n):
        x = X[valid[:, j], j].astype(np.float64)
        if x.size:
            lo, hi = float(x.min()), float(x.max())
            w = hi - lo if hi > lo else max(abs(lo), abs(hi), 1.0)
            low[j], high[j] = lo - w, hi + w
    return low, high


def departure(estimate: np.ndarray, rows: np.ndarray, low: np.ndarray, high: np.ndarray) -> np.ndarray:
    """Per state, the first of the ``rows`` (bool (T,)) where ``estimate`` (T, n) is not finite or
    outside [low_j, high_j] (:func:`divergence_range`); -1 where it stays within. (n,) int64."""
    if not isinstance(estimate, np.ndarray) or estimate.ndim != 2 or estimate.dtype.kind != "f":
        raise ValueError("estimate: expected a 2-D floating-point numpy array (T, n)")
    T, n = estimate.shape
    if not isinstance(rows, np.ndarray) or rows.dtype != np.bool_ or rows.shape != (T,):
        raise ValueError(f"rows: expected a bool array of shape ({T},)")
    for name, b in (("low", low), ("high", high)):
        if not isinstance(b, np.ndarray) or b.shape != (n,) or b.dtype.kind != "f":
            raise ValueError(f"{name}: expected a floating-point array of shape ({n},)")
    x = estimate.astype(np.float64)
    with np.errstate(invalid="ignore"):
        out_of_range = ~np.isfinite(x) | (x < low) | (x > high)
    out_of_range &= rows[:, None]
    first = np.full(n, -1, dtype=np.int64)
    for j in range(n):
        hits = np.flatnonzero(out_of_range[:, j])
        if hits.size:
            first[j] = int(hits[0])
    return first
