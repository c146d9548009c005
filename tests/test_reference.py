"""Tests of the pure-NumPy reference identifier (pyrhonn.reference)."""
from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.special import expit

from pyrhonn import Activation, Factor, FactorKind, IdentifierConfig, NeuronConfig, terms
from pyrhonn.config import monomial
from pyrhonn.reference import ReferenceIdentifier, activate

KalmanFilter = pytest.importorskip("filterpy.kalman").KalmanFilter

SETTINGS = settings(deadline=None, database=None, suppress_health_check=[HealthCheck.too_slow])


def rel_close(a: np.ndarray, b: np.ndarray, rtol: float = 1e-9) -> bool:
    """||a - b|| <= rtol ||b|| (Frobenius norm), with a tiny floor for b = 0."""
    return float(np.linalg.norm(np.asarray(a) - np.asarray(b))) <= rtol * max(float(np.linalg.norm(b)), 1e-12)


def snapshot(ident: ReferenceIdentifier) -> tuple:
    return ident.weights, ident.covariances, ident.prediction, ident.learning


def assert_same_snapshot(a: tuple, b: tuple) -> None:
    for wa, wb in zip(a[0], b[0]):
        np.testing.assert_array_equal(wa, wb)
    for pa, pb in zip(a[1], b[1]):
        np.testing.assert_array_equal(pa, pb)
    np.testing.assert_array_equal(a[2], b[2])
    assert a[3] == b[3]


# ---------------------------------------------------------------- strategies

@st.composite
def configs(draw: st.DrawFn) -> IdentifierConfig:
    n = draw(st.integers(1, 3))
    m = draw(st.integers(0, 2))
    kinds = [FactorKind.S, FactorKind.X, FactorKind.ONE] + ([FactorKind.U] if m else [])
    pos = lambda lo, hi: st.floats(lo, hi, allow_nan=False)  # noqa: E731
    neurons = []
    for _ in range(n):
        L = draw(st.integers(1, 4))
        term_list = []
        for _ in range(L):
            factors = []
            for _ in range(draw(st.integers(1, 3))):
                kind, power = draw(st.sampled_from(kinds)), draw(st.integers(1, 3))
                if kind in (FactorKind.S, FactorKind.X):
                    factors.append(Factor(kind, draw(st.integers(0, n - 1)), draw(st.integers(0, 3)), power))
                elif kind is FactorKind.U:
                    factors.append(Factor.u(draw(st.integers(0, m - 1)), power))
                else:
                    factors.append(Factor.one())
            term_list.append(tuple(factors))
        unique: dict[frozenset, tuple[Factor, ...]] = {}
        for term in term_list:  # NeuronConfig refuses the same product twice
            unique.setdefault(monomial(term), term)
        term_list, L = list(unique.values()), len(unique)
        vec = lambda lo, hi: np.array(draw(st.lists(pos(lo, hi), min_size=L, max_size=L)))  # noqa: E731
        p0 = draw(st.one_of(pos(0.1, 100.0), st.just(None)))
        q = draw(st.sampled_from(["zero", "scalar", "vector"]))
        neurons.append(NeuronConfig(
            terms=tuple(term_list),
            activation=draw(st.sampled_from(list(Activation))),
            beta=draw(pos(0.1, 3.0)),
            p0=vec(0.1, 100.0) if p0 is None else p0,
            q={"zero": 0.0, "scalar": draw(pos(1e-4, 1.0)), "vector": vec(0.0, 1.0)}[q],
            r=draw(pos(0.01, 10.0)),
            eta=1.0,
            w0=vec(-1.0, 1.0),
        ))
    x0 = np.array(draw(st.lists(pos(-1.0, 1.0), min_size=n, max_size=n)))
    return IdentifierConfig(n_states=n, n_inputs=m, neurons=tuple(neurons), x0=x0)


