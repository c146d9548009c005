"""The HONN observer baseline of eq. 16-19 (pyrhonn.baselines.honn_observer)."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from pyrhonn import metrics
from pyrhonn.baselines import HonnObserver, HonnObserverParams, common_targets, observe_oscillator
from pyrhonn.baselines.honn_observer import basis, bipolar, chain_matrix, paper_delay_functions
from pyrhonn.plants import oscillator

PAPER_C = np.array([[1.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 1.0]])
PAPER_K = np.array([[0.3, 0.0], [1.0, 0.0], [0.0, 0.3], [0.0, 1.0]])


@pytest.fixture(scope="module")
def traj_02():
    return oscillator.simulate(dt=0.2)


def _data(T: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    return rng.standard_normal((T, 2)), rng.standard_normal((T, 1))


# -- parameters ------------------------------------------------------------------------

def test_defaults_are_the_papers_matrices_with_A_rebuilt_for_the_sampling_period():
    p = HonnObserverParams()
    np.testing.assert_array_equal(p.A, [[1, 0.2, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0.2], [0, 0, 0, 1]])
    np.testing.assert_array_equal(p.C, PAPER_C)
    np.testing.assert_array_equal(p.K, PAPER_K)
    np.testing.assert_array_equal(p.F, np.ones((4, 2)))
    np.testing.assert_array_equal(p.B, np.eye(4))
    np.testing.assert_array_equal(p.D, np.zeros((4, 1)))
    assert (p.sigma1, p.beta, p.d_hat, p.dt) == (0.6, 0.01, 3.2, 0.2)
    assert p.l1 == 15 and not p.basis_bias  # documented choice 6 (no constant term)
    np.testing.assert_array_equal(p.Gamma1, 0.2 * np.eye(15))
    np.testing.assert_array_equal(p.x0_hat, np.zeros(4))
    np.testing.assert_array_equal(p.W0, np.zeros((15, 4)))
    assert p.h is paper_delay_functions and p.h_times_dt
    np.testing.assert_array_equal(HonnObserverParams(dt=0.02).A, chain_matrix(0.02))
    assert HonnObserverParams(dt=0.02).A[0, 1] == 0.02
    # the 16-term basis (constant + 5 + 10; docs/plants.md#honn-observer-readings, reading 6) is one flag
    # away and gives the paper's l1
    assert HonnObserverParams(basis_bias=True).l1 == 16


def test_paper_delay_functions_are_eq18_with_h4_fixed():
    x = np.array([0.3, -1.2, 5.0, 7.0])
    np.testing.assert_allclose(paper_delay_functions(x),
                               [0.0, 2 * np.cos(0.3), 0.0, 2 * (0.09 + 1.44) * np.sin(-1.2)], rtol=1e-15)


def test_basis_is_constant_sigmoids_and_pairwise_products_of_eq19():
    x, u = np.array([10.0, -20.0, 30.0, 0.0]), np.array([50.0])
    s = (1 - np.exp(-0.01 * np.r_[x, u])) / (1 + np.exp(-0.01 * np.r_[x, u]))  # eq. 19 as printed
    np.testing.assert_allclose(bipolar(np.r_[x, u], 0.01), s, rtol=1e-13)
    phi = basis(x, u, 0.01, bias=True)
    pairs = [s[i] * s[j] for i in range(5) for j in range(i + 1, 5)]
    np.testing.assert_allclose(phi, np.r_[1.0, s, pairs], rtol=1e-13)
    np.testing.assert_allclose(basis(x, u, 0.01), np.r_[s, pairs], rtol=1e-13)


@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"dt": 0.0}, "dt"),
        ({"dt": float("nan")}, "dt"),
        ({"A": np.eye(3)}, "B"),  # n = 3 from A, B is still 4x4
        ({"A": np.ones((4, 3))}, "A"),
        ({"A": [[1.0]]}, "A"),
        ({"C": np.ones((2, 3))}, "C"),
        ({"K": np.ones((4, 3))}, "K"),
        ({"F": np.ones((2, 4))}, "F"),
        ({"D": np.zeros(4)}, "D"),
        ({"K": np.array([[np.inf, 0], [1, 0], [0, 0.3], [0, 1]])}, r"K\[0, 0\]"),
        ({"Gamma1": -0.2}, "Gamma1"),
        ({"Gamma1": np.eye(16)}, "Gamma1"),
        ({"Gamma1": np.diag(np.r_[1.0, -np.ones(14)])}, "Gamma1"),
        ({"sigma1": 1.5}, "sigma1"),
        ({"sigma1": True}, "sigma1"),
        ({"l1": 16}, "l1"),
        ({"l1": 15.0}, "l1"),
        ({"beta": 0.0}, "beta"),
        ({"d_hat": 3.1}, "d_hat"),  # not a whole number of 0.2 s periods
        ({"d_hat": -0.2}, "d_hat"),
        ({"h": "cos"}, "h"),
        ({"h": lambda x: np.zeros(3)}, "h"),
        ({"h_times_dt": 1}, "h_times_dt"),
        ({"x0_hat": np.zeros(5)}, "x0_hat"),
        ({"x0_hat": [0.0, 0.0, 0.0, 0.0]}, "x0_hat"),
        ({"W0": np.zeros((16, 4))}, "W0"),
        ({"basis_bias": "yes"}, "basis_bias"),
    ],
)
def test_params_reject_bad_values_with_the_field_named(kwargs, field):
    with pytest.raises(ValueError, match=f"^{field}"):
        HonnObserverParams(**kwargs)


def test_params_are_frozen_with_read_only_private_copies():
    K = PAPER_K.copy()
    p = HonnObserverParams(K=K)
    K[0, 0] = 99.0
    assert p.K[0, 0] == 0.3
    with pytest.raises(dataclasses.FrozenInstanceError):
        p.sigma1 = 0.1  # type: ignore[misc]
    with pytest.raises(ValueError):
        p.A[0, 0] = 2.0  # type: ignore[index]


# -- shapes, alignment, validation ------------------------------------------------------

def test_run_rows_are_xhat_k_from_x0_hat_and_equal_repeated_steps():
    Y, U = _data(40)
    x0 = np.array([0.5, -0.5, 1.0, 2.0])
    p = HonnObserverParams(x0_hat=x0)
    est = HonnObserver(p).run(Y, U)
    assert est.shape == (40, 4) and est.dtype == np.float64
    np.testing.assert_array_equal(est[0], x0)  # row 0 is x̂(0), before y(0) is used
    obs = HonnObserver(p)
    rows = [obs.estimate]
    for k in range(40):
        rows.append(obs.step(Y[k], U[k]))
    np.testing.assert_allclose(est, np.array(rows[:40]), rtol=0, atol=0)
    assert obs.k == 40
    # run continues from the current state; after it the observer holds x̂(T)
    obs2 = HonnObserver(p)
    first, second = obs2.run(Y[:25], U[:25]), obs2.run(Y[25:], U[25:])
    np.testing.assert_array_equal(np.vstack([first, second]), est)
    np.testing.assert_array_equal(obs2.estimate, rows[40])


def test_run_of_zero_samples_returns_an_empty_array():
    assert HonnObserver().run(np.zeros((0, 2)), np.zeros((0, 1))).shape == (0, 4)


@pytest.mark.parametrize(
    "Y, U, name",
    [
        (np.zeros((5, 3)), np.zeros((5, 1)), "Y"),
        (np.zeros(5), np.zeros((5, 1)), "Y"),
        (np.zeros((5, 2), dtype=np.float32), np.zeros((5, 1)), "Y"),
        ([[0.0, 0.0]] * 5, np.zeros((5, 1)), "Y"),
        (np.zeros((5, 2)), np.zeros((4, 1)), "U"),
        (np.zeros((5, 2)), np.zeros(5), "U"),
        (np.zeros((5, 2)), np.zeros((5, 1), dtype=np.int64), "U"),
    ],
)
def test_run_rejects_wrong_shapes_and_dtypes_naming_the_argument(Y, U, name):
    with pytest.raises(ValueError, match=f"^{name}"):
        HonnObserver().run(Y, U)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_data_raises_naming_the_argument_and_leaves_the_observer_unchanged(bad):
    Y, U = _data(10)
    obs = HonnObserver()
    obs.run(Y[:3], U[:3])
    before = (obs.k, obs.estimate, obs.weights)
    Yb, Ub = Y.copy(), U.copy()
    Yb[7, 1] = bad
    Ub[4, 0] = bad
    with pytest.raises(ValueError, match=r"^Y\[7, 1\]"):
        obs.run(Yb, U)
    with pytest.raises(ValueError, match=r"^U\[4, 0\]"):
        obs.run(Y, Ub)
    with pytest.raises(ValueError, match=r"^y\[0\]"):
        obs.step(np.array([bad, 0.0]), U[0])
    with pytest.raises(ValueError, match=r"^u\[0\]"):
        obs.step(Y[0], np.array([bad]))
    assert obs.k == before[0]
    np.testing.assert_array_equal(obs.estimate, before[1])
    np.testing.assert_array_equal(obs.weights, before[2])


def test_a_diverging_estimate_raises_and_leaves_the_observer_unchanged():
    obs = HonnObserver(HonnObserverParams(A=1e200 * np.eye(4), x0_hat=np.ones(4)))
    Y, U = _data(10)
    with pytest.raises(FloatingPointError, match="not finite"):
        obs.run(Y, U)
    assert obs.k == 0
    np.testing.assert_array_equal(obs.estimate, np.ones(4))


def test_common_targets_pairs_observer_row_k_with_identifier_row_k_minus_1():
    T = 6
    truth = np.arange(T * 4, dtype=np.float64).reshape(T, 4)
    obs = truth + 0.5  # rows x̂(k)
    ident = np.vstack([truth[1:], truth[-1:]]) - 0.25  # rows x̂(k+1)
    X, o, i = common_targets(truth, obs, ident)
    assert X.shape == o.shape == i.shape == (T - 1, 4)
    np.testing.assert_array_equal(X - o, -0.5)
    np.testing.assert_array_equal(X - i, 0.25)
    np.testing.assert_allclose(metrics.rmse(X, i), 0.25)
    with pytest.raises(ValueError, match="^identifier"):
        common_targets(truth, obs, ident[:-1])
    with pytest.raises(ValueError, match="^truth"):
        common_targets(truth[:1], obs[:1], ident[:1])


# -- the update laws ---------------------------------------------------------------------

def test_one_step_is_eq16_and_eq17_written_out():
    rng = np.random.default_rng(1)
    p = HonnObserverParams(dt=0.2, basis_bias=True, x0_hat=rng.standard_normal(4),
                           W0=rng.standard_normal((16, 4)), D=rng.standard_normal((4, 1)))
    y, u = rng.standard_normal(2), rng.standard_normal(1)
    obs = HonnObserver(p)
    x, W = p.x0_hat, p.W0
    phi = basis(x, u, 0.01, bias=True)
    y_tilde = y - PAPER_C @ x
    h = 0.2 * paper_delay_functions(x)  # k = 0 < d̂: the pre-history x̂(-16) = x̂(0)
    x_next = p.A @ x + (W.T @ phi + h) + PAPER_K @ y_tilde + p.D @ u
    W_next = 0.4 * W + 0.2 * np.outer(phi, np.ones((4, 2)) @ y_tilde)
    np.testing.assert_allclose(obs.step(y, u), x_next, rtol=1e-14, atol=1e-14)
    np.testing.assert_allclose(obs.weights, W_next, rtol=1e-14, atol=1e-14)


def test_weights_decay_by_one_minus_sigma1_per_step_when_the_output_error_is_zero():
    rng = np.random.default_rng(2)
    W0 = rng.standard_normal((16, 4))
    p = HonnObserverParams(basis_bias=True, W0=W0, x0_hat=rng.standard_normal(4))
    obs = HonnObserver(p)
    for k in range(1, 13):
        y = PAPER_C @ obs.estimate  # y(k) = ŷ(k): ỹ = 0
        obs.step(y, np.array([np.sin(0.3 * k)]))
        np.testing.assert_allclose(obs.weights, 0.4 ** k * W0, rtol=1e-12, atol=0)


def test_weights_decay_by_one_minus_sigma1_when_the_regressor_is_zero():
    # without the constant, Phi1(0, 0) = 0: eq. 17 is pure leakage whatever the output error
    rng = np.random.default_rng(3)
    W0 = rng.standard_normal((15, 4))
    for sigma1 in (0.6, 0.1):
        obs = HonnObserver(HonnObserverParams(W0=W0, sigma1=sigma1))
        np.testing.assert_array_equal(obs.regressor(np.zeros(1)), np.zeros(15))
        obs.step(np.array([3.0, -2.0]), np.zeros(1))
        np.testing.assert_allclose(obs.weights, (1 - sigma1) * W0, rtol=1e-15, atol=0)


def test_h_times_dt_scales_only_the_delay_term():
    x0 = np.array([0.7, -1.1, 0.2, 0.4])
    y, u = np.array([0.3, 0.1]), np.array([0.5])
    a = HonnObserver(HonnObserverParams(x0_hat=x0, h_times_dt=True)).step(y, u)
    b = HonnObserver(HonnObserverParams(x0_hat=x0, h_times_dt=False)).step(y, u)
    c = HonnObserver(HonnObserverParams(x0_hat=x0, h=None)).step(y, u)
    h = paper_delay_functions(x0)
    np.testing.assert_allclose(a - c, 0.2 * h, atol=1e-15)
    np.testing.assert_allclose(b - c, h, atol=1e-15)


# -- the delay -----------------------------------------------------------------------------

@pytest.mark.parametrize("dt, d_hat, samples", [(0.2, 3.2, 16), (0.02, 3.2, 160), (0.2, 3.0, 15), (0.02, 3.0, 150)])
def test_h_is_evaluated_at_the_estimate_d_hat_samples_back(dt, d_hat, samples):
    seen: list[np.ndarray] = []

    def h(x: np.ndarray) -> np.ndarray:
        seen.append(x.copy())
        return paper_delay_functions(x)

    p = HonnObserverParams(dt=dt, d_hat=d_hat, h=h, x0_hat=np.array([0.1, 0.2, 0.3, 0.4]))
    assert p.delay_samples == samples
    seen.clear()  # the constructor probes h once
    Y, U = _data(samples + 40, seed=4)
    est = HonnObserver(p).run(Y, U)
    assert len(seen) == samples + 40
    for k, arg in enumerate(seen):
        np.testing.assert_array_equal(arg, est[k - samples] if k >= samples else p.x0_hat)


def _delayed_plant(dt: float, d: int, steps: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """x(k+1) = A x(k) + T h(x(k - d)) + D u(k), eq. 16's model with f = 0; constant pre-history."""
    A = np.eye(4) + dt * np.array([[0, 1, 0, 0], [-1, -1, 0, 0], [0, 0, 0, 1], [0, 0, -1, -1.0]])
    D = np.array([[0.0], [dt], [0.0], [dt]])
    U = np.sin(0.3 * dt * np.arange(steps))[:, None]
    X = np.empty((steps, 4))
    X[0] = [1.0, -0.5, 0.8, 0.2]
    for k in range(steps - 1):
        X[k + 1] = A @ X[k] + dt * paper_delay_functions(X[max(k - d, 0)]) + D @ U[k]
    return A, D, X, U


