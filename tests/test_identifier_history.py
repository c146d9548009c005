"""``wait_for_history``: a neuron learns only once every delayed tap of its
regressor reads a measured sample (after construction, reset and restart),
bit for bit as an identifier without the option whose learning is off for
the padded samples; the same in the one-call run, the neurons side by side,
populations and the NumPy reference. Off by default (the paper's constant
initial history is learned from). Float32 first."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from pyrhonn import Identifier, IdentifierConfig, terms
from pyrhonn.configfile import dumps, loads
from pyrhonn.population import run_population
from pyrhonn.reference import ReferenceIdentifier

DTYPES = ["float32", "float64"]
T = 80
D = 3  # the deepest tap: u1(k-3)


def config(dtype: str, wait: bool, n: int = 2) -> IdentifierConfig:
    """n states, one input; every neuron reads its state, x1(k-1) and u1(k-3)."""
    ts = (*terms.first_order(1, 0), *terms.delayed_taps(0, [1]), *terms.delayed_inputs(0, [D]), *terms.bias())
    cfg = IdentifierConfig.uniform(ts, n_states=n, n_inputs=1, beta=1.0, p0=10.0, q=1e-4, r=0.1, dtype=dtype)
    return cfg.replace(neurons=tuple(dataclasses.replace(nr, wait_for_history=wait) for nr in cfg.neurons))


def data(dtype: str, n: int = 2) -> tuple[np.ndarray, np.ndarray]:
    k = np.arange(T)
    X = np.column_stack([np.sin(0.1 * k + j) + 0.3 * np.cos(0.37 * k) for j in range(n)]).astype(dtype)
    U = np.sin(0.23 * k).reshape(T, 1).astype(dtype)
    return X, U


def stepped_twin(cfg: IdentifierConfig, X: np.ndarray, U: np.ndarray, restart_at: int | None = None) -> np.ndarray:
    """The config without the option, its learning off while the taps read the padded history."""
    twin = Identifier(cfg.replace(neurons=tuple(dataclasses.replace(nr, wait_for_history=False)
                                                for nr in cfg.neurons)))
    out, since = [], 0
    for k in range(T):
        if k == restart_at:
            twin.restart()
            since = 0
        twin.learning = since > D
        out.append(twin.step(X[k], U[k]))
        since += 1
    return np.array(out)


@pytest.mark.parametrize("dtype", DTYPES)
def test_a_waiting_neuron_learns_from_the_first_sample_whose_taps_are_all_measured(dtype: str) -> None:
    X, U = data(dtype)
    cfg = config(dtype, wait=True)
    ident = Identifier(cfg)
    Y = ident.run(X, U)
    np.testing.assert_array_equal(Y, stepped_twin(cfg, X, U))
    assert [ident.health(i).updates for i in range(2)] == [T - 1 - D] * 2
    plain = Identifier(config(dtype, wait=False))
    plain.run(X, U)
    assert [plain.health(i).updates for i in range(2)] == [T - 1] * 2


@pytest.mark.parametrize("dtype", DTYPES)
def test_after_a_restart_the_neuron_waits_again(dtype: str) -> None:
    X, U = data(dtype)
    cfg = config(dtype, wait=True)
    ident = Identifier(cfg)
    Y1 = ident.run(X[:40], U[:40])
    ident.restart()
    Y2 = ident.run(X[40:], U[40:])
    np.testing.assert_array_equal(np.vstack([Y1, Y2]), stepped_twin(cfg, X, U, restart_at=40))


@pytest.mark.parametrize("dtype", DTYPES)
def test_neurons_side_by_side_and_populations_wait_as_stepping_does(dtype: str) -> None:
    X, U = data(dtype, n=4)
    cfg = config(dtype, wait=True, n=4)
    one = Identifier(cfg)
    stepped = np.array([one.step(X[k], U[k]) for k in range(T)])
    np.testing.assert_array_equal(Identifier(cfg).run(X, U), stepped)
    members = [cfg, cfg.replace(neurons=tuple(dataclasses.replace(nr, r=0.5) for nr in cfg.neurons)),
               config(dtype, wait=False, n=4)]
    for member, Y in zip(members, run_population(members, X, U)):
        np.testing.assert_array_equal(Y, Identifier(member).run(X, U))


def test_waiting_follows_the_numpy_reference_with_dropouts() -> None:
    X, U = data("float64")
    valid = np.ones_like(X, dtype=bool)
    valid[20:23, 0] = False
    valid[50, 1] = False
    cfg = config("float64", wait=True)
    Y = Identifier(cfg).run(X, U, valid)
    ref = ReferenceIdentifier(cfg)
    Yr = np.array([ref.step(X[k], U[k], valid[k]) for k in range(T)])
    np.testing.assert_allclose(Y, Yr, rtol=1e-9, atol=1e-12)


def test_wait_for_history_round_trips_through_the_config_file_and_rejects_non_booleans() -> None:
    cfg = config("float32", wait=True)
    text = dumps(cfg)
    assert "wait_for_history = true" in text
    assert loads(text).config == cfg
    assert "wait_for_history" not in dumps(config("float32", wait=False))
    with pytest.raises(ValueError, match="wait_for_history"):
        loads(text.replace("wait_for_history = true", 'wait_for_history = "yes"'))
    with pytest.raises(ValueError, match="wait_for_history"):
        dataclasses.replace(cfg.neurons[0], wait_for_history=1)
