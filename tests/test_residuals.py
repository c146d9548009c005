"""pyrhonn.residuals: the correlation estimates equal numpy.correlate and a direct loop over the
pairs inside each stretch; white noise passes the whiteness and independence tests at about the
nominal 1 % rate while a sine or an input echo fails them; the verdict's count is the binomial
tail; fit, divergence range and departure are the documented formulas; bad input is refused."""
from __future__ import annotations

import math
from statistics import NormalDist

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from scipy.stats import binom, norm

from pyrhonn.residuals import (Z_99, allowed_outside, autocorrelation, confidence_bound, cross_correlation,
                               departure, divergence_range, fit_percent, independence_test, peak_bound, stretches,
                               usable_residuals, whiteness_test)

FINITE = st.floats(-1e3, 1e3, allow_nan=False, allow_infinity=False)


def series(min_size: int = 3, max_size: int = 120) -> st.SearchStrategy[np.ndarray]:
    return hnp.arrays(np.float64, st.integers(min_size, max_size), elements=FINITE)


def spread(a: np.ndarray) -> bool:
    """Far from constant, so that the normalisation is well conditioned."""
    return bool(np.std(a) > 1e-3 * (np.max(np.abs(a)) + 1.0))


def direct_pairs(u: list[np.ndarray], e: list[np.ndarray], tau: int) -> float:
    """sum over every stretch s and k with both k and k + tau inside it of
    (u_s[k] - ubar)(e_s[k + tau] - ebar), means pooled over every stretch, by plain loops."""
    ubar = sum(float(x) for s in u for x in s) / sum(len(s) for s in u)
    ebar = sum(float(x) for s in e for x in s) / sum(len(s) for s in e)
    total = 0.0
    for us, es in zip(u, e):
        for k in range(len(us)):
            if 0 <= k + tau < len(es):
                total += (float(us[k]) - ubar) * (float(es[k + tau]) - ebar)
    return total


@settings(max_examples=60, deadline=None)
@given(e=series(), lags=st.integers(1, 40))
def test_autocorrelation_of_one_stretch_is_numpy_correlate_normalised(e: np.ndarray, lags: int) -> None:
    assume(spread(e))
    a = e - e.mean()
    full = np.correlate(a, a, mode="full")  # full[N - 1 + tau] = sum_k a[k + tau] a[k]
    N = e.size
    expected = np.zeros(lags + 1)
    top = min(lags, N - 1)
    expected[:top + 1] = full[N - 1:N + top] / full[N - 1]
    np.testing.assert_allclose(autocorrelation(e, lags), expected, rtol=0, atol=1e-9)


@settings(max_examples=60, deadline=None)
@given(u=series(), seed=st.integers(0, 2**32 - 1), lags=st.integers(1, 30))
def test_cross_correlation_of_one_stretch_is_numpy_correlate_normalised(u: np.ndarray, seed: int, lags: int) -> None:
    e = np.random.default_rng(seed).normal(size=u.size) * 3.0 + 1.0
    assume(spread(u) and spread(e))
    a, b = u - u.mean(), e - e.mean()
    N = u.size
    full = np.correlate(b, a, mode="full")  # full[N - 1 + tau] = sum_k b[k + tau] a[k] = N c_ue(tau)
    expected = np.zeros(2 * lags + 1)
    for tau in range(-lags, lags + 1):
        if abs(tau) < N:
            expected[lags + tau] = full[N - 1 + tau]
    expected /= math.sqrt(float(a @ a) * float(b @ b))
    np.testing.assert_allclose(cross_correlation(u, e, lags), expected, rtol=0, atol=1e-9)


@settings(max_examples=40, deadline=None)
@given(data=st.data(), count=st.integers(1, 5), lags=st.integers(1, 12))
def test_pooled_stretches_match_a_direct_loop_over_pairs_inside_each_stretch(data: st.DataObject, count: int,
                                                                              lags: int) -> None:
    lengths = [data.draw(st.integers(1, 25)) for _ in range(count)]
    u = [data.draw(hnp.arrays(np.float64, n, elements=FINITE)) for n in lengths]
    e = [data.draw(hnp.arrays(np.float64, n, elements=FINITE)) for n in lengths]
    assume(spread(np.concatenate(u)) and spread(np.concatenate(e)))
    N = sum(lengths)
    cee0, cuu0 = direct_pairs(e, e, 0) / N, direct_pairs(u, u, 0) / N
    auto = [direct_pairs(e, e, tau) / N / cee0 for tau in range(lags + 1)]
    cross = [direct_pairs(u, e, tau) / N / math.sqrt(cuu0 * cee0) for tau in range(-lags, lags + 1)]
    np.testing.assert_allclose(autocorrelation(e, lags), auto, rtol=0, atol=1e-9)
    np.testing.assert_allclose(cross_correlation(u, e, lags), cross, rtol=0, atol=1e-9)


