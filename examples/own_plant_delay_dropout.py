"""Your own plant, with an input dead time and a sensor dropout, identified online.

The plant below stands for yours: two states, one input that acts only after
DEAD_TIME samples, and a position sensor that drops out for a stretch. The
script finds the dead time from the data (pyrhonn.search.dead_times), builds
the identifier with the input delayed by that dead time (terms written as a
config file writes them), identifies the plant online with the dropout flagged, and checks that
the identifier bridges the dropout: inside it, its prediction stays close to
the plant's true state, which it never saw there.

    python examples/own_plant_delay_dropout.py

Exits 1 (with the figures) if the identification is not as good as stated.
"""
from __future__ import annotations

import sys

import numpy as np

from pyrhonn import Activation, Identifier, IdentifierConfig
from pyrhonn.configfile import parse_term
from pyrhonn.experiments import Experiment
from pyrhonn.search import dead_times

DEAD_TIME = 4            # samples between the input and its first effect
T = 4000                 # samples
DROPOUT = slice(3000, 3060)  # the position sensor is lost here


def plant(T: int, seed: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """A damped, saturating two-state plant driven through a dead time: X (T, 2), U (T, 1)."""
    rng = np.random.default_rng(seed)
    steps = np.repeat(rng.uniform(-1.0, 1.0, T // 50 + 1), 50)[:T]  # a new input level every 50 samples
    U = (steps + 0.05 * rng.standard_normal(T))[:, None]
    X = np.zeros((T, 2))
    for k in range(T - 1):
        u = U[k - DEAD_TIME, 0] if k >= DEAD_TIME else 0.0
        X[k + 1, 0] = X[k, 0] + 0.1 * X[k, 1]                                  # position
        X[k + 1, 1] = 0.85 * X[k, 1] - 0.05 * X[k, 0] + 0.3 * np.tanh(2.0 * u)  # velocity
    return X + 0.001 * rng.standard_normal(X.shape), U


def main() -> int:
    X_true, U = plant(T)
    valid = np.ones(X_true.shape, dtype=bool)
    valid[DROPOUT, 0] = False
    X = X_true.copy()
    X[DROPOUT, 0] = np.nan             # what the sensor delivered: nothing

    (dead,) = dead_times([Experiment(X, U, valid, name="plant")], max_dead_time=10)
    print(f"input dead time found in the data: {dead} samples (the plant's: {DEAD_TIME})")

    # one term list per neuron, written as a config file writes them (1-based: x1 is the position)
    neuron_terms = [
        ["x1", "x2"],                                          # the position integrates the velocity
        ["x1", "x2", f"u1(k-{dead})", f"u1(k-{dead})^3"],      # the velocity feels the input late
    ]
    cfg = IdentifierConfig.uniform([[parse_term(s, 2, 1) for s in ts] for ts in neuron_terms],
                                   n_states=2, n_inputs=1, activation=Activation.BIPOLAR, beta=2.0,
                                   p0=100.0, q=1e-6, r=1e-4)
    ident = Identifier(cfg)
    Xhat = ident.run(X, U, valid)      # row t is the prediction of sample t + 1

    pred = Xhat[:-1]                   # predictions of samples 1 .. T-1
    truth = X_true[1:]
    settled = slice(1000, DROPOUT.start - 1)
    inside = slice(DROPOUT.start - 1, DROPOUT.stop - 1)
    rmse_before = float(np.sqrt(np.mean((pred[settled] - truth[settled]) ** 2, axis=0))[1])
    gap = float(np.max(np.abs(pred[inside, 0] - truth[inside, 0])))
    span = float(np.ptp(X_true[:, 0]))
    print(f"velocity one-step RMSE before the dropout: {rmse_before:.4g}")
    print(f"position inside the {DROPOUT.stop - DROPOUT.start}-sample dropout: largest error {gap:.4g} "
          f"({100 * gap / span:.2f} % of the position's range), never measured there")
    for i in range(cfg.n_states):
        h = ident.health(i)
        print(f"neuron {i}: {h.updates} updates, {h.rejected} refused")
    ok = dead == DEAD_TIME and rmse_before < 0.01 and gap < 0.02 * span
    print("OK" if ok else "NOT AS STATED")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
