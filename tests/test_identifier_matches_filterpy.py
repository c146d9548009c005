"""Each neuron's update is a scalar-measurement Kalman filter on its weights
(F = I, H = z^T): checked against filterpy's KalmanFilter, an independent
implementation (it even uses the Joseph form of the covariance update)."""
from __future__ import annotations

import numpy as np
from filterpy.kalman import KalmanFilter
from hypothesis import given, settings, strategies as st

from pyrhonn import FactorKind, Identifier, IdentifierConfig

from strategies import configs, trajectory

RTOL = 1e-9


def rel(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-12))


@settings(max_examples=20, deadline=None)
@given(cfg=configs(), seed=st.integers(0, 2**32 - 1))
def test_every_neuron_update_equals_filterpy_kalman_filter(cfg: IdentifierConfig, seed: int) -> None:
    cfg = cfg.replace(neurons=tuple(
        type(nr)(terms=nr.terms, activation=nr.activation, beta=nr.beta, p0=nr.p0, q=nr.q, r=nr.r, eta=1.0, w0=nr.w0)
        for nr in cfg.neurons))
    T = 300
    X, U, valid = trajectory(seed, T, cfg.n_states, cfg.n_inputs, 0.1)
    ident = Identifier(cfg)
    filters = []
    for nr in cfg.neurons:
        L = nr.n_terms
        kf = KalmanFilter(dim_x=L, dim_z=1)
        kf.x = nr.w0_vector().reshape(L, 1)
        kf.P = nr.p0_matrix()
        kf.Q = np.diag(nr.q_diagonal())
        kf.R = np.array([[nr.r]])
        kf.F = np.eye(L)
        filters.append(kf)
    for k in range(T):
        if k > 0:
            for i, (kf, z) in enumerate(zip(filters, ident.regressors)):
                # no learning where z_i(k-1) read a prediction of x_i at one of its own taps
                own = [f.delay for t in cfg.neurons[i].terms for f in t
                       if f.kind in (FactorKind.S, FactorKind.X) and f.index == i]
                own_measured = all(valid[max(k - 1 - d, 0), i] for d in range(max(own) + 1)) if own else True
                if valid[k, i] and own_measured:
                    kf.update(np.array([[X[k, i]]]), H=z.reshape(1, -1))
                    kf.predict()
        ident.step(X[k], U[k] if cfg.n_inputs else None, valid[k])
        if k % 25 == 0 or k == T - 1:
            for i, kf in enumerate(filters):
                assert rel(ident.get_weights(i), kf.x.ravel()) <= RTOL, f"w of neuron {i} at step {k}"
                assert rel(ident.get_covariance(i), kf.P) <= RTOL, f"P of neuron {i} at step {k}"