@settings(max_examples=60, deadline=None)
@given(u=series(), seed=st.integers(0, 2**32 - 1), lags=st.integers(1, 30))
def test_swapping_the_series_mirrors_the_lags_about_zero(u: np.ndarray, seed: int, lags: int) -> None:
    e = np.random.default_rng(seed).uniform(-5.0, 5.0, u.size)
    assume(spread(u) and spread(e))
    np.testing.assert_allclose(cross_correlation(e, u, lags), cross_correlation(u, e, lags)[::-1], rtol=0, atol=1e-12)


@settings(max_examples=60, deadline=None)
@given(e=series(), scale=st.floats(1e-3, 1e3), offset=FINITE, lags=st.integers(1, 30))
def test_correlations_are_within_one_and_ignore_scale_and_offset(e: np.ndarray, scale: float, offset: float,
                                                                 lags: int) -> None:
    assume(spread(e))
    r = autocorrelation(e, lags)
    assert r[0] == pytest.approx(1.0) and np.all(np.abs(r) <= 1.0 + 1e-12)
    np.testing.assert_allclose(autocorrelation(scale * e + offset, lags), r, rtol=0, atol=1e-7)
    np.testing.assert_allclose(autocorrelation(-e, lags), r, rtol=0, atol=1e-12)
    u = np.roll(e, 3)
    np.testing.assert_allclose(cross_correlation(u, -e, lags), -cross_correlation(u, e, lags), rtol=0, atol=1e-12)


def test_white_noise_passes_whiteness_and_independence_at_about_the_nominal_rate() -> None:
    """Under the null hypothesis each lag is outside the 99 % bound about 1 % of the time and
    the verdict rejects at most about 1 % of the time (fixed seeds: the counts are exact)."""
    N, L, trials = 400, 20, 300
    outside = rejected = tested = cross_outside = cross_rejected = cross_tested = 0
    for seed in range(trials):
        rng = np.random.default_rng(seed)
        e, u = rng.normal(size=N), rng.uniform(-1.0, 1.0, N)
        w = whiteness_test(e, L)
        c = independence_test(u, e, L)
        outside += w.outside
        tested += w.tested
        rejected += not w.passed
        cross_outside += c.outside
        cross_tested += c.tested
        cross_rejected += not c.passed
    assert 0.004 < outside / tested < 0.016
    assert 0.004 < cross_outside / cross_tested < 0.016
    assert rejected / trials <= 0.03 and cross_rejected / trials <= 0.03


@settings(max_examples=40, deadline=None)
@given(period=st.floats(6.0, 80.0), phase=st.floats(0.0, 2 * math.pi), N=st.integers(300, 2000),
       amplitude=st.floats(0.01, 100.0), seed=st.integers(0, 2**32 - 1))
def test_a_sine_residual_is_not_white(period: float, phase: float, N: int, amplitude: float, seed: int) -> None:
    k = np.arange(N)
    e = amplitude * (np.sin(2 * math.pi * k / period + phase)
                     + 0.1 * np.random.default_rng(seed).normal(size=N))
    test = whiteness_test(e, 25)
    assert test.passed is False and test.outside > test.allowed


@settings(max_examples=40, deadline=None)
@given(delay=st.integers(0, 10), gain=st.floats(0.3, 3.0), seed=st.integers(0, 2**32 - 1))
def test_a_residual_that_echoes_the_input_is_correlated_with_it(delay: int, gain: float, seed: int) -> None:
    rng = np.random.default_rng(seed)
    u = rng.uniform(-1.0, 1.0, 1000)
    e = 0.1 * rng.normal(size=u.size)
    e[delay:] += gain * u[:u.size - delay]  # the model missed u(k - delay)'s effect on x(k)
    test = independence_test(u, e, 25)
    assert test.passed is False
    assert int(test.lags[np.argmax(np.abs(test.values))]) == delay
    assert abs(test.values[25 + delay]) > test.bound


def test_the_bound_is_z_over_root_n_and_the_allowed_count_the_binomial_tail() -> None:
    assert confidence_bound(400) == pytest.approx(Z_99 / 20.0)
    assert Z_99 == pytest.approx(NormalDist().inv_cdf(0.995), abs=5e-4)
    for M in (1, 5, 20, 25, 51, 101, 400):
        m = allowed_outside(M)
        assert binom.sf(m, M, 0.01) <= 0.005 + 1e-15
        assert m == 0 or binom.sf(m - 1, M, 0.01) > 0.005
        # every one of M standard normal lags within z_M with probability 1 - 0.005 (Bonferroni)
        z_M = peak_bound(400, M) * 20.0
        assert 2 * M * norm.sf(z_M) == pytest.approx(0.005, rel=1e-9)
    assert allowed_outside(25) == 2 and allowed_outside(51) == 3