@pytest.mark.parametrize("dt", [0.2, 0.02])
def test_exact_model_and_true_delay_make_the_observer_reproduce_the_plant(dt):
    d = round(3.2 / dt)  # 16 or 160 samples
    A, D, X, U = _delayed_plant(dt, d, d + 200)
    Y = X @ PAPER_C.T

    def run(d_hat: float) -> np.ndarray:
        p = HonnObserverParams(dt=dt, A=A, D=D, d_hat=d_hat, x0_hat=X[0])
        return HonnObserver(p).run(Y, U)

    np.testing.assert_allclose(run(3.2), X, rtol=1e-12, atol=1e-12)
    for off in (-1, 1):  # one sample off: the index arithmetic matters
        assert np.max(np.abs(run(round(3.2 / dt + off) * dt) - X)) > 1e-3


# -- Example 1 -----------------------------------------------------------------------------

def test_observer_on_example1_at_T_0p2_gives_finite_bounded_estimates(traj_02):
    est = observe_oscillator(traj_02)
    assert est.shape == traj_02.X.shape
    assert np.all(np.isfinite(est))
    assert np.max(np.abs(est)) < 2.0 * np.max(np.abs(traj_02.X))
    r = metrics.rmse(traj_02.X, est)
    assert np.all(r < np.ptp(traj_02.X, axis=0) / 2)  # loose: far better than "no estimate"
    print("\nHONN observer, Example 1, T = 0.2 s, 100 s: RMSE", np.round(r, 5),
          "AD", np.round(metrics.absolute_deviation(traj_02.X, est), 5))


def test_observe_oscillator_feeds_y_equal_C_x_of_the_true_states(traj_02):
    p = HonnObserverParams(dt=0.2)
    np.testing.assert_array_equal(observe_oscillator(traj_02, p),
                                  HonnObserver(p).run(traj_02.X @ PAPER_C.T, traj_02.U))
    np.testing.assert_array_equal(observe_oscillator(traj_02, measured=True), observe_oscillator(traj_02))


def test_observe_oscillator_rejects_mismatched_inputs(traj_02):
    with pytest.raises(ValueError, match=r"^params\.dt"):
        observe_oscillator(traj_02, HonnObserverParams(dt=0.02))
    with pytest.raises(ValueError, match="^traj"):
        observe_oscillator(traj_02.X)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="^measured"):
        observe_oscillator(traj_02, measured=1)  # type: ignore[arg-type]


def test_constant_basis_term_makes_the_paper_gains_diverge_on_example1(traj_02):
    # documents choice 6 of the module docstring: the 16-term basis (with the constant)
    est = observe_oscillator(traj_02, HonnObserverParams(basis_bias=True))
    assert np.max(np.abs(est)) > 1e3 * np.max(np.abs(traj_02.X))
