"""The Python API on your own numpy arrays: build an identifier, learn a
recording in one call, continue sample by sample, save and resume.

    python examples/python_api.py

The arrays here come from a small synthetic plant; put your own (T, n) states,
(T, m) inputs and (T, n) validity flags in their place. Exits 1 if a check
fails.
"""
from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np

from pyrhonn import Activation, Identifier, IdentifierConfig, terms


def recording(T: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """X (T, 2), U (T, 1) and valid (T, 2) of a coupled nonlinear plant, with a short dropout."""
    rng = np.random.default_rng(seed)
    U = (np.sin(0.01 * np.arange(T)) + 0.1 * rng.standard_normal(T))[:, None]
    X = np.zeros((T, 2))
    for k in range(T - 1):
        X[k + 1, 0] = 0.9 * X[k, 0] + 0.2 * np.tanh(X[k, 1])
        X[k + 1, 1] = 0.7 * X[k, 1] + 0.5 * U[k, 0]
    valid = np.ones((T, 2), dtype=bool)
    valid[1500:1510, 0] = False          # state 0 not measured: the identifier uses its own prediction
    X[1500:1510, 0] = np.nan
    return X, U, valid


def main() -> int:
    X, U, valid = recording(3000)
    cfg = IdentifierConfig.uniform(
        terms.first_order(2, 1) + terms.pairwise_products([0, 1]),   # S(x1), S(x2), u1, S(x1) S(x2)
        n_states=2, n_inputs=1, activation=Activation.BIPOLAR, beta=1.0, p0=100.0, q=1e-4, r=1e-2)

    # learn the first 2,000 samples in one C call; row t is the prediction of sample t + 1
    ident = Identifier(cfg)
    Xhat = ident.run(X[:2000], U[:2000], valid[:2000])
    scored = valid[1001:2000]
    rmse = np.sqrt(np.mean((X[1001:2000][scored] - Xhat[1000:1999][scored]) ** 2))
    print(f"one-step RMSE over samples 1001-1999: {rmse:.3g}")

    # save the whole filter, then continue both the original and the restored one sample by sample
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "state.npz"
        ident.save(path)
        resumed = Identifier.load(path)
    same = True
    for k in range(2000, 3000):
        a = ident.step(X[k], U[k], valid[k])
        b = resumed.step(X[k], U[k], valid[k])
        same &= bool(np.array_equal(a, b))
    print(f"the restored identifier continues bit for bit: {same}")

    for i in range(cfg.n_states):
        h = ident.health(i)
        print(f"neuron {i}: {h.updates} updates, {h.rejected} refused, trace P {h.trace_p:.3g}")
    ok = same and rmse < 0.05
    print("OK" if ok else "NOT AS STATED")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
