"""Example 3: the linear induction motor."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pyrhonn.plants import HoldWindow, lim
from pyrhonn.plants.lim import LimInput, LimParams

DT = 1e-4


@pytest.fixture(scope="module")
def paper_run():
    return lim.simulate()


def rotating_inputs(amplitude: float, freq: float, horizon: float, sign: float = 1.0) -> np.ndarray:
    t = np.arange(round(horizon / DT) + 1) * DT
    return np.column_stack([amplitude * np.cos(freq * t), sign * amplitude * np.sin(freq * t)])


def test_paper_run_has_50001_samples_of_six_states(paper_run):
    assert paper_run.X.shape == (50001, 6) and paper_run.U.shape == (50001, 2)
    assert paper_run.state_names == ("q_m", "v", "lambda_a", "lambda_b", "i_a", "i_b")
    assert paper_run.dt == DT


def test_inputs_are_zero_before_2_s_then_the_eq_21_22_chirp(paper_run):
    t, U = paper_run.t, paper_run.U
    k2 = 20000
    assert np.all(U[:k2] == 0.0)
    np.testing.assert_allclose(U[k2], [170.0, 0.0], atol=1e-9)  # phi(2) = 0
    np.testing.assert_allclose(np.hypot(U[k2:, 0], U[k2:, 1]), 170.0, rtol=1e-12)
    phi = 0.3 * t[k2:] * (98.6 / 6 * t[k2:] - 98.6 / 3)
    np.testing.assert_allclose(U[k2:, 0], 170.0 * np.cos(phi), atol=1e-9)
    np.testing.assert_allclose(U[k2:, 1], 170.0 * np.sin(phi), atol=1e-9)


def test_motor_at_rest_until_the_voltage_is_applied(paper_run):
    assert np.all(paper_run.X[:20001] == 0.0)


def test_zero_input_from_rest_stays_exactly_at_rest():
    tr = lim.simulate(horizon=0.5, inputs=np.zeros((5001, 2)), holds=())
    assert np.all(tr.X == 0.0)


def test_position_is_the_integral_of_velocity(paper_run):
    q, v = paper_run.X[:, 0], paper_run.X[:, 1]
    np.testing.assert_allclose(np.diff(q), DT * v[:-1], rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(q[1:], DT * np.cumsum(v[:-1]), rtol=1e-9, atol=1e-12)


def test_unforced_motor_loses_its_flux_current_and_speed():
    x0 = np.array([0.01, 0.3, 0.5, -0.2, 3.0, -2.0])
    tr = lim.simulate(horizon=1.0, inputs=np.zeros((10001, 2)), x0=x0, holds=())
    # electrical states die out within the rotor time constant L_r / R_r ~ 11 ms ...
    assert np.max(np.abs(tr.X[5000:, 2:])) < 1e-9
    # ... after which the carriage coasts down with the viscous rate k2 = R_m / D_m, position settling
    k2 = LimParams().constants().k2
    v = tr.X[:, 1]
    assert v[10000] / v[5000] == pytest.approx((1 - k2 * DT) ** 5000, rel=1e-9)
    assert 0.0 < v[-1] < v[5000] and np.all(np.diff(tr.X[5000:, 0]) > 0)


@settings(max_examples=10, deadline=None)
@given(freq=st.floats(20.0, 300.0), amplitude=st.floats(20.0, 170.0))
def test_reversing_the_phase_sequence_mirrors_the_motion(freq, amplitude):
    # q -> -q, v -> -v, lambda_b -> -lambda_b, i_b -> -i_b when u_b -> -u_b (exact symmetry of the model)
    a = lim.simulate(horizon=0.2, inputs=rotating_inputs(amplitude, freq, 0.2), holds=())
    b = lim.simulate(horizon=0.2, inputs=rotating_inputs(amplitude, freq, 0.2, -1.0), holds=())
    mirror = np.array([-1, -1, 1, -1, 1, -1])
    np.testing.assert_allclose(a.X, b.X * mirror, rtol=1e-9, atol=1e-12)


def test_forward_travelling_field_pushes_the_motor_forward():
    tr = lim.simulate(horizon=0.5, inputs=rotating_inputs(100.0, 2 * np.pi * 10, 0.5), holds=())
    assert tr.X[-1, 1] > 0.05 and tr.X[-1, 0] > 0.0


def test_paper_run_moves_forward_monotonically(paper_run):
    assert np.all(np.diff(paper_run.X[:, 0]) >= 0.0)


def test_position_measurement_held_for_one_second_from_2p1_s(paper_run):
    k0 = 21000
    invalid = np.flatnonzero(~paper_run.valid[:, 0])
    np.testing.assert_array_equal(invalid, np.arange(k0, k0 + 10000))
    assert np.all(paper_run.X_meas[k0:k0 + 10000, 0] == paper_run.X[k0 - 1, 0])
    assert paper_run.valid[:, 1:].all()
    ok = paper_run.valid
    np.testing.assert_array_equal(paper_run.X_meas[ok], paper_run.X[ok])


def test_all_states_reading_of_the_delay_freezes_every_state():
    tr = lim.simulate(horizon=3.5, holds=lim.paper_holds(all_states=True))
    assert np.all((~tr.valid).sum(axis=0) == 10000)
    real_time = lim.paper_holds(start=1.1)
    assert real_time == (HoldWindow(0, 1.1, 1.0),)


def test_derived_constants_match_plants_md():
    # the k_i that docs/plants.md#lim-parameters lists
    k = LimParams().constants()
    expected = {"k1": 22.8, "k2": 1.79, "k3": 0.357, "k5": 3.27, "k6": 87.6, "k7": 1.11e4, "k8": 1.40e4,
                "k9": -1453.0, "k10": -173.0}
    for name, value in expected.items():
        assert getattr(k, name) == pytest.approx(value, rel=5e-3), name


def test_sanity_figures_agree_with_the_independent_run_in_plants_md(paper_run):
    # docs/plants.md#lim-parameters: over 5 s q_m reaches ~1.06 m, v peaks at ~0.57 m/s, |i| peaks at ~31 A
    X = paper_run.X
    assert X[-1, 0] == pytest.approx(1.06, rel=0.02)
    assert X[:, 1].max() == pytest.approx(0.57, rel=0.02)
    assert np.hypot(X[:, 4], X[:, 5]).max() == pytest.approx(31.0, rel=0.05)


def test_halving_the_step_barely_moves_the_mechanical_states():
    a = lim.simulate(horizon=3.0)
    b = lim.simulate(horizon=3.0, dt=DT / 2)
    err = np.max(np.abs(a.X - b.X[::2]), axis=0)
    scale = np.max(np.abs(b.X), axis=0)
    assert np.all(err[:2] < 0.01 * scale[:2]) and np.all(err < 0.02 * scale), err / scale


def test_literal_255_factor_is_available_as_an_amplitude():
    inp = LimInput(amplitude=255 * 170.0)
    U = inp(np.array([1.0, 2.0]))
    np.testing.assert_allclose(U, [[0.0, 0.0], [43350.0, 0.0]], atol=1e-6)


@pytest.mark.parametrize(
    "kwargs, field",
    [({"L_sr": 0.05}, "L_sr"), ({"D_m": 0.0}, "D_m"), ({"R_m": -1.0}, "R_m"), ({"n_p": float("inf")}, "n_p"),
     ({"R_s": None}, "R_s")],
)
def test_bad_parameters_raise_value_error_naming_the_field(kwargs, field):
    with pytest.raises(ValueError, match=rf"^{field}:"):
        LimParams(**kwargs)


@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"horizon": 1.00005}, "horizon"),
        ({"inputs": np.zeros((10, 2))}, "inputs"),
        ({"x0": np.zeros((6, 1))}, "x0"),
        ({"holds": (HoldWindow(6, 1.0, 1.0),)}, r"holds\[0\].state"),
    ],
)
def test_bad_simulation_settings_raise_value_error_naming_the_field(kwargs, field):
    with pytest.raises(ValueError, match=rf"^{field}"):
        lim.simulate(**kwargs)


@pytest.mark.parametrize("kwargs, field", [({"amplitude": float("nan")}, "amplitude"), ({"start": -1.0}, "start")])
def test_bad_input_settings_raise_value_error_naming_the_field(kwargs, field):
    with pytest.raises(ValueError, match=rf"^{field}:"):
        LimInput(**kwargs)
