"""Hypothesis strategies shared by the identifier tests: random valid
configurations within the compiled capacities, and smooth random
trajectories with dropouts."""
from __future__ import annotations

import numpy as np
from hypothesis import strategies as st

from pyrhonn import Activation, Factor, FactorKind, IdentifierConfig, NeuronConfig
from pyrhonn.config import monomial


@st.composite
def factors(draw: st.DrawFn, n: int, m: int, max_delay: int = 3) -> Factor:
    kinds = [FactorKind.S, FactorKind.S, FactorKind.X, FactorKind.ONE] + ([FactorKind.U] * 2 if m else [])
    kind = draw(st.sampled_from(kinds))
    power = draw(st.integers(1, 3))
    if kind is FactorKind.ONE:
        return Factor.one()
    if kind is FactorKind.U:
        return Factor.u(draw(st.integers(0, m - 1)), power, delay=draw(st.integers(0, max_delay)))
    delay = draw(st.integers(0, max_delay))
    return Factor(kind, draw(st.integers(0, n - 1)), delay, power)


@st.composite
def neuron_configs(draw: st.DrawFn, n: int, m: int) -> NeuronConfig:
    drawn = [tuple(draw(factors(n, m)) for _ in range(draw(st.integers(1, 3))))
             for _ in range(draw(st.integers(1, 8)))]
    unique: dict[frozenset, tuple[Factor, ...]] = {}
    for term in drawn:  # NeuronConfig refuses the same product twice
        unique.setdefault(monomial(term), term)
    terms = tuple(unique.values())
    L = len(terms)
    diag = draw(st.booleans())
    p0 = (np.array([draw(st.floats(0.1, 100.0)) for _ in range(L)]) if diag
          else draw(st.floats(0.1, 100.0)))
    return NeuronConfig(
        terms=terms,
        activation=draw(st.sampled_from(list(Activation))),
        beta=draw(st.floats(0.05, 3.0)),
        p0=p0,
        q=draw(st.floats(1e-4, 1.0)),
        r=draw(st.floats(1e-2, 10.0)),
        eta=draw(st.floats(0.2, 1.0)),
        w0=np.array([draw(st.floats(-1.0, 1.0)) for _ in range(L)]),
    )


@st.composite
def configs(draw: st.DrawFn, dtype: str = "float64") -> IdentifierConfig:
    n = draw(st.integers(1, 5))
    m = draw(st.integers(0, 3))
    neurons = tuple(draw(neuron_configs(n, m)) for _ in range(n))
    x0 = np.array([draw(st.floats(-1.0, 1.0)) for _ in range(n)])
    return IdentifierConfig(n_states=n, n_inputs=m, neurons=neurons, dtype=dtype, x0=x0)


def trajectory(seed: int, T: int, n: int, m: int, dropout: float = 0.0, dtype: str = "float64"):
    """Sums of sines with random frequencies and phases (bounded, smooth like
    a sampled plant), inputs likewise, and a random valid mask whose invalid
    entries are NaN, as a dropped measurement would be."""
    rng = np.random.default_rng(seed)
    t = np.arange(T)[:, None] * 0.05

    def signals(k: int) -> np.ndarray:
        f = rng.uniform(0.05, 2.0, (3, k))
        a = rng.uniform(0.2, 1.5, (3, k))
        ph = rng.uniform(0, 2 * np.pi, (3, k))
        return sum(a[i] * np.sin(f[i] * t + ph[i]) for i in range(3))

    X = signals(n).astype(dtype)
    U = signals(m).astype(dtype) if m else np.zeros((T, 0), dtype=dtype)
    valid = rng.random((T, n)) >= dropout
    X[~valid] = np.nan
    return X, U, valid