def test_a_constant_residual_has_no_correlation_and_no_verdict() -> None:
    e = np.full(50, 2.5)
    assert np.all(np.isnan(autocorrelation(e, 5)))
    assert whiteness_test(e, 5).passed is None
    assert independence_test(np.linspace(0.0, 1.0, 50), e, 5).passed is None


def test_lags_longer_than_every_stretch_read_zero() -> None:
    e = [np.array([1.0, -1.0, 2.0]), np.array([0.5, -3.0])]
    r = autocorrelation(e, 6)
    assert np.all(r[3:] == 0.0) and r[0] == 1.0


def test_stretches_are_the_runs_of_usable_samples() -> None:
    x = np.arange(10, dtype=np.float64)
    usable = np.array([1, 1, 0, 1, 0, 0, 1, 1, 1, 0], dtype=bool)
    got = stretches(x, usable)
    assert [list(s) for s in got] == [[0.0, 1.0], [3.0], [6.0, 7.0, 8.0]]


@settings(max_examples=50, deadline=None)
@given(valid=hnp.arrays(np.bool_, st.tuples(st.integers(1, 40), st.integers(1, 3)), elements=st.booleans()),
       first=st.integers(0, 6), depth=st.integers(0, 4))
def test_usable_residuals_need_a_valid_target_and_measured_taps(valid: np.ndarray, first: int, depth: int) -> None:
    T, n = valid.shape
    expected = np.zeros_like(valid)
    for k in range(T):
        for i in range(n):
            rows = range(k - 1 - depth, k)
            expected[k, i] = (k >= first and valid[k, i] and k - 1 - depth >= 0
                              and all(valid[r].all() for r in rows))
    np.testing.assert_array_equal(usable_residuals(valid, first, depth), expected)


def test_fit_is_the_nrmse_fit_of_matlab_compare() -> None:
    rng = np.random.default_rng(4)
    x = rng.normal(size=(200, 2)) * [1.0, 10.0] + [0.0, 5.0]
    xh = x + rng.normal(size=x.shape) * [0.1, 4.0]
    expected = [100.0 * (1.0 - np.linalg.norm(x[:, j] - xh[:, j]) / np.linalg.norm(x[:, j] - x[:, j].mean()))
                for j in range(2)]
    np.testing.assert_allclose(fit_percent(x, xh), expected, rtol=1e-12)
    assert fit_percent(x, x)[0] == 100.0
    assert fit_percent(x, np.tile(x.mean(axis=0), (200, 1)))[0] == pytest.approx(0.0, abs=1e-12)


def test_departure_is_the_first_sample_beyond_the_widened_range_or_not_finite() -> None:
    X = np.array([[0.0, 3.0], [1.0, 3.0], [2.0, 3.0], [np.nan, 3.0]])
    valid = np.array([[1, 1], [1, 1], [1, 1], [0, 1]], dtype=bool)
    low, high = divergence_range(X, valid)
    np.testing.assert_array_equal(low, [-2.0, 0.0])   # span 2; a constant state: widened by |3|
    np.testing.assert_array_equal(high, [4.0, 6.0])
    est = np.array([[9.0, 3.0], [3.9, 3.0], [4.1, 6.0], [0.0, np.inf]])
    rows = np.array([False, True, True, True])
    np.testing.assert_array_equal(departure(est, rows, low, high), [2, 3])  # row 0 is not checked
    np.testing.assert_array_equal(departure(est[:2], rows[:2], low, high), [-1, -1])


@pytest.mark.parametrize("call, message", [
    (lambda: autocorrelation(np.arange(5), 2), "expected a floating-point array"),
    (lambda: autocorrelation(np.array([1.0, np.nan, 2.0]), 2), "e[1]: must be finite"),
    (lambda: autocorrelation(np.ones((3, 2)), 2), "expected a 1-D array"),
    (lambda: autocorrelation(np.ones(5), 0), "lags: must be >= 1"),
    (lambda: autocorrelation([], 3), "e: no samples"),
    (lambda: cross_correlation(np.ones(4), [np.ones(2), np.ones(2)], 1), "stretch lengths"),
    (lambda: stretches(np.ones(3), np.ones(3)), "usable: expected a bool array"),
])
def test_bad_input_is_refused_naming_the_argument(call, message: str) -> None:
    with pytest.raises(ValueError, match=None) as info:
        call()
    assert message in str(info.value)
