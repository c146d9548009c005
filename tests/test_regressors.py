"""Regressors of a trajectory in NumPy, against the C core's, and the refit of w0 for a new S."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pyrhonn import Identifier
from pyrhonn.config import Activation, Factor, IdentifierConfig, NeuronConfig
from pyrhonn.regressors import refit_w0, regressor_matrix, usable_rows

TERMS = ((Factor.x(0),), (Factor.s(0, delay=2), Factor.u(0, delay=1)), (Factor.s(1, power=2),),
         (Factor.u(0, 2),), (Factor.one(),))


def config(activation: Activation, beta: float, w0: np.ndarray | None = None) -> IdentifierConfig:
    nr = NeuronConfig(terms=TERMS, activation=activation, beta=beta,
                      w0=np.zeros(len(TERMS)) if w0 is None else w0)
    return IdentifierConfig(n_states=2, n_inputs=1, neurons=(nr, NeuronConfig(terms=((Factor.x(1),),))))


def trajectory(T: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    return rng.uniform(-2.0, 2.0, (T, 2)), rng.uniform(-1.0, 1.0, (T, 1))


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**31), beta=st.floats(0.1, 5.0), bipolar=st.booleans())
def test_the_regressor_matrix_is_the_core_s_regressor(seed: int, beta: float, bipolar: bool) -> None:
    X, U = trajectory(40, seed)
    cfg = config(Activation.BIPOLAR if bipolar else Activation.LOGISTIC, beta)
    ident = Identifier(cfg)
    ident.learning = False
    rows = np.arange(cfg.max_delay, 40)
    Z = regressor_matrix(cfg.neurons[0], X, U, rows)
    for k in range(40):
        ident.step(X[k], U[k])
        if k >= cfg.max_delay:  # before it the core's taps read the first sample
            np.testing.assert_allclose(ident.regressors[0], Z[k - cfg.max_delay], rtol=1e-12, atol=1e-14)


def test_refit_recovers_the_weights_of_a_plant_in_the_model_class() -> None:
    truth = config(Activation.LOGISTIC, 2.0, np.array([0.5, -0.7, 0.3, 0.2, -0.1]))
    X, U = trajectory(300, 1)
    for k in range(truth.max_delay, 299):  # x1(k+1) = w^T z(k), sample by sample (z(k) reads x1(k))
        X[k + 1, 0] = (regressor_matrix(truth.neurons[0], X, U, np.array([k])) @ truth.neurons[0].w0_vector())[0]
    valid = np.ones(X.shape, dtype=bool)
    stale = config(Activation.LOGISTIC, 1.0, np.array([0.5, -0.7, 0.3, 0.2, -0.1]))  # w0 fitted for beta 1
    trial = config(Activation.LOGISTIC, 2.0, stale.neurons[0].w0_vector())
    fitted = refit_w0(trial, X, U, valid, 300, stale)
    np.testing.assert_allclose(fitted.neurons[0].w0_vector(), truth.neurons[0].w0_vector(), atol=1e-10)
    assert fitted.neurons[1] == trial.neurons[1]  # the slope of neuron 2 did not change: w0 kept
    assert refit_w0(stale, X, U, valid, 300, stale) is stale  # nothing changed, nothing refitted


def test_refit_reads_only_the_samples_before_end_and_measured_rows() -> None:
    X, U = trajectory(200, 2)
    valid = np.ones(X.shape, dtype=bool)
    valid[50:55, 1] = False
    rows = usable_rows(config(Activation.BIPOLAR, 1.0), valid, 120)
    assert rows.max() == 118 and rows.min() == 2
    assert not np.any((rows >= 49) & (rows <= 56)) and 48 in rows and 57 in rows  # k-2..k+1 touch 50..54
    base, trial = config(Activation.BIPOLAR, 1.0), config(Activation.BIPOLAR, 3.0)
    a = refit_w0(trial, X, U, valid, 120, base)
    X2 = X.copy()
    X2[120:] = 1e6  # what lies after end changes nothing
    np.testing.assert_array_equal(refit_w0(trial, X2, U, valid, 120, base).neurons[0].w0_vector(),
                                  a.neurons[0].w0_vector())


def test_bad_arguments_are_named() -> None:
    X, U = trajectory(20, 3)
    with pytest.raises(ValueError, match="^X: "):
        regressor_matrix(config(Activation.BIPOLAR, 1.0).neurons[0], X.astype(np.float32), U, np.arange(2, 10))
    with pytest.raises(ValueError, match="^end: "):
        usable_rows(config(Activation.BIPOLAR, 1.0), np.ones((20, 2), dtype=bool), 21)
