"""Free-run (parallel model) and k-step-ahead validation, pyrhonn.simulation:
against the NumPy reference model, against branches built by hand from
separate identifiers, and the identifier left exactly as a plain run leaves it."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, reject, settings, strategies as st

from pyrhonn import Activation, Factor, Identifier, IdentifierConfig, IdentifierError, NeuronConfig, presets, terms
from pyrhonn.reference import ReferenceIdentifier, activate
from pyrhonn.simulation import free_run, scores, simulate, steps_ahead

from strategies import configs, trajectory


def _example1(dtype: str = "float64", T: int = 300) -> tuple[Identifier, np.ndarray, np.ndarray]:
    from pyrhonn.plants import oscillator

    _, X = oscillator.sample(horizon=0.2 * (T - 1))
    return Identifier(presets.example1(dtype)), X.astype(dtype), np.zeros((T, 1), dtype=dtype)


def _core_bytes(ident: Identifier) -> bytes:
    ident._settle()  # the whole state in the struct, if step() lent some to the vector lanes
    return bytes(ident._ffi.buffer(ident._net))


def _core_bytes_but_scratch(ident: Identifier) -> bytes:
    """The core's bytes with its step scratch zeroed: each neuron's inactive
    bank (w, P or its factors, their proof: a step's candidates) and the z
    bank that does not hold z(k-1). A run whose neurons go side by side
    (``rhonn_run_wide``) leaves in them what rhonn_step would not."""
    ident._settle()
    ffi, net = ident._ffi, ident._net
    copy = ffi.new("rhonn_t *")
    ffi.memmove(copy, net, ffi.sizeof("rhonn_t"))
    for i in range(ident.n_states):
        nb = net.bank[i] ^ 1
        ffi.memmove(ffi.addressof(copy.w[i][nb]), b"\0" * ffi.sizeof(copy.w[i][nb]), ffi.sizeof(copy.w[i][nb]))
        ffi.memmove(ffi.addressof(copy.p[i][nb]), b"\0" * ffi.sizeof(copy.p[i][nb]), ffi.sizeof(copy.p[i][nb]))
        copy.cert[i][nb] = 0
    zb = net.zbank ^ 1
    ffi.memmove(ffi.addressof(copy.z[zb]), b"\0" * ffi.sizeof(copy.z[zb]), ffi.sizeof(copy.z[zb]))
    return bytes(ffi.buffer(copy))


@pytest.mark.parametrize("dtype", ["float32", "float64"])
def test_one_step_is_the_run_aligned_with_the_measurements(dtype: str) -> None:
    ident, X, U = _example1(dtype)
    x0 = ident.prediction
    sim = simulate(ident, X, U)
    want = Identifier(presets.example1(dtype)).run(X, U)
    np.testing.assert_array_equal(sim.one_step[0], x0)
    np.testing.assert_array_equal(sim.one_step[1:], want[:-1])
    np.testing.assert_array_equal(sim.next_prediction, want[-1])
    assert sim.free_run is None and sim.ahead is None and sim.one_step.dtype == np.dtype(dtype)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(cfg=configs(), seed=st.integers(0, 2**32 - 1), split=st.floats(0.0, 0.9))
def test_free_run_matches_the_numpy_reference_fed_its_own_predictions(cfg: IdentifierConfig, seed: int,
                                                                       split: float) -> None:
    T = 300
    K = int(split * T)
    X, U, valid = trajectory(seed, T, cfg.n_states, cfg.n_inputs, 0.1)
    Uc = U if cfg.n_inputs else None
    try:
        sim = simulate(Identifier(cfg), X, Uc, valid, free_run_from=K)
    except IdentifierError:
        reject()
    assert sim.free_run is not None
    if sim.free_run_diverged is not None:
        reject()
    ref = ReferenceIdentifier(cfg)
    learnt = ref.run(X[:K], U[:K], valid[:K]) if K else np.empty((0, cfg.n_states))
    ref.learning = False
    free = ref.run(X[K:], U[K:], np.zeros((T - K, cfg.n_states), dtype=bool))
    start = learnt[-1] if K else np.asarray(cfg.x0_vector(), dtype=np.float64)
    want = np.vstack([start[None, :], free[:-1]])
    assert np.all(np.isnan(sim.free_run[:K]))
    scale = max(1.0, float(np.max(np.abs(want))))
    # a short free run of a frozen network: the 1e-11 agreement of the learnt
    # weights grows at most with the network's own gain over the run
    np.testing.assert_allclose(sim.free_run[K:], want, rtol=0, atol=1e-6 * scale)


def test_free_run_is_the_frozen_network_iterated_on_its_own_outputs() -> None:
    """An independent, explicit recursion: xhat(k+1)_i = w_i . z_i(xhat(k), u(k))."""
    neuron = lambda i: NeuronConfig(terms=terms.first_order([0, 1], inputs=[0]) + terms.bias(),  # noqa: E731
                                    activation=Activation.LOGISTIC, beta=1.0, eta=1.0, r=0.1, q=1e-4, p0=10.0)
    cfg = IdentifierConfig(n_states=2, n_inputs=1, neurons=(neuron(0), neuron(1)))
    T, K = 400, 250
    k = np.arange(T)
    U = np.sin(0.05 * k)[:, None]
    X = np.column_stack([np.sin(0.05 * k + 0.3), 0.5 * np.cos(0.07 * k)])
    ident = Identifier(cfg)
    sim = simulate(ident, X, U, free_run_from=K)
    W = [ident.get_weights(i) for i in range(2)]  # frozen from K on: the weights of the free run
    xhat = sim.one_step[K].copy()
    for t in range(K, T - 1):
        s = activate(Activation.LOGISTIC, 1.0, xhat)
        z = np.array([s[0], s[1], U[t, 0], 1.0])
        xhat = np.array([W[0] @ z, W[1] @ z])
        np.testing.assert_allclose(sim.free_run[t + 1], xhat, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("dtype", ["float32", "float64"])
@pytest.mark.parametrize("frozen_from", [None, 150])
def test_each_k_step_prediction_equals_a_branch_built_by_hand(dtype: str, frozen_from: int | None) -> None:
    H = 4
    ident, X, U = _example1(dtype)
    got = steps_ahead(ident, X, U, steps=H, frozen_from=frozen_from)
    assert np.all(np.isnan(got[:H]))
    for k in (0, 1, 37, 149, 150, 151, 200, X.shape[0] - H - 1):
        branch = Identifier(presets.example1(dtype))
        if frozen_from is None or k < frozen_from:
            branch.run(X[:k + 1], U[:k + 1])
        else:
            branch.run(X[:frozen_from], U[:frozen_from])
            branch.learning = False
            branch.run(X[frozen_from:k + 1], U[frozen_from:k + 1])
        branch.learning = False
        none = np.zeros((H - 1, X.shape[1]), dtype=bool)
        ahead = branch.run(X[k + 1:k + H], U[k + 1:k + H], none)
        np.testing.assert_array_equal(got[k + H], ahead[-1], err_msg=f"x̂({k + H} | {k})")


def test_one_step_ahead_is_the_one_step_prediction() -> None:
    ident, X, U = _example1()
    sim = simulate(ident, X, U, steps=1)
    assert sim.ahead is not None
    np.testing.assert_array_equal(sim.ahead[1:], sim.one_step[1:])
    assert np.all(np.isnan(sim.ahead[0]))


@pytest.mark.parametrize("dtype", ["float32", "float64"])
def test_k_step_branches_leave_the_identifier_exactly_as_a_run_without_them(dtype: str) -> None:
    with_branches, X, U = _example1(dtype)
    plain = Identifier(presets.example1(dtype))
    sim = simulate(with_branches, X, U, free_run_from=200, steps=6)
    reference = simulate(plain, X, U, free_run_from=200)
    np.testing.assert_array_equal(sim.one_step, reference.one_step)
    np.testing.assert_array_equal(sim.free_run, reference.free_run)
    assert _core_bytes_but_scratch(with_branches) == _core_bytes_but_scratch(plain)
    assert with_branches.learning and plain.learning  # the switch as it was


def test_simulate_continues_a_run_and_keeps_learning_on_when_no_split_is_asked() -> None:
    ident, X, U = _example1()
    whole = Identifier(presets.example1()).run(X, U)
    ident.run(X[:100], U[:100])
    sim = simulate(ident, X[100:], U[100:], steps=3)
    np.testing.assert_array_equal(sim.one_step[1:], whole[100:-1])
    np.testing.assert_array_equal(ident.prediction, whole[-1])


def test_a_diverging_free_run_is_a_result_with_nan_rows_not_an_error() -> None:
    # x̂(k+1) = 2 x̂(k) with the weight frozen: float32 overflows after about 128 doublings
    cfg = IdentifierConfig(n_states=1, n_inputs=0, dtype="float32", neurons=(
        NeuronConfig(terms=((Factor.x(0),),), beta=1.0, eta=1.0, r=1.0, q=0.0, p0=1.0, w0=np.array([2.0])),))
    ident = Identifier(cfg)
    ident.learning = False
    X = np.ones((300, 1), dtype=np.float32)
    sim = simulate(ident, X, free_run_from=10)
    assert sim.free_run is not None and sim.free_run_diverged is not None
    d = sim.free_run_diverged
    assert 130 <= d <= 140
    assert np.all(np.isfinite(sim.free_run[10:d])) and np.all(np.isnan(sim.free_run[d:]))
    np.testing.assert_array_equal(sim.free_run[10:d, 0], 2.0 ** np.arange(1, d - 9))
    sc = scores(X.astype(np.float64), sim.free_run.astype(np.float64), np.ones_like(X, dtype=bool))
    assert sc.rmse[0] == np.inf and sc.missing[0] == 300 - d + 10
    assert not ident.learning


@pytest.mark.parametrize("kwargs, message", [
    ({"free_run_from": 300}, "free_run_from: 300 out of range 0..299"),
    ({"free_run_from": -1}, "free_run_from: -1 out of range"),
    ({"free_run_from": True}, "free_run_from: expected an integer"),
    ({"free_run_from": 2.0}, "free_run_from: expected an integer"),
    ({"steps": 0}, "steps: 0 out of range >= 1"),
    ({"steps": "3"}, "steps: expected an integer"),
])
def test_bad_settings_are_named_and_change_nothing(kwargs: dict, message: str) -> None:
    ident, X, U = _example1()
    ident.run(X[:10], U[:10])
    before = _core_bytes(ident)
    with pytest.raises(ValueError, match=message):
        simulate(ident, X, U, **kwargs)
    assert _core_bytes(ident) == before


def test_bad_data_is_named_and_changes_nothing() -> None:
    ident, X, U = _example1()
    before = _core_bytes(ident)
    bad = X.copy()
    bad[7, 2] = np.nan
    with pytest.raises(ValueError, match=r"X\[7, 2\]: not finite"):
        simulate(ident, bad, U, free_run_from=5)
    with pytest.raises(ValueError, match="X: expected dtype float64, got float32"):
        simulate(ident, X.astype(np.float32), U)
    with pytest.raises(ValueError, match="identifier: expected a pyrhonn Identifier"):
        simulate(ReferenceIdentifier(presets.example1()), X, U)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="X: no samples"):
        simulate(ident, X[:0], U[:0])
    assert _core_bytes(ident) == before


def test_a_failing_step_rolls_the_identifier_back_to_before_the_call() -> None:
    cfg = IdentifierConfig(n_states=1, n_inputs=0, neurons=(
        NeuronConfig(terms=((Factor.x(0, 3),),), beta=1.0, eta=1.0, r=1.0, q=0.0, p0=1.0),))
    ident = Identifier(cfg)
    X = np.ones((50, 1))
    ident.run(X[:5])
    before = _core_bytes(ident)
    X[30, 0] = 1e200  # the regressor reads x(k-3): the prediction at sample 33 is not finite
    with pytest.raises(IdentifierError, match="at sample 33"):
        simulate(ident, X, steps=3)
    assert _core_bytes(ident) == before


def test_free_run_helper_returns_the_simulation_free_run() -> None:
    ident, X, U = _example1()
    got = free_run(ident, X, U, start=120)
    want = simulate(Identifier(presets.example1()), X, U, free_run_from=120).free_run
    np.testing.assert_array_equal(got, want)
