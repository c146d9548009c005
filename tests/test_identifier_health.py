"""Filter health (innovation, e^2/s, trace P, counters) and restart after a
break in the sample stream, on both builds of the core; the innovation gate
(a neuron skips an update whose e^2/s exceeds its gate, counted in health)."""
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


# -- the innovation gate (rhonn.h INNOVATION GATE) -------------------------------------------------


def linear_plant(T: int, dtype: str) -> tuple[np.ndarray, np.ndarray]:
    """x(k+1) = A x(k) + B u(k): the identifier's terms [x1, x2, u1, 1] hold it exactly."""
    A, B = np.array([[0.6, 0.3], [0.4, 0.5]]), np.array([0.5, -0.3])
    k = np.arange(T)
    U = (np.sin(0.1 * k) + 0.5 * np.sin(0.37 * k))[:, None]
    X = np.empty((T, 2))
    X[0] = [0.1, -0.2]
    for t in range(T - 1):
        X[t + 1] = A @ X[t] + B * U[t, 0]
    return X.astype(dtype), U.astype(dtype)


def gate_config(dtype: str, gate: float) -> IdentifierConfig:
    from dataclasses import replace

    from pyrhonn import CovarianceForm

    config = IdentifierConfig.uniform(terms.first_order(2, 1) + terms.bias(), n_states=2, n_inputs=1, p0=10.0,
                                      q=1e-6, r=0.1, dtype=dtype, gate=gate)
    raw = tuple(replace(nr, terms=tuple(((f if f.kind.name != "S" else type(f).x(f.index)),) for (f,) in nr.terms),
                        covariance=CovarianceForm.UD if i else CovarianceForm.FULL)
                for i, nr in enumerate(config.neurons))
    return config.replace(neurons=raw)


@pytest.mark.parametrize("dtype", DTYPES)
def test_the_gate_keeps_a_1e6_outlier_out_of_every_weight_and_counts_it(dtype: str) -> None:
    """Gate 9 (chi-square 1 dof at 99.7 %): x1 + 1e6 at sample 300 is learned
    by no neuron. At that sample neuron 0 (whose innovation it is) skips its
    update, and neuron 1 (whose update reads no x1(300)) learns exactly what
    a twin fed the true sample learns; at the next sample both neurons'
    regressors hold the outlier and both skip. So every weight and
    covariance is what the true data taught, nothing of the outlier; no step
    failed, health counts 2 + 1 gated updates, and learning goes on after.
    With the gate off the same outlier is learned: the weights jump."""
    X, U = linear_plant(400, dtype)
    gated, open_ = Identifier(gate_config(dtype, 9.0)), Identifier(gate_config(dtype, 0.0))
    twin = Identifier(gate_config(dtype, 9.0))
    for ident in (gated, open_, twin):
        ident.run(X[:300], U[:300])
    assert [h.gated for h in gated.healths] == [0, 0]  # no good sample gated

    def state(ident: Identifier, i: int) -> tuple[bytes, bytes]:
        return ident.get_weights(i).tobytes(), ident.get_covariance(i).tobytes()

    neuron0 = state(gated, 0)
    bad = X[300].copy()
    bad[0] += np.asarray(1e6, dtype=dtype)
    gated.step(bad, U[300])
    twin.step(X[300], U[300])
    assert gated.health(0).gated == 1 and gated.health(0).nis > 9.0
    assert state(gated, 0) == neuron0 and state(gated, 1) == state(twin, 1)
    after = [state(gated, 0), state(gated, 1)]
    gated.step(X[301], U[301])  # z(300) read the outlier, in both neurons
    assert [state(gated, 0), state(gated, 1)] == after
    assert [h.gated for h in gated.healths] == [2, 1] and all(h.rejected == 0 for h in gated.healths)
    gated.run(X[302:], U[302:])
    assert [h.updates for h in gated.healths] == [399 - 2, 399 - 1]
    w_before = open_.weights
    open_.step(bad, U[300])
    jump = max(float(np.max(np.abs(a.astype(np.float64) - b))) for a, b in zip(open_.weights, w_before))
    assert jump > 1.0 and open_.health(0).gated == 0


@pytest.mark.parametrize("dtype", DTYPES)
def test_the_gate_follows_the_numpy_reference_and_is_off_by_default(dtype: str) -> None:
    from pyrhonn.reference import ReferenceIdentifier

    assert small_config(dtype).neurons[0].gate == 0.0
    config = small_config(dtype, gate=6.0, forgetting=0.97)
    X, U, _ = trajectory(seed=9, T=300, n=2, m=1, dtype=dtype)
    X[[60, 61, 150, 220]] += np.asarray(25.0, dtype=dtype)  # outliers, one right after another
    ident, ref = Identifier(config), ReferenceIdentifier(config)
    got = ident.run(X, U)
    want = ref.run(X, U)
    tol = 1e-3 if dtype == "float32" else 1e-8
    np.testing.assert_allclose(got, want, rtol=tol, atol=tol)
    assert sum(h.gated for h in ident.healths) >= 4
