"""Filter health (innovation, e^2/s, trace P, counters) and restart after a
break in the sample stream, on both builds of the core."""
from __future__ import annotations

import numpy as np
import pytest

from pyrhonn import Activation, Identifier, IdentifierConfig, IdentifierError, terms
from pyrhonn.configfile import load_shipped

from strategies import trajectory

DTYPES = ["float32", "float64"]


def small_config(dtype: str, **neuron_fields) -> IdentifierConfig:
    return IdentifierConfig.uniform(terms.first_order(2, 1), n_states=2, n_inputs=1,
                                    activation=Activation.LOGISTIC, beta=1.0, p0=10.0, q=1e-3, r=0.1,
                                    dtype=dtype, **neuron_fields)


@pytest.mark.parametrize("dtype", DTYPES)
def test_health_reports_the_innovation_and_its_normalised_square(dtype: str) -> None:
    ident = Identifier(small_config(dtype))
    X, U, _ = trajectory(seed=3, T=40, n=2, m=1, dtype=dtype)
    for k in range(39):
        ident.step(X[k], U[k])
    P = [ident.get_covariance(i).astype(np.float64) for i in range(2)]
    z = [r.astype(np.float64) for r in ident.regressors]
    xhat = ident.prediction.astype(np.float64)
    ident.step(X[39], U[39])
    for i in range(2):
        h = ident.health(i)
        e = float(X[39, i]) - xhat[i]
        s = 0.1 + z[i] @ P[i] @ z[i]
        tol = 1e-4 if dtype == "float32" else 1e-10
        assert h.innovation == pytest.approx(e, rel=tol, abs=tol)
        assert h.nis == pytest.approx(e * e / s, rel=10 * tol, abs=tol)
        assert h.trace_p == pytest.approx(float(np.trace(ident.get_covariance(i))), rel=tol)
        assert h.updates == 39 and h.rejected == 0 and h.fail_run == 0


@pytest.mark.parametrize("dtype", DTYPES)
def test_a_refused_update_is_counted_and_a_good_one_clears_the_run(dtype: str) -> None:
    ident = Identifier(small_config(dtype))
    x = np.array([0.5, 0.2], dtype=dtype)
    u = np.array([1.0], dtype=dtype)
    ident.step(x, u)
    ident.step(x, u)
    # A measurement near the top of the range: the weight update of neuron 0
    # overflows (weights would not be finite) and is refused.
    big = np.finfo(dtype).max / 4
    w_before = ident.get_weights(0)
    huge_x = np.array([big, 0.2], dtype=dtype)
    for failures in (1, 2):
        with pytest.raises(IdentifierError):
            ident.step(huge_x, u)
        h = ident.health(0)
        assert h.rejected == failures and h.fail_run == failures
        np.testing.assert_array_equal(ident.get_weights(0), w_before)
    ident.step(x, u)
    h = ident.health(0)
    assert h.rejected == 2 and h.fail_run == 0 and h.updates == 2


@pytest.mark.parametrize("dtype", DTYPES)
def test_health_rejects_a_bad_neuron_index(dtype: str) -> None:
    ident = Identifier(small_config(dtype))
    for bad in (-1, 2, 1.0, True, "0"):
        with pytest.raises(ValueError, match="neuron"):
            ident.health(bad)  # type: ignore[arg-type]


@pytest.mark.parametrize("dtype", DTYPES)
def test_after_restart_the_next_step_learns_nothing_and_refills_the_delayed_taps(dtype: str) -> None:
    config = load_shipped("example1").config.replace(dtype=dtype)
    ident = Identifier(config)
    X, U, _ = trajectory(seed=5, T=60, n=4, m=1, dtype=dtype)
    ident.run(X[:50], U[:50])
    weights = [w.copy() for w in ident.weights]
    covs = [P.copy() for P in ident.covariances]
    ident.restart()
    got = ident.step(X[55], U[55])  # samples 50..54 lost
    for i in range(4):
        np.testing.assert_array_equal(ident.get_weights(i), weights[i])
        np.testing.assert_array_equal(ident.get_covariance(i), covs[i])
    # The same as a fresh identifier holding the learnt weights and P, whose
    # first step has a constant history: nothing of samples before 50 is used.
    fresh = Identifier(config)
    for i in range(4):
        fresh.set_weights(i, weights[i])
        fresh.set_covariance(i, covs[i])
    np.testing.assert_array_equal(got, fresh.step(X[55], U[55]))
    # and learning resumes on the step after
    ident.step(X[56], U[56])
    assert any(not np.array_equal(ident.get_weights(i), weights[i]) for i in range(4))
