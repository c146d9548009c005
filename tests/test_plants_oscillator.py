"""Example 1 (eq. 15): the delayed oscillator integrator and its sampling."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from pyrhonn.plants import HoldWindow, oscillator
from pyrhonn.plants.oscillator import OscillatorParams


@pytest.fixture(scope="module")
def run_02():
    return oscillator.simulate(dt=0.2)


@pytest.fixture(scope="module")
def run_002():
    return oscillator.simulate(dt=0.02)


def test_default_run_samples_100_s_from_the_initial_state(run_02, run_002):
    assert run_02.X.shape == (501, 4) and run_002.X.shape == (5001, 4)
    np.testing.assert_array_equal(run_02.t, np.arange(501) * 0.2)
    np.testing.assert_array_equal(run_02.X[0], np.ones(4))
    assert run_02.state_names == ("x1", "x2", "x3", "x4") and run_02.input_names == ("u",)
    assert run_02.valid.all() and np.array_equal(run_02.X_meas, run_02.X)  # no delay in the measurement


def test_input_is_sin_0p3_t_at_the_sample_times(run_002):
    np.testing.assert_allclose(run_002.U[:, 0], np.sin(0.3 * run_002.t), rtol=0, atol=1e-15)


def test_both_sampling_periods_sample_the_same_continuous_solution(run_02, run_002):
    # ZOH sampling = the continuous solution at kT: every 10th sample at T = 0.02 s is the T = 0.2 s sample
    np.testing.assert_array_equal(run_002.X[::10], run_02.X)


def test_halving_the_internal_step_changes_samples_less_than_the_stated_bound():
    # dt = 0.02 covers the dt = 0.2 samples too; the default horizon (100 s) and step (5 ms)
    err = oscillator.convergence_error(dt=0.02)
    assert err.shape == (4,)
    assert np.all(err < oscillator.CONVERGENCE_BOUND), err


def test_integrator_error_falls_16_fold_per_halving_so_it_is_fourth_order():
    # RK4 with O(h^4) Hermite history: the step-halving difference shrinks by 2^4
    e1 = oscillator.convergence_error(dt=0.2, horizon=12.0, step=0.02)
    e2 = oscillator.convergence_error(dt=0.2, horizon=12.0, step=0.01)
    ratio = e1 / e2
    assert np.all((ratio > 12.0) & (ratio < 20.0)), ratio


def test_solution_ignores_the_delay_value_until_t_reaches_tau():
    # for t <= tau the delayed terms read the constant history, whatever tau is
    t, x3, _ = oscillator.integrate(OscillatorParams(tau=3.0), horizon=6.0)
    _, x35, _ = oscillator.integrate(OscillatorParams(tau=3.5), horizon=6.0)
    upto = t <= 3.0 + 1e-12
    np.testing.assert_array_equal(x3[upto], x35[upto])
    later = t >= 3.3
    assert np.max(np.abs(x3[later] - x35[later])) > 1e-2


def test_derivative_of_the_solution_uses_the_state_delayed_by_exactly_tau():
    params = OscillatorParams()
    h = 0.005
    t, x, _ = oscillator.integrate(params, horizon=15.0, step=h)
    N = round(params.tau / h)
    # independent derivative: 5-point central difference of the computed solution
    dx = (x[:-4] - 8 * x[1:-3] + 8 * x[3:-1] - x[4:]) / (12 * h)
    n_all = np.arange(2, len(t) - 2)
    # skip stencils that straddle the kinks the delay creates at t = 0, tau, 2 tau, ...
    phase = np.mod(n_all, N)
    n = n_all[(n_all > N + 2) & (phase > 2) & (phase < N - 2)]

    def residual(lag: int) -> float:
        f = np.array([oscillator.rhs(t[k], x[k], x[k - lag], params) for k in n[::7]])
        return float(np.max(np.abs(dx[n[::7] - 2] - f)))

    # the exact lag leaves only the O(h^4) stencil/integration error (~6e-5, on the fast x4);
    # a lag off by just two internal steps (10 ms) leaves an O(1) residual
    assert residual(N) < 2e-4
    assert residual(N - 2) > 0.1
    assert residual(N + 2) > 0.1


def test_first_two_delay_intervals_match_an_independent_scipy_method_of_steps():
    p = OscillatorParams()

    def f(t, x, xd):
        return oscillator.rhs(t, x, xd, p)

    seg1 = solve_ivp(lambda t, x: f(t, x, p.x0), (0.0, 3.0), p.x0, method="DOP853",
                     rtol=1e-12, atol=1e-12, dense_output=True)
    seg2 = solve_ivp(lambda t, x: f(t, x, seg1.sol(t - 3.0)), (3.0, 6.0), seg1.y[:, -1], method="DOP853",
                     rtol=1e-12, atol=1e-12, dense_output=True)
    traj = oscillator.simulate(dt=0.2, horizon=6.0)
    ref = np.array([seg1.sol(tk) if tk <= 3.0 else seg2.sol(tk) for tk in traj.t])
    np.testing.assert_allclose(traj.X, ref, rtol=0, atol=1e-7)


def test_state_ranges_are_those_of_a_sustained_oscillation(run_002):
    lo, hi = run_002.X.min(axis=0), run_002.X.max(axis=0)
    assert np.all(lo < -2.5) and np.all(hi > 2.5) and np.all(hi < 15.0) and np.all(lo > -15.0)


def test_hold_windows_and_corruption_apply_to_the_oscillator():
    from pyrhonn.plants import Corruption

    tr = oscillator.simulate(dt=0.2, horizon=20.0, holds=(HoldWindow(1, 5.0, 1.0),),
                             corruption=Corruption(noise_std=np.full(4, 0.01), seed=3))
    assert (~tr.valid[:, 1]).sum() == 5 and tr.valid[:, [0, 2, 3]].all()
    assert np.all(tr.X_meas[25:30, 1] == tr.X_meas[24, 1])
    np.testing.assert_array_equal(tr.X, oscillator.simulate(dt=0.2, horizon=20.0).X)


@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"tau": -1.0}, "tau"),
        ({"tau": float("nan")}, "tau"),
        ({"x0": np.ones(3)}, "x0"),
        ({"x0": [1.0, 1.0, 1.0, 1.0]}, "x0"),
        ({"input_frequency": "0.3"}, "input_frequency"),
    ],
)
def test_bad_parameters_raise_value_error_naming_the_field(kwargs, field):
    with pytest.raises(ValueError, match=rf"^{field}"):
        OscillatorParams(**kwargs)


@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"step": 0.007}, "step"),  # does not divide tau = 3
        ({"dt": 0.2, "step": 0.015}, "step"),  # divides tau but not dt
        ({"dt": 0.3, "horizon": 10.0}, "horizon"),  # horizon not a multiple of dt
        ({"dt": 0.0}, "dt"),
        ({"horizon": -5.0}, "horizon"),
    ],
)
def test_bad_simulation_settings_raise_value_error_naming_the_field(kwargs, field):
    with pytest.raises(ValueError, match=rf"^{field}"):
        oscillator.simulate(**kwargs)
