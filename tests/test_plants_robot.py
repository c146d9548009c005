"""Example 2: the electrically driven differential robot."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pyrhonn.plants import Corruption, robot
from pyrhonn.plants.robot import ChirpInput, RobotParams

DT = 0.01


@pytest.fixture(scope="module")
def paper_run():
    return robot.simulate()


def constant_inputs(u1: float, u2: float, horizon: float = 15.0) -> np.ndarray:
    T = round(horizon / DT) + 1
    return np.column_stack([np.full(T, u1), np.full(T, u2)])


def test_paper_run_has_1501_samples_of_seven_states(paper_run):
    assert paper_run.X.shape == (1501, 7) and paper_run.U.shape == (1501, 2)
    assert paper_run.state_names == ("X", "Y", "theta", "omega1", "omega2", "i1", "i2")
    np.testing.assert_array_equal(paper_run.X[0], np.zeros(7))


def test_inputs_are_sin_and_cos_of_the_proposed_chirp(paper_run):
    t = paper_run.t
    c = np.sin(2 * np.pi * (0.1 + 0.0045 * t) * t)
    np.testing.assert_allclose(paper_run.U, np.column_stack([np.sin(c), np.cos(c)]), rtol=0, atol=1e-14)


def test_zero_input_from_rest_stays_exactly_at_rest():
    tr = robot.simulate(inputs=constant_inputs(0.0, 0.0), holds=())
    assert np.all(tr.X == 0.0)


def test_each_pose_step_is_euler_of_J_theta_times_wheel_speeds(paper_run):
    p = RobotParams()
    X, Y, th, w1, w2 = (paper_run.X[:, j] for j in range(5))
    v = p.r / 2 * (w1 + w2)
    np.testing.assert_allclose(np.diff(X), DT * v[:-1] * np.cos(th[:-1]), rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(np.diff(Y), DT * v[:-1] * np.sin(th[:-1]), rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(np.diff(th), DT * p.r / (2 * p.b) * (w1 - w2)[:-1], rtol=1e-12, atol=1e-15)


def test_pose_is_the_integral_of_the_wheel_speeds_against_a_continuous_reference(paper_run):
    # the continuous model with the same ZOH inputs, solved tightly: Euler at 10 ms stays close
    p = RobotParams()
    U = paper_run.U

    ref = np.empty_like(paper_run.X)
    ref[0] = 0.0
    x = np.zeros(7)
    h = DT / 4  # classical RK4 at 2.5 ms, input held over each 10 ms sample (ZOH)
    for k in range(len(U) - 1):
        for _ in range(4):
            k1 = robot.rhs(x, U[k], p)
            k2 = robot.rhs(x + h / 2 * k1, U[k], p)
            k3 = robot.rhs(x + h / 2 * k2, U[k], p)
            k4 = robot.rhs(x + h * k3, U[k], p)
            x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        ref[k + 1] = x
    scale = np.ptp(ref, axis=0)
    err = np.abs(paper_run.X - ref)
    # the pose follows the continuous integral of the wheel speeds to 0.1% of its range
    assert np.all(err[:, :3].max(axis=0) < 1e-3 * scale[:3]), err[:, :3].max(axis=0) / scale[:3]
    # the Euler plant stays close overall (RMS < 3% of range) and ends within 2% (docs/plants.md#robot-model);
    # omega1 ends near zero, so it gets an absolute bound (docs/plants.md: ~0.006 rad/s)
    assert np.all(np.sqrt(np.mean(err ** 2, axis=0)) < 0.03 * scale)
    end = err[-1]
    assert np.all((end < 0.02 * np.abs(ref[-1])) | (end < 0.01)), end


def test_equal_voltages_drive_the_robot_in_a_straight_line():
    tr = robot.simulate(inputs=constant_inputs(1.0, 1.0), holds=())
    X, Y, th, w1, w2, i1, i2 = tr.X.T
    np.testing.assert_array_equal(w1, w2)
    np.testing.assert_array_equal(i1, i2)
    assert np.all(th == 0.0) and np.all(Y == 0.0)
    assert np.all(np.diff(X) >= 0) and np.all(np.diff(X)[2:] > 0)  # moves from the 3rd step on


def test_constant_voltage_reaches_the_analytic_steady_wheel_speed():
    # straight line at steady state: N K_T i = d omega and u = R_a i + K_E N omega
    p = RobotParams()
    u = 2.0
    tr = robot.simulate(inputs=constant_inputs(u, u), holds=())
    w_ss = u / (p.R_a * p.d_m1 / (p.N * p.K_T) + p.K_E * p.N)
    np.testing.assert_allclose(tr.X[-1, 3:5], [w_ss, w_ss], rtol=1e-6)
    np.testing.assert_allclose(tr.X[-1, 5:7], p.d_m1 * w_ss / (p.N * p.K_T) * np.ones(2), rtol=1e-6)


@settings(max_examples=20, deadline=None)
@given(u1=st.floats(-3, 3), u2=st.floats(-3, 3))
def test_swapping_the_motor_voltages_mirrors_the_motion(u1, u2):
    # mirror about the X axis: Y -> -Y, theta -> -theta, right and left wheels swap
    a = robot.simulate(inputs=constant_inputs(u1, u2, 3.0), horizon=3.0, holds=())
    b = robot.simulate(inputs=constant_inputs(u2, u1, 3.0), horizon=3.0, holds=())
    mirrored = b.X[:, [0, 1, 2, 4, 3, 6, 5]] * np.array([1, -1, -1, 1, 1, 1, 1])
    np.testing.assert_allclose(a.X, mirrored, rtol=1e-9, atol=1e-12)


def test_paper_hold_windows_freeze_ten_samples_of_each_state(paper_run):
    starts = (13.0, 9.0, 5.0, 8.0, 6.0, 1.0, 4.0)
    for j, s in enumerate(starts):
        k0 = round(s / DT)
        invalid = np.flatnonzero(~paper_run.valid[:, j])
        np.testing.assert_array_equal(invalid, np.arange(k0, k0 + 10))
        assert np.all(paper_run.X_meas[k0:k0 + 10, j] == paper_run.X[k0 - 1, j])
        ok = paper_run.valid[:, j]
        np.testing.assert_array_equal(paper_run.X_meas[ok, j], paper_run.X[ok, j])


def test_sanity_figures_agree_with_the_independent_run_in_plants_md(paper_run):
    # docs/plants.md#robot-scenario: X drifts ~0.7 m, theta ends near -0.71 rad, |omega| < 1 rad/s, |i| < 0.4 A
    X = paper_run.X
    assert abs(X[-1, 0] - 0.70) < 0.05
    assert abs(X[-1, 2] - (-0.71)) < 0.05
    assert np.max(np.abs(X[:, 3:5])) < 1.0
    assert np.max(np.abs(X[:, 5:7])) < 0.4


def test_noise_quantisation_and_dropouts_are_seeded_and_reproducible():
    c = Corruption(noise_std=np.full(7, 1e-3), resolution=np.array([1e-3, 1e-3, 0, 0, 0, 0, 0]),
                   dropout=0.05, seed=11)
    a, b = robot.simulate(corruption=c), robot.simulate(corruption=c)
    np.testing.assert_array_equal(a.X_meas, b.X_meas)
    np.testing.assert_array_equal(a.valid, b.valid)
    other = robot.simulate(corruption=Corruption(noise_std=np.full(7, 1e-3), resolution=c.resolution,
                                                 dropout=0.05, seed=12))
    assert not np.array_equal(a.X_meas, other.X_meas)
    np.testing.assert_array_equal(a.X, other.X)


def test_explicit_no_holds_leaves_every_sample_valid():
    assert robot.simulate(holds=()).valid.all()


@pytest.mark.parametrize(
    "kwargs, field",
    [({"r": 0.0}, "r"), ({"m_c": float("nan")}, "m_c"), ({"d_m1": -0.1}, "d_m1"), ({"L_a": "0.048"}, "L_a"),
     ({"N": True}, "N")],
)
def test_bad_parameters_raise_value_error_naming_the_field(kwargs, field):
    with pytest.raises(ValueError, match=rf"^{field}:"):
        RobotParams(**kwargs)


@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"inputs": np.zeros((1500, 2))}, "inputs"),
        ({"inputs": np.zeros((1501, 2), dtype=np.float32)}, "inputs"),
        ({"x0": np.zeros(6)}, "x0"),
        ({"dt": 0.007}, "horizon"),
        ({"params": {"r": 0.15}}, "params"),
        ({"corruption": Corruption(noise_std=np.ones(4))}, "corruption.noise_std"),
    ],
)
def test_bad_simulation_settings_raise_value_error_naming_the_field(kwargs, field):
    with pytest.raises(ValueError, match=rf"^{field}"):
        robot.simulate(**kwargs)


def test_bad_chirp_raises_value_error_naming_the_field():
    with pytest.raises(ValueError, match=r"^t1:"):
        ChirpInput(t1=0.0)