@st.composite
def trajectories(draw: st.DrawFn, cfg: IdentifierConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    T = draw(st.integers(2, 25))
    X = rng.uniform(-2.0, 2.0, (T, cfg.n_states))
    U = rng.uniform(-2.0, 2.0, (T, cfg.n_inputs))
    V = rng.random((T, cfg.n_states)) < draw(st.sampled_from([1.0, 0.7]))
    X[~V] = np.nan  # invalid samples must be ignored
    return X, U, V


# ------------------------------------------- independent filterpy pipeline

def independent_regressor(nr: NeuronConfig, past, u_past) -> np.ndarray:
    """z_i from scratch: past(j, d) is the effective x_j(k - d), u_past(j, d) is u_j(k - d)."""
    def S(s: float) -> float:
        if nr.activation is Activation.LOGISTIC:
            return float(expit(nr.beta * s))
        return math.tanh(nr.beta * s / 2.0)  # (1 - e^-bs) / (1 + e^-bs)

    value = {FactorKind.S: lambda f: S(past(f.index, f.delay)), FactorKind.X: lambda f: past(f.index, f.delay),
             FactorKind.U: lambda f: u_past(f.index, f.delay), FactorKind.ONE: lambda f: 1.0}
    return np.array([math.prod(value[f.kind](f) ** f.power for f in term) for term in nr.terms])


def well_conditioned(kfs: list, z_prev: list[np.ndarray]) -> bool:
    """True while every P_i has cond < 1e6 and every |z_ij| < 1e3.

    Dropouts feed predictions back through raw x^p terms, which can make the
    regressor explode and P_i numerically singular; then the textbook
    P - K H^T P and filterpy's Joseph form differ by rounding far above 1e-9
    (both are equally "right"), so the comparison stops there.
    """
    return all(np.linalg.cond(kf.P) < 1e6 for kf in kfs) and all(np.max(np.abs(z)) < 1e3 for z in z_prev)


@given(data=st.data())
@settings(SETTINGS, max_examples=300)
def test_each_neuron_matches_filterpy_kalman_filter_with_identity_transition(data: st.DataObject) -> None:
    cfg = data.draw(configs())
    X, U, V = data.draw(trajectories(cfg))
    ref = ReferenceIdentifier(cfg)
    kfs = []
    for nr in cfg.neurons:
        kf = KalmanFilter(dim_x=nr.n_terms, dim_z=1)
        kf.x = nr.w0_vector().reshape(-1, 1)
        kf.P, kf.Q, kf.R, kf.F = nr.p0_matrix(), np.diag(nr.q_diagonal()), np.array([[nr.r]]), np.eye(nr.n_terms)
        kfs.append(kf)
    history: list[np.ndarray] = []
    xhat, z_prev = cfg.x0_vector(), None
    for k in range(X.shape[0]):
        if k > 0 and not well_conditioned(kfs, z_prev):
            break  # beyond here the two forms of eq. 7 legitimately differ by more than 1e-9
        if k > 0:
            for i, kf in enumerate(kfs):
                # no learning where z_i(k-1) read a prediction of x_i at one of its own taps
                own = [f.delay for t in cfg.neurons[i].terms for f in t
                       if f.kind in (FactorKind.S, FactorKind.X) and f.index == i]
                own_measured = all(V[max(k - 1 - d, 0), i] for d in range(max(own) + 1)) if own else True
                if V[k, i] and own_measured:
                    kf.update(X[k, i], H=z_prev[i].reshape(1, -1))
                    kf.predict()
        history.append(np.where(V[k], X[k], xhat))
        past = lambda j, d: history[max(k - d, 0)][j]  # noqa: E731
        u_past = lambda j, d: U[max(k - d, 0), j]  # noqa: E731
        z_prev = [independent_regressor(nr, past, u_past) for nr in cfg.neurons]
        xhat = np.array([kf.x[:, 0] @ z for kf, z in zip(kfs, z_prev)])

        got = ref.step(X[k], U[k], V[k])
        for i, kf in enumerate(kfs):
            assert rel_close(ref.weights[i], kf.x[:, 0]), (k, i)
            assert rel_close(ref.covariances[i], kf.P), (k, i)
        assert rel_close(got, xhat), k


# -------------------------------------------------------- hand computations

def test_hand_computed_two_steps_with_logistic_and_bias() -> None:
    # z = [S(x), 1], logistic beta 1, P(0) = I, Q = 0, R = 1, eta = 1, w(0) = 0.
    cfg = IdentifierConfig.uniform(terms.first_order(1) + terms.bias(), n_states=1, n_inputs=0)
    ident = ReferenceIdentifier(cfg)
    # k = 0, x = 0: no learning; z(0) = [1/2, 1]; xhat(1) = 0.
    assert ident.step(np.array([0.0])) == pytest.approx([0.0], abs=0)
    # k = 1, x = 1: e = 1, s = 1 + 1/4 + 1 = 9/4, K = [2/9, 4/9] = w(2).
    out = ident.step(np.array([1.0]))
    np.testing.assert_allclose(ident.weights[0], [2 / 9, 4 / 9], rtol=1e-15)
    np.testing.assert_allclose(ident.covariances[0], [[8 / 9, -2 / 9], [-2 / 9, 5 / 9]], rtol=1e-15)
    S1 = 1.0 / (1.0 + math.exp(-1.0))
    np.testing.assert_allclose(out, [2 / 9 * S1 + 4 / 9], rtol=1e-15)
    np.testing.assert_array_equal(out, ident.prediction)


def test_hand_computed_two_steps_with_raw_power_input_eta_and_q() -> None:
    # z = [x^2, u], P(0) = 2I, Q = 0.1 I, R = 0.5, eta = 0.5, w(0) = [1, 1/2].
    nr = NeuronConfig(terms=((Factor.x(0, power=2),), (Factor.u(0),)), p0=2.0, q=0.1, r=0.5, eta=0.5,
                      w0=np.array([1.0, 0.5]))
    ident = ReferenceIdentifier(IdentifierConfig(n_states=1, n_inputs=1, neurons=(nr,)))
    # k = 0, x = 1, u = 2: z(0) = [1, 2], xhat(1) = 1 + 1 = 2.
    np.testing.assert_array_equal(ident.step(np.array([1.0]), np.array([2.0])), [2.0])
    # k = 1, x = 3, u = -1: e = 1, P H = [2, 4], s = 0.5 + 10 = 10.5, K = [4/21, 8/21],
    # w = [1 + 2/21, 1/2 + 4/21] = [23/21, 29/42]; z(1) = [9, -1]; xhat(2) = 385/42.
    out = ident.step(np.array([3.0]), np.array([-1.0]))
    np.testing.assert_allclose(ident.weights[0], [23 / 21, 29 / 42], rtol=1e-15)
    np.testing.assert_allclose(ident.covariances[0], [[2.1 - 4 / 10.5, -8 / 10.5], [-8 / 10.5, 2.1 - 16 / 10.5]],
                               rtol=1e-15)
    np.testing.assert_allclose(out, [385 / 42], rtol=1e-14)


# ------------------------------------------------------- step semantics

def two_state_config(**kw) -> IdentifierConfig:
    t = terms.first_order(2, 1) + terms.pairwise_products(2) + terms.bias()
    return IdentifierConfig.uniform(t, n_states=2, n_inputs=1, p0=5.0, q=1e-2, r=0.5, **kw).replace(
        x0=np.array([0.3, -0.4]))


def test_invalid_measurement_skips_learning_and_substitutes_own_prediction() -> None:
    cfg = two_state_config()
    a, b = ReferenceIdentifier(cfg), ReferenceIdentifier(cfg)
    rng = np.random.default_rng(1)
    for _ in range(5):
        x, u = rng.normal(size=2), rng.normal(size=1)
        np.testing.assert_array_equal(a.step(x, u), b.step(x, u))
    before = snapshot(a)
    x, u = np.array([0.7, np.nan]), np.array([0.2])
    out_a = a.step(x, u, np.array([True, False]))
    # Neuron 1 kept w and P (no Q added either); neuron 0 learned.
    np.testing.assert_array_equal(a.weights[1], before[0][1])
    np.testing.assert_array_equal(a.covariances[1], before[1][1])
    assert not np.array_equal(a.weights[0], before[0][0])
    # Feeding the prediction as a valid measurement gives e = 0: same weights,
    # same regressor, hence the same prediction (only P_1 differs, by Q and the gain).
    out_b = b.step(np.array([0.7, before[2][1]]), u)
    np.testing.assert_array_equal(out_a, out_b)
    np.testing.assert_array_equal(a.weights[1], b.weights[1])
    assert not np.array_equal(a.covariances[1], b.covariances[1])


def test_first_step_does_not_learn_and_uses_x0_for_invalid_states() -> None:
    cfg = two_state_config()
    a, b = ReferenceIdentifier(cfg), ReferenceIdentifier(cfg)
    init = snapshot(a)
    out_a = a.step(np.array([np.nan, 1.5]), np.array([0.5]), np.array([False, True]))
    out_b = b.step(np.array([0.3, 1.5]), np.array([0.5]))  # x0[0] = 0.3
    np.testing.assert_array_equal(out_a, out_b)
    for w, w0 in zip(a.weights, init[0]):
        np.testing.assert_array_equal(w, w0)
    for p, p0 in zip(a.covariances, init[1]):
        np.testing.assert_array_equal(p, p0)
    a.step(np.array([0.1, 0.2]), np.array([0.0]))
    # the second step learns, except neuron 0: z_0(0) read x0 in place of its own missing x_1(0)
    np.testing.assert_array_equal(a.weights[0], init[0][0])
    assert not np.array_equal(a.weights[1], init[0][1])
    a.step(np.array([0.2, 0.1]), np.array([0.0]))
    assert not np.array_equal(a.weights[0], init[0][0])
    a.reset()
    assert_same_snapshot(snapshot(a), init)
    a.step(np.array([5.0, -5.0]), np.array([1.0]))  # first step again after reset
    for w, w0 in zip(a.weights, init[0]):
        np.testing.assert_array_equal(w, w0)


@pytest.mark.parametrize("raw", [True, False])
def test_delayed_taps_read_constant_initial_history(raw: bool) -> None:
    nr = NeuronConfig(terms=terms.delayed_taps(0, [0, 1, 3], raw=raw), w0=np.array([1.0, 10.0, 100.0]),
                      activation=Activation.BIPOLAR, beta=0.7)
    ident = ReferenceIdentifier(IdentifierConfig(n_states=1, n_inputs=0, neurons=(nr,)))
    ident.learning = False
    xs = [0.5, -1.0, 2.0, 0.25, -0.75, 1.25]
    f = (lambda s: s) if raw else (lambda s: math.tanh(0.7 * s / 2))
    for k, xk in enumerate(xs):
        out = ident.step(np.array([xk]))
        tap = lambda d: f(xs[max(k - d, 0)])  # noqa: E731
        np.testing.assert_allclose(out, [tap(0) + 10 * tap(1) + 100 * tap(3)], rtol=1e-14)


def test_delayed_tap_history_holds_substituted_predictions() -> None:
    # x(k+1) prediction = w * x(k-1) with w = 2 frozen: an invalid sample's
    # stand-in prediction is what the delayed tap reads one step later.
    nr = NeuronConfig(terms=terms.delayed_taps(0, [1], raw=True), w0=np.array([2.0]))
    ident = ReferenceIdentifier(IdentifierConfig(n_states=1, n_inputs=0, neurons=(nr,)))
    ident.learning = False
    assert ident.step(np.array([1.0]))[0] == 2.0  # history constant: x(-1) = x(0) = 1
    assert ident.step(np.array([3.0]))[0] == 2.0  # reads x(0) = 1
    assert ident.step(np.array([np.nan]), None, np.array([False]))[0] == 6.0  # reads x(1) = 3; x_eff(2) = 2
    assert ident.step(np.array([0.0]))[0] == 4.0  # reads x_eff(2) = 2


def test_learning_off_freezes_weights_but_predictions_continue() -> None:
    cfg = two_state_config()
    ident = ReferenceIdentifier(cfg)
    rng = np.random.default_rng(2)
    X, U = rng.normal(size=(30, 2)), rng.normal(size=(30, 1))
    ident.run(X[:10], U[:10])
    snap = snapshot(ident)
    ident.learning = False
    assert ident.learning is False
    outs = ident.run(X[10:20], U[10:20])
    for w, w_before in zip(ident.weights, snap[0]):
        np.testing.assert_array_equal(w, w_before)
    for p, p_before in zip(ident.covariances, snap[1]):
        np.testing.assert_array_equal(p, p_before)
    # Predictions continue as w^T z(k) with the frozen weights: the same as a
    # fresh, never-learning identifier started from those weights.
    frozen_cfg = cfg.replace(neurons=tuple(
        NeuronConfig(terms=nr.terms, w0=w) for nr, w in zip(cfg.neurons, snap[0])))
    frozen = ReferenceIdentifier(frozen_cfg)
    frozen.learning = False
    np.testing.assert_allclose(frozen.run(X[:20], U[:20])[10:], outs, rtol=1e-13)
    ident.learning = True
    ident.step(X[20], U[20])
    assert not np.array_equal(ident.weights[0], snap[0][0])
    ident.reset()
    assert ident.learning is True


def test_run_equals_repeated_steps_and_rows_are_predictions() -> None:
    cfg = two_state_config()
    a, b = ReferenceIdentifier(cfg), ReferenceIdentifier(cfg)
    rng = np.random.default_rng(3)
    X, U = rng.normal(size=(20, 2)), rng.normal(size=(20, 1))
    V = rng.random((20, 2)) < 0.8
    Xh = a.run(X, U, V)
    for t in range(20):
        np.testing.assert_array_equal(Xh[t], b.step(X[t], U[t], V[t]))
    assert Xh.shape == (20, 2) and Xh.dtype == np.float64
    np.testing.assert_array_equal(a.prediction, Xh[-1])
    assert a.run(np.empty((0, 2)), np.empty((0, 1))).shape == (0, 2)


def test_run_stops_at_first_failing_step_keeping_earlier_steps() -> None:
    cfg = two_state_config()
    a, b = ReferenceIdentifier(cfg), ReferenceIdentifier(cfg)
    X, U = np.full((5, 2), 0.1), np.zeros((5, 1))
    X[3, 1] = np.inf
    with pytest.raises(ValueError, match=r"step 3: x\[1\]: not finite"):
        a.run(X, U)
    b.run(X[:3], U[:3])
    assert_same_snapshot(snapshot(a), snapshot(b))


def test_float32_inputs_and_config_dtype_still_compute_in_float64() -> None:
    cfg = two_state_config(dtype="float32")
    ident = ReferenceIdentifier(cfg)
    out = ident.step(np.array([0.1, 0.2], dtype=np.float32), np.array([1.0], dtype=np.float32))
    assert out.dtype == np.float64 and ident.weights[0].dtype == np.float64


def test_returned_arrays_are_copies_and_inputs_are_not_modified() -> None:
    ident = ReferenceIdentifier(two_state_config())
    x, u, v = np.array([0.5, np.nan]), np.array([1.0]), np.array([True, False])
    out = ident.step(x, u, v)
    out[:] = 99.0
    ident.weights[0][:] = 99.0
    ident.covariances[0][:] = 99.0
    ident.prediction[:] = 99.0
    assert not np.any(ident.prediction == 99.0) and not np.any(ident.weights[0] == 99.0)
    assert not np.any(ident.covariances[0] == 99.0)
    np.testing.assert_array_equal(x, [0.5, np.nan])
    np.testing.assert_array_equal(v, [True, False])


# -------------------------------------------------------------- bad input

BAD_STEPS = [
    ([0.1, 0.2], np.array([0.0]), None, r"^x: expected a real floating numpy array"),
    (np.array([1, 2]), np.array([0.0]), None, r"^x: expected a real floating array, got dtype int"),
    (np.array([0.1, 0.2, 0.3]), np.array([0.0]), None, r"^x: expected shape \(2,\)"),
    (np.array([[0.1, 0.2]]), np.array([0.0]), None, r"^x: expected shape \(2,\)"),
    (np.array([0.1, 0.2]), None, None, r"^u: expected"),
    (np.array([0.1, 0.2]), np.array([0.0, 1.0]), None, r"^u: expected shape \(1,\)"),
    (np.array([0.1, 0.2]), np.array([1 + 0j]), None, r"^u: expected a real floating array"),
    (np.array([0.1, 0.2]), np.array([0.0]), np.array([1, 1]), r"^valid: expected a bool array"),
    (np.array([0.1, 0.2]), np.array([0.0]), np.array([True]), r"^valid: expected shape"),
    (np.array([0.1, np.nan]), np.array([0.0]), None, r"^x\[1\]: not finite$"),
    (np.array([np.inf, np.nan]), np.array([0.0]), np.array([True, False]), r"^x\[0\]: not finite$"),
    (np.array([0.1, 0.2]), np.array([-np.inf]), None, r"^u\[0\]: not finite$"),
    (np.array([np.nan, 0.2]), np.array([np.nan]), np.array([False, True]), r"^u\[0\]: not finite$"),
]


@pytest.mark.parametrize("x, u, valid, message", BAD_STEPS)
@pytest.mark.parametrize("warm", [0, 3])
def test_bad_inputs_raise_value_error_and_leave_state_unchanged(x, u, valid, message, warm: int) -> None:
    cfg = two_state_config()
    a, b = ReferenceIdentifier(cfg), ReferenceIdentifier(cfg)
    rng = np.random.default_rng(4)
    X, U = rng.normal(size=(warm + 4, 2)), rng.normal(size=(warm + 4, 1))
    a.run(X[:warm], U[:warm])
    b.run(X[:warm], U[:warm])
    with pytest.raises(ValueError, match=message):
        a.step(x, u, valid)
    assert_same_snapshot(snapshot(a), snapshot(b))
    # Hidden state (history, z(k-1), first-step flag) too: the futures agree.
    np.testing.assert_array_equal(a.run(X[warm:], U[warm:]), b.run(X[warm:], U[warm:]))


def test_bad_trajectory_shapes_raise_value_error() -> None:
    ident = ReferenceIdentifier(two_state_config())
    with pytest.raises(ValueError, match=r"^X: "):
        ident.run(np.zeros(4), np.zeros((4, 1)))
    with pytest.raises(ValueError, match=r"^U: expected shape \(4, 1\)"):
        ident.run(np.zeros((4, 2)), np.zeros((3, 1)))
    with pytest.raises(ValueError, match=r"^valid: expected a bool array"):
        ident.run(np.zeros((4, 2)), np.zeros((4, 1)), np.ones((4, 2)))
    np.testing.assert_array_equal(ident.prediction, [0.3, -0.4])


def numerical_failure(ident: ReferenceIdentifier, steps: list[float], message: str) -> None:
    for xk in steps[:-1]:
        ident.step(np.array([xk]))
    before = snapshot(ident)
    with pytest.raises(ValueError, match=message):
        ident.step(np.array([steps[-1]]))
    assert_same_snapshot(snapshot(ident), before)


def test_non_positive_innovation_raises_and_leaves_state_unchanged() -> None:
    # Indefinite P (eigenvalues 3, -1), which a config refuses as P(0), put in the model's state
    # directly: with H = [-1, 1], R + H^T P H = 1 - 2 = -1.
    nr = NeuronConfig(terms=(terms.delayed_taps(0, [0], raw=True) + terms.bias()))
    ref = ReferenceIdentifier(IdentifierConfig(n_states=1, n_inputs=0, neurons=(nr,)))
    ref._P[0][...] = [[1.0, 2.0], [2.0, 1.0]]
    numerical_failure(ref, [-1.0, 0.0], r"^neuron 0: innovation")


def test_overflowing_covariance_raises_and_leaves_state_unchanged() -> None:
    nr = NeuronConfig(terms=terms.delayed_taps(0, [0], raw=True), p0=1e308, q=1e308)
    numerical_failure(ReferenceIdentifier(IdentifierConfig(n_states=1, n_inputs=0, neurons=(nr,))),
                      [1e-200, 1.0], r"^neuron 0: updated covariance")


def test_overflowing_weights_raise_and_leave_state_unchanged() -> None:
    # R tiny and P huge: K ~ 1/z, and a huge error e makes eta K e overflow.
    nr = NeuronConfig(terms=terms.delayed_taps(0, [0], raw=True), p0=1e300, r=1e-300)
    numerical_failure(ReferenceIdentifier(IdentifierConfig(n_states=1, n_inputs=0, neurons=(nr,))),
                      [1e-300, 1.7e308], r"^neuron 0: updated weights")


def test_overflowing_prediction_raises_and_leaves_state_unchanged() -> None:
    nr = NeuronConfig(terms=((Factor.x(0, power=255),),), w0=np.array([1.0]))
    ident = ReferenceIdentifier(IdentifierConfig(n_states=1, n_inputs=0, neurons=(nr,), x0=np.array([0.5])))
    numerical_failure(ident, [1e3], r"^neuron 0: prediction is not finite")
    ident.step(np.array([1.0]))  # still a first step: no learning
    np.testing.assert_array_equal(ident.weights[0], [1.0])


# ------------------------------------------------------------- activation

@pytest.mark.parametrize("activation", list(Activation))
def test_activations_are_finite_and_saturate_for_huge_arguments(activation: Activation) -> None:
    s = np.array([-1.7e308, -1e200, -745.0, -1e-300, -0.0, 0.0, 1e-300, 745.0, 1e200, 1.7e308])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for beta in (1e-300, 1.0, 1e300):
            out = activate(activation, beta, s)
            assert np.all(np.isfinite(out))
        out = activate(activation, 1e300, s)
    lo = 0.0 if activation is Activation.LOGISTIC else -1.0
    np.testing.assert_array_equal(out[[0, 1, -2, -1]], [lo, lo, 1.0, 1.0])
    assert np.all(np.diff(activate(activation, 1.0, s)) >= 0)


@given(beta=st.floats(1e-3, 1e3), s=st.floats(-1e6, 1e6))
@SETTINGS
def test_activations_match_the_paper_formulas(beta: float, s: float) -> None:
    t = beta * s / 2.0
    assert float(activate(Activation.LOGISTIC, beta, s)) == pytest.approx(float(expit(beta * s)), rel=1e-14, abs=1e-300)
    assert float(activate(Activation.BIPOLAR, beta, s)) == pytest.approx(math.tanh(t), rel=1e-14, abs=1e-300)
    if abs(beta * s) < 700:  # the literal eq. 6 and eq. 19 do not overflow here
        e = math.exp(-beta * s)
        assert float(activate(Activation.LOGISTIC, beta, s)) == pytest.approx(1.0 / (1.0 + e), rel=1e-13)
        assert float(activate(Activation.BIPOLAR, beta, s)) == pytest.approx((1.0 - e) / (1.0 + e), rel=1e-9, abs=1e-15)


def test_constructor_rejects_non_config() -> None:
    with pytest.raises(TypeError, match="config"):
        ReferenceIdentifier({"n_states": 1})  # type: ignore[arg-type]
