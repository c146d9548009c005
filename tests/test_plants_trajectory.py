"""The shared measurement model (noise, quantisation, dropouts, hold windows) and Trajectory."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pyrhonn.plants import Corruption, HoldWindow, Trajectory, measure, sample_times

DT = 0.01


def smooth_states(T: int = 400, n: int = 3) -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(T) * DT
    X = np.column_stack([np.sin((j + 1) * t) * (j + 1) + 0.1 * j for j in range(n)])
    return t, X


@settings(max_examples=60, deadline=None)
@given(state=st.integers(0, 2), k0=st.integers(1, 390), length=st.integers(1, 60))
def test_hold_window_freezes_exactly_its_samples_at_the_last_value(state, k0, length):
    t, X = smooth_states()
    X_meas, valid = measure(t, X, dt=DT, holds=(HoldWindow(state, k0 * DT, length * DT),))
    inside = np.zeros(len(t), dtype=bool)
    inside[k0:k0 + length] = True
    np.testing.assert_array_equal(valid[:, state], ~inside)
    assert np.all(X_meas[inside, state] == X[k0 - 1, state])
    np.testing.assert_array_equal(X_meas[~inside, state], X[~inside, state])
    others = [j for j in range(3) if j != state]
    assert valid[:, others].all() and np.array_equal(X_meas[:, others], X[:, others])


def test_window_start_is_robust_to_decimal_rounding():
    # 2.1 s at dt = 1e-4 is sample 21000, and 1 s is 10000 samples, despite 2.1 / 1e-4 != 21000 in binary
    t = np.arange(40000) * 1e-4
    X = np.zeros((40000, 1))
    _, valid = measure(t, X, dt=1e-4, holds=(HoldWindow(0, 2.1, 1.0),))
    np.testing.assert_array_equal(np.flatnonzero(~valid[:, 0]), np.arange(21000, 31000))


def test_window_past_the_end_is_clipped():
    t, X = smooth_states(100)
    _, valid = measure(t, X, dt=DT, holds=(HoldWindow(0, 0.95, 1.0), HoldWindow(1, 5.0, 1.0)))
    assert (~valid[:, 0]).sum() == 5 and valid[:, 1].all()


def test_invalid_first_sample_has_no_value_to_hold_and_reads_nan():
    t, X = smooth_states(50)
    X_meas, valid = measure(t, X, dt=DT, holds=(HoldWindow(1, 0.0, 0.03),))
    assert np.all(np.isnan(X_meas[:3, 1])) and not valid[:3, 1].any()
    np.testing.assert_array_equal(X_meas[3:, 1], X[3:, 1])


def test_noise_is_seeded_reproducible_and_has_the_requested_spread():
    t, X = smooth_states(20000, 2)
    c = Corruption(noise_std=np.array([0.1, 0.0]), seed=5)
    a, _ = measure(t, X, dt=DT, corruption=c)
    b, _ = measure(t, X, dt=DT, corruption=c)
    np.testing.assert_array_equal(a, b)
    assert np.std(a[:, 0] - X[:, 0]) == pytest.approx(0.1, rel=0.03)
    assert abs(np.mean(a[:, 0] - X[:, 0])) < 0.005
    np.testing.assert_array_equal(a[:, 1], X[:, 1])  # std 0: untouched
    c2, _ = measure(t, X, dt=DT, corruption=Corruption(noise_std=np.array([0.1, 0.0]), seed=6))
    assert not np.array_equal(a, c2)


def test_noise_realisation_does_not_depend_on_dropouts():
    t, X = smooth_states(500, 2)
    std = np.array([0.05, 0.05])
    clean, _ = measure(t, X, dt=DT, corruption=Corruption(noise_std=std, seed=9))
    dropped, valid = measure(t, X, dt=DT, corruption=Corruption(noise_std=std, dropout=0.2, seed=9))
    np.testing.assert_array_equal(dropped[valid], clean[valid])


@settings(max_examples=40, deadline=None)
@given(res=st.floats(1e-4, 1.0), quantiser=st.sampled_from(["floor", "round"]))
def test_quantised_readings_sit_on_the_encoder_grid(res, quantiser):
    t, X = smooth_states(300, 2)
    c = Corruption(resolution=np.array([res, 0.0]), quantiser=quantiser)
    Xm, valid = measure(t, X, dt=DT, corruption=c)
    assert valid.all()
    levels = Xm[:, 0] / res
    np.testing.assert_allclose(levels, np.round(levels), atol=1e-6)
    err = X[:, 0] - Xm[:, 0]
    if quantiser == "floor":
        assert np.all(err >= -1e-9 * res) and np.all(err < res * (1 + 1e-9))
    else:
        assert np.all(np.abs(err) <= res / 2 * (1 + 1e-9))
    np.testing.assert_array_equal(Xm[:, 1], X[:, 1])


def test_dropouts_hold_the_previous_reading_at_the_requested_rate():
    t, X = smooth_states(20000, 2)
    c = Corruption(dropout=np.array([0.1, 0.0]), seed=2)
    Xm, valid = measure(t, X, dt=DT, corruption=c)
    assert (~valid[:, 0]).mean() == pytest.approx(0.1, abs=0.01)
    assert valid[:, 1].all()
    lost = np.flatnonzero(~valid[:, 0])
    lost = lost[lost > 0]
    np.testing.assert_array_equal(Xm[lost, 0], Xm[lost - 1, 0])
    Xm2, valid2 = measure(t, X, dt=DT, corruption=c)
    np.testing.assert_array_equal(valid, valid2)
    np.testing.assert_array_equal(Xm, Xm2)


def test_noise_is_added_before_quantisation():
    t = np.arange(1000) * DT
    X = np.full((1000, 1), 0.5)
    Xm, _ = measure(t, X, dt=DT, corruption=Corruption(noise_std=np.array([0.3]), resolution=np.array([1.0]),
                                                       quantiser="round", seed=1))
    assert set(np.unique(Xm[:, 0])) <= {-1.0, 0.0, 1.0, 2.0} and len(np.unique(Xm)) >= 2


def test_by_name_builds_per_state_arrays():
    c = Corruption.by_name(("q", "v"), noise_std={"v": 0.2}, resolution={"q": 1e-3}, dropout={"q": 0.1})
    np.testing.assert_array_equal(c.noise_std, [0.0, 0.2])
    np.testing.assert_array_equal(c.resolution, [1e-3, 0.0])
    np.testing.assert_array_equal(c.dropout, [0.1, 0.0])
    with pytest.raises(ValueError, match=r"^noise_std: unknown state 'w'"):
        Corruption.by_name(("q", "v"), noise_std={"w": 0.1})


@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"noise_std": np.array([0.1, -0.1])}, r"noise_std\[1\]"),
        ({"noise_std": [0.1, 0.1]}, "noise_std"),
        ({"resolution": np.array([np.nan])}, r"resolution\[0\]"),
        ({"quantiser": "ceil"}, "quantiser"),
        ({"dropout": 1.0}, "dropout"),
        ({"dropout": np.array([0.5, -0.1])}, r"dropout\[1\]"),
        ({"seed": -1}, "seed"),
        ({"seed": 1.5}, "seed"),
    ],
)
def test_bad_corruption_raises_value_error_naming_the_field(kwargs, field):
    with pytest.raises(ValueError, match=rf"^{field}"):
        Corruption(**kwargs)


@pytest.mark.parametrize(
    "kwargs, field",
    [({"state": -1, "start": 1.0, "duration": 0.1}, "state"), ({"state": 0, "start": -1.0, "duration": 0.1}, "start"),
     ({"state": 0, "start": 1.0, "duration": 0.0}, "duration"), ({"state": 0.0, "start": 1.0, "duration": 1.0}, "state")],
)
def test_bad_hold_window_raises_value_error_naming_the_field(kwargs, field):
    with pytest.raises(ValueError, match=rf"^{field}:"):
        HoldWindow(**kwargs)


def test_measure_rejects_mismatched_inputs():
    t, X = smooth_states(10, 2)
    with pytest.raises(ValueError, match=r"^holds\[0\].state"):
        measure(t, X, dt=DT, holds=(HoldWindow(2, 0.0, 0.1),))
    with pytest.raises(ValueError, match=r"^corruption.resolution"):
        measure(t, X, dt=DT, corruption=Corruption(resolution=np.ones(3)))
    with pytest.raises(ValueError, match=r"^X"):
        measure(t, X.astype(np.float32), dt=DT)
    with pytest.raises(ValueError, match=r"^holds\[0\]"):
        measure(t, X, dt=DT, holds=((0, 0.0, 0.1),))


def make_trajectory(**changes):
    t, X = smooth_states(20, 2)
    fields = dict(t=t, X=X, U=np.zeros((20, 1)), valid=np.ones((20, 2), dtype=bool), X_meas=X.copy(),
                  state_names=("a", "b"), input_names=("u",), dt=DT)
    fields.update(changes)
    return Trajectory(**fields)


@pytest.mark.parametrize(
    "changes, field",
    [
        ({"X": np.zeros((20, 2), dtype=np.float32)}, "X"),
        ({"U": np.zeros((19, 1))}, "U"),
        ({"valid": np.ones((20, 2))}, "valid"),
        ({"X_meas": np.full((20, 2), np.nan)}, r"X_meas\[0, 0\]"),
        ({"t": np.arange(20) * 0.02}, "t"),
        ({"state_names": ["a", "b"]}, "state_names"),
        ({"dt": 0.0}, "dt"),
    ],
)
def test_trajectory_rejects_inconsistent_fields(changes, field):
    with pytest.raises(ValueError, match=rf"^{field}"):
        make_trajectory(**changes)


def test_remeasure_keeps_the_truth_and_changes_only_the_measurement():
    tr = make_trajectory()
    held = tr.remeasure(holds=(HoldWindow(0, 0.05, 0.05),))
    np.testing.assert_array_equal(held.X, tr.X)
    assert (~held.valid).sum() == 5 and held.metadata["holds"] == [{"state": 0, "start": 0.05, "duration": 0.05}]
    np.testing.assert_array_equal(tr.state("b"), tr.X[:, 1])


def test_sample_times_include_both_ends_and_demand_a_whole_number_of_periods():
    np.testing.assert_array_equal(sample_times(0.2, 1.0), np.arange(6) * 0.2)
    with pytest.raises(ValueError, match=r"^horizon"):
        sample_times(0.3, 1.0)
