"""A refused learning update with ``skip_refused``: only its neuron skips the
update, the other neurons learn, the step and ``run()`` go on, and
``reset_after`` recovers the neuron inside one ``run()``. Without it the
whole step is refused, as before. Both precisions, float32 first."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from pyrhonn import Identifier, IdentifierConfig, IdentifierError
from pyrhonn.configfile import dumps, loads
from pyrhonn.population import run_identifiers_outcomes, run_population
from pyrhonn.reference import ReferenceIdentifier

DTYPES = ["float32", "float64"]
T = 40

# Neuron 0's first term is the raw x1, held at 0 below, so its P_00 gains
# nothing from a measurement: with P0 and Q at the top of the range
# P_00 + Q_00 overflows at every update (a refusal that comes from the stored
# state, so it repeats). Neuron 1 reads measured states and the input only.
CONFIG = """
format = "pyrhonn-config"
version = 1
n_states = 2
n_inputs = 1
dtype = "{dtype}"
[defaults]
activation = "logistic"
beta = 1.0
p0 = 10.0
q = 1e-3
r = 0.1
eta = 1.0
[[neurons]]
terms = ["x1", "S(x2)", "u1", "1"]
{neuron0}
[[neurons]]
terms = ["S(x1)", "S(x2)", "u1", "1"]
"""


def config(dtype: str, *, overflowing: bool, skip: bool, reset_after: int = 0) -> IdentifierConfig:
    big = float(np.finfo(dtype).max)
    lines = []
    if overflowing:
        lines += [f"p0 = [{big!r}, 10.0, 10.0, 10.0]", f"q = [{big!r}, 1e-3, 1e-3, 1e-3]"]
    if skip:
        lines.append("skip_refused = true")
    if reset_after:
        lines.append(f"reset_after = {reset_after}")
    return loads(CONFIG.format(dtype=dtype, neuron0="\n".join(lines))).config


def data(dtype: str) -> tuple[np.ndarray, np.ndarray]:
    k = np.arange(T)
    X = np.column_stack([np.zeros(T), np.cos(0.07 * k) + 0.2 * np.sin(0.2 * k)]).astype(dtype)
    U = np.sin(0.05 * k).reshape(T, 1).astype(dtype)
    return X, U


@pytest.mark.parametrize("dtype", DTYPES)
def test_without_skip_refused_the_first_refusal_refuses_the_run_and_changes_nothing(dtype: str) -> None:
    X, U = data(dtype)
    ident = Identifier(config(dtype, overflowing=True, skip=False))
    with pytest.raises(IdentifierError):
        ident.run(X, U)
    assert ident.steps == 0
    assert ident.health(1).updates == 0


@pytest.mark.parametrize("dtype", DTYPES)
def test_a_refused_neuron_keeps_its_weights_while_the_others_learn_to_the_end(dtype: str) -> None:
    X, U = data(dtype)
    cfg = config(dtype, overflowing=True, skip=True)
    ident = Identifier(cfg)
    Y = ident.run(X, U)
    assert ident.steps == T
    h0, h1 = ident.health(0), ident.health(1)
    assert (h0.rejected, h0.updates, h0.resets, h0.fail_run) == (T - 1, 0, 0, T - 1)
    assert (h1.rejected, h1.updates) == (0, T - 1)
    np.testing.assert_array_equal(ident.get_weights(0), np.zeros(4, dtype=dtype))
    np.testing.assert_array_equal(ident.get_covariance(0), cfg.neurons[0].p0_matrix().astype(dtype))
    # neuron 1 learns bit for bit as in a twin whose neuron 0 is well posed
    twin = Identifier(config(dtype, overflowing=False, skip=False))
    Yt = twin.run(X, U)
    np.testing.assert_array_equal(Y[:, 1], Yt[:, 1])
    np.testing.assert_array_equal(ident.get_weights(1), twin.get_weights(1))
    # stepping gives the same bits as the one-call run
    stepped = Identifier(cfg)
    Ys = np.array([stepped.step(X[k], U[k]) for k in range(T)])
    np.testing.assert_array_equal(Ys, Y)


@pytest.mark.parametrize("dtype", DTYPES)
def test_reset_after_recovers_the_refusing_neuron_inside_one_run(dtype: str) -> None:
    X, U = data(dtype)
    ident = Identifier(config(dtype, overflowing=True, skip=True, reset_after=3))
    ident.run(X, U)
    h0 = ident.health(0)
    assert (h0.rejected, h0.resets, h0.fail_run) == (T - 1, (T - 1) // 3, (T - 1) % 3)
    assert ident.health(1).updates == T - 1


def test_skip_refused_follows_the_numpy_reference() -> None:
    X, U = data("float64")
    cfg = config("float64", overflowing=True, skip=True)
    Y = Identifier(cfg).run(X, U)
    ref = ReferenceIdentifier(cfg)
    Yr = np.array([ref.step(X[k], U[k]) for k in range(T)])
    np.testing.assert_allclose(Y, Yr, rtol=1e-9, atol=1e-12)


def observed(ident: Identifier) -> list[bytes]:
    """What an identifier exposes after a run, as bytes: its prediction,
    weights, covariances as stored, steps and health records."""
    out = [ident.prediction.tobytes(), repr(ident.steps).encode()]
    out += [w.tobytes() for w in ident.weights]
    out += [ident._stored_covariance(i).tobytes() for i in range(ident.n_states)]
    return out + [repr(h).encode() for h in ident.healths]


@pytest.mark.parametrize("dtype", DTYPES)
def test_a_population_skips_refusals_member_by_member_as_their_own_runs(dtype: str) -> None:
    """Members that skip their refusals (with and without reset_after) run in
    the lanes beside a well-posed member and one without skip_refused, which
    stops at its first refusal: each is its own run, bit for bit."""
    X, U = data(dtype)
    configs = [config(dtype, overflowing=False, skip=False)]
    configs += [config(dtype, overflowing=True, skip=True, reset_after=r) for r in (0, 2, 5)]
    configs += [config(dtype, overflowing=True, skip=False)]
    for cfg, Y in zip(configs[:4], run_population(configs[:4], X, U)):
        np.testing.assert_array_equal(Y, Identifier(cfg).run(X, U))
    members, alone = [Identifier(c) for c in configs], [Identifier(c) for c in configs]
    outcomes = run_identifiers_outcomes(members, X, U)
    for k, (member, single) in enumerate(zip(members, alone)):
        if k == 4:
            assert isinstance(outcomes[k], IdentifierError)  # stops at the first refusal, as alone
            with pytest.raises(IdentifierError):
                single.run(X, U)
        else:
            np.testing.assert_array_equal(outcomes[k], single.run(X, U))
        assert observed(member) == observed(single), f"member {k}: state differs"
    assert [members[k].health(0).rejected for k in range(4)] == [0, T - 1, T - 1, T - 1]
    assert [members[k].health(0).resets for k in range(4)] == [0, 0, (T - 1) // 2, (T - 1) // 5]


@pytest.mark.parametrize("dtype", DTYPES)
def test_neurons_side_by_side_skip_refusals_as_the_single_run(dtype: str) -> None:
    """The vector lanes holding one identifier's neurons (rhonn_run_wide, and
    steps lent to the lanes) skip a refused neuron bit for bit as rhonn_run."""
    X, U = data(dtype)
    cfg = config(dtype, overflowing=True, skip=True, reset_after=4)
    lanes, single, stepped = Identifier(cfg), Identifier(cfg), Identifier(cfg)
    lanes._wide, single._wide, stepped._wide = True, False, True
    Y = lanes.run(X, U)
    np.testing.assert_array_equal(Y, single.run(X, U))
    np.testing.assert_array_equal(np.array([stepped.step(X[k], U[k]) for k in range(T)]), Y)
    assert observed(lanes) == observed(single) == observed(stepped)
    assert lanes.health(0).resets == (T - 1) // 4


def test_skip_refused_round_trips_through_the_config_file_and_rejects_non_booleans() -> None:
    cfg = config("float32", overflowing=False, skip=True)
    assert cfg.neurons[0].skip_refused and not cfg.neurons[1].skip_refused
    text = dumps(cfg)
    assert "skip_refused = true" in text
    assert loads(text).config == cfg
    assert "skip_refused" not in dumps(config("float32", overflowing=False, skip=False))
    with pytest.raises(ValueError, match=r"neurons\[0\]\.skip_refused"):
        loads(CONFIG.format(dtype="float32", neuron0="skip_refused = 1"))
    with pytest.raises(ValueError, match="skip_refused"):
        dataclasses.replace(cfg.neurons[0], skip_refused=1)
