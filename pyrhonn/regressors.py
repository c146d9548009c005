"""Regressors of a recorded trajectory, and initial weights fitted to them.

For neuron i of a config and a trajectory (X, U), the regressor at sample k
is the vector of its high-order terms (eq. 4-5),

    z_il(k) = prod_{f in I_l} xi_f(k - d_f) ^ p_f,
    xi = [S(x_1) .. S(x_n), x_1 .. x_n, u_1 .. u_m, 1],

S the neuron's activation at its slope beta (eq. 6 / eq. 19, as
:func:`pyrhonn.reference.activate` computes it). :func:`regressor_matrix`
stacks z_i(k) over rows k; :func:`refit_w0` fits w_i(0) by least squares,

    w_i(0) = argmin_w sum_k (x_i(k+1) - w^T z_i(k))^2,

over the rows whose taps and target are all measured. A config whose slope
or activation changed (a tuning trial) keeps a consistent starting point
this way: w(0) fitted for one S is not a fit for another.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from .config import FactorKind, IdentifierConfig, NeuronConfig
from .experiments import window_rows
from .reference import activate
from .validation import check_int, fail

__all__ = ["regressor_matrix", "usable_rows", "refit_w0"]


def usable_rows(config: IdentifierConfig, valid: np.ndarray, end: int) -> np.ndarray:
    """The rows k < end - 1 whose samples k - D .. k + 1 (D the config's deepest delay) are all measured."""
    end = check_int("end", end, 0, valid.shape[0])
    return window_rows(valid, config.max_delay, stop=end)


def regressor_matrix(neuron: NeuronConfig, X: np.ndarray, U: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """(len(rows), L_i): z_i(k) of ``neuron`` for every row k (X (T, n), U (T, m) float64, measured)."""
    if not isinstance(X, np.ndarray) or X.ndim != 2 or X.dtype != np.float64:
        raise fail("X", "expected a (T, n) float64 numpy array")
    if not isinstance(U, np.ndarray) or U.ndim != 2 or U.dtype != np.float64 or U.shape[0] != X.shape[0]:
        raise fail("U", f"expected a ({X.shape[0]}, m) float64 numpy array")
    Z = np.ones((rows.size, neuron.n_terms))
    S = None
    for col, term in enumerate(neuron.terms):
        for f in term:
            if f.kind is FactorKind.ONE:
                continue
            if f.kind is FactorKind.S:
                if S is None:
                    S = np.asarray(activate(neuron.activation, neuron.beta, X))
                src = S
            else:
                src = X if f.kind is FactorKind.X else U
            Z[:, col] *= src[rows - f.delay, f.index] ** f.power
    return Z


def refit_w0(config: IdentifierConfig, X: np.ndarray, U: np.ndarray, valid: np.ndarray, end: int,
             reference: IdentifierConfig) -> IdentifierConfig:
    """``config`` with w0 refitted by least squares on samples 0..end-1 for every neuron whose
    activation or beta differs from ``reference``'s (the others keep their w0). A neuron with
    fewer usable rows than twice its terms, or whose fit is not finite, keeps its w0."""
    if len(config.neurons) != len(reference.neurons):
        raise fail("reference", "expected a config with the same neurons")
    changed = [i for i, (a, b) in enumerate(zip(config.neurons, reference.neurons))
               if a.activation is not b.activation or a.beta != b.beta]
    if not changed:
        return config
    rows = usable_rows(config, valid, end)
    Xm = np.where(valid, X, 0.0)
    neurons = list(config.neurons)
    for i in changed:
        nr = neurons[i]
        if rows.size < 2 * nr.n_terms:
            continue
        Z = regressor_matrix(nr, Xm, U, rows)
        w, *_ = np.linalg.lstsq(Z, Xm[rows + 1, i], rcond=None)
        if np.all(np.isfinite(w)):
            neurons[i] = replace(nr, w0=w)
    return config.replace(neurons=tuple(neurons))
