"""RMSE and absolute deviation per state."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from pyrhonn.metrics import absolute_deviation, rmse

TRUTH = np.array([[1.0, 0.0], [2.0, 0.0], [3.0, 0.0], [4.0, 0.0]])
ESTIMATE = np.array([[1.0, 1.0], [1.0, -1.0], [4.0, 1.0], [2.0, -1.0]])
# errors e = truth - estimate: column 0 = [0, 1, -1, 2], column 1 = [-1, 1, -1, 1]


def test_rmse_on_a_hand_computed_example():
    # column 0: sqrt((0 + 1 + 1 + 4) / 4) = sqrt(1.5); column 1: sqrt(4 / 4) = 1
    np.testing.assert_allclose(rmse(TRUTH, ESTIMATE), [math.sqrt(1.5), 1.0], rtol=1e-15)


def test_absolute_deviation_on_a_hand_computed_example():
    # column 0: mean 0.5, |e - 0.5| = [0.5, 0.5, 1.5, 1.5] -> 1.0; column 1: mean 0, |e| = 1 -> 1.0
    np.testing.assert_allclose(absolute_deviation(TRUTH, ESTIMATE), [1.0, 1.0], rtol=1e-15)


def test_absolute_deviation_equals_matlab_mad_default():
    # MATLAB: mad([1 2 3 4 10]) = 2.4 (mean 4, deviations 3 2 1 0 6)
    e = np.array([1.0, 2.0, 3.0, 4.0, 10.0])[:, None]
    assert absolute_deviation(e, np.zeros_like(e))[0] == pytest.approx(2.4, rel=1e-15)


def test_warmup_drops_the_first_samples():
    # warmup 2: column 0 errors [-1, 2]: rmse sqrt(5/2), mean 0.5, deviations 1.5, 1.5
    np.testing.assert_allclose(rmse(TRUTH, ESTIMATE, warmup=2), [math.sqrt(2.5), 1.0], rtol=1e-15)
    np.testing.assert_allclose(absolute_deviation(TRUTH, ESTIMATE, warmup=2), [1.5, 1.0], rtol=1e-15)
    np.testing.assert_array_equal(rmse(TRUTH, ESTIMATE, warmup=0), rmse(TRUTH, ESTIMATE))


def test_constant_bias_counts_in_rmse_but_not_in_absolute_deviation():
    truth = np.linspace(0, 1, 50)[:, None] * np.ones((1, 3))
    estimate = truth + np.array([0.5, -2.0, 0.0])
    np.testing.assert_allclose(rmse(truth, estimate), [0.5, 2.0, 0.0], rtol=1e-12)
    np.testing.assert_allclose(absolute_deviation(truth, estimate), 0.0, atol=1e-12)


def test_float32_inputs_are_accepted_and_measured_in_float64():
    out = rmse(TRUTH.astype(np.float32), ESTIMATE.astype(np.float32))
    assert out.dtype == np.float64 and out.shape == (2,)


finite = st.floats(-1e3, 1e3, allow_nan=False, allow_infinity=False)
pairs = st.integers(1, 30).flatmap(
    lambda T: st.integers(1, 4).flatmap(
        lambda n: st.tuples(hnp.arrays(np.float64, (T, n), elements=finite),
                            hnp.arrays(np.float64, (T, n), elements=finite))))


@settings(max_examples=200, deadline=None)
@given(pairs)
def test_absolute_deviation_never_exceeds_std_which_never_exceeds_rmse(pair):
    truth, estimate = pair
    e = truth - estimate
    ad, r = absolute_deviation(truth, estimate), rmse(truth, estimate)
    sd = np.std(e, axis=0)
    assert ad.shape == r.shape == (truth.shape[1],)
    assert np.all(ad <= sd * (1 + 1e-9) + 1e-9)
    assert np.all(sd <= r * (1 + 1e-9) + 1e-9)
    np.testing.assert_allclose(r ** 2, np.mean(e, axis=0) ** 2 + sd ** 2, rtol=1e-9, atol=1e-6)


@settings(max_examples=100, deadline=None)
@given(pairs, finite, st.floats(0.01, 100.0))
def test_absolute_deviation_ignores_offsets_and_scales_with_the_error(pair, offset, scale):
    truth, estimate = pair
    base = absolute_deviation(truth, estimate)
    np.testing.assert_allclose(absolute_deviation(truth, estimate + offset), base, rtol=1e-7, atol=1e-7)
    np.testing.assert_allclose(absolute_deviation(scale * truth, scale * estimate), scale * base,
                               rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(rmse(scale * truth, scale * estimate), scale * rmse(truth, estimate),
                               rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("metric", [rmse, absolute_deviation])
@pytest.mark.parametrize(
    "truth, estimate, warmup, field",
    [
        (TRUTH, ESTIMATE[:3], 0, "estimate"),
        (TRUTH[:, 0], ESTIMATE[:, 0], 0, "truth"),
        (TRUTH.tolist(), ESTIMATE, 0, "truth"),
        (TRUTH.astype(int), ESTIMATE, 0, "truth"),
        (TRUTH, np.where(np.arange(8).reshape(4, 2) == 7, np.nan, ESTIMATE), 0, r"estimate\[3, 1\]"),
        (np.where(np.arange(8).reshape(4, 2) == 2, np.inf, TRUTH), ESTIMATE, 0, r"truth\[1, 0\]"),
        (TRUTH, ESTIMATE, 4, "warmup"),
        (TRUTH, ESTIMATE, -1, "warmup"),
        (TRUTH, ESTIMATE, 1.0, "warmup"),
        (TRUTH, ESTIMATE, True, "warmup"),
        (np.zeros((4, 0)), np.zeros((4, 0)), 0, "truth"),
    ],
)
def test_bad_inputs_raise_value_error_naming_the_argument(metric, truth, estimate, warmup, field):
    with pytest.raises(ValueError, match=rf"^{field}"):
        metric(truth, estimate, warmup=warmup)


def test_errors_near_the_float64_limit_give_finite_metrics_without_warnings() -> None:
    import warnings

    truth = np.array([[1e308, 1.0], [-1e308, 2.0], [0.0, 3.0]])
    estimate = np.zeros((3, 2))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no numpy overflow warning leaks to a user's terminal
        r, ad = rmse(truth, estimate), absolute_deviation(truth, estimate)
        np.testing.assert_allclose(r, [math.sqrt(2.0 / 3.0) * 1e308, math.sqrt(14.0 / 3.0)], rtol=1e-15)
        np.testing.assert_allclose(ad, [2.0 / 3.0 * 1e308, 2.0 / 3.0], rtol=1e-15)
        apart = np.array([[1e308], [-1e308]])  # truth and estimate beyond float64 apart: the error is inf
        assert rmse(apart, -apart)[0] == np.inf and absolute_deviation(apart, -apart)[0] == np.inf
