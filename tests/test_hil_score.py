"""hil.score's identification figures (Table 7): each measure is
recomputed here from the scenario's plan and the estimates, with numpy and
nothing from hil.score or pyrhonn.metrics."""
from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("can")
pytest.importorskip("cantools")

from hil import report  # noqa: E402
from hil.scenario import TABLE7, Scenario  # noqa: E402
from hil.score import score  # noqa: E402
from hil.transport import run_replay  # noqa: E402


def _rmse(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean((np.asarray(a, np.float64) - np.asarray(b, np.float64)) ** 2)))


def _scored(sc: Scenario) -> tuple[dict, object]:
    r = score(run_replay(sc, "virtual"))
    assert r["frames"]["answered"] == sc.cycles  # every cycle answered: the series below is complete
    return r, sc.build()


def test_truth_no_hold_measured_and_sensor_errors_are_the_documented_comparisons() -> None:
    # 1.95 s .. 2.25 s: the hold ends at 2.1 s, the voltages switch on at 2.0 s
    r, plan = _scored(Scenario(duration=0.3, start=1.95, seed=4))
    est = r["_series"]["est"]
    truth = np.asarray(plan.truth_next)
    X, V = np.asarray(plan.X), np.asarray(plan.valid)
    fresh_next = np.append(V[1:, 0], True)
    assert 0 < int((~fresh_next).sum()) < plan.cycles       # the window holds and releases the position
    for j, name in enumerate(("position", "velocity")):
        got = r["identification"][name]
        assert got["rmse"] == pytest.approx(_rmse(truth[:, j], est[:, j]), rel=1e-12)
        fresh = np.append(V[1:, j], True) & V[:, j]    # sample and target both measured
        assert got["outside_hold"]["cycles"] == int(fresh.sum())
        assert got["outside_hold"]["rmse"] == pytest.approx(_rmse(truth[fresh, j], est[fresh, j]), rel=1e-12)
        nxt = np.append(V[1:, j], True)[:-1]
        assert got["vs_measurement"]["cycles"] == int(nxt.sum())
        assert got["vs_measurement"]["rmse"] == pytest.approx(_rmse(X[1:, j][nxt], est[:-1, j][nxt]), rel=1e-12)
        assert got["measurement_vs_truth"]["rmse"] == pytest.approx(_rmse(X[1:, j][nxt], truth[:-1, j][nxt]),
                                                                    rel=1e-12)
        assert (got["table7_rmse"], got["table7_absolute_deviation"]) == (TABLE7[name]["rmse"],
                                                                          TABLE7[name]["absolute_deviation"])
    # the held position is far from the truth once the motor moves: outside the hold is the smaller error
    pos = r["identification"]["position"]
    assert pos["outside_hold"]["rmse"] < pos["rmse"]
    text = report.table(r)
    assert f"{pos['measurement_vs_truth']['rmse']:.3e}" in text and f"{pos['outside_hold']['rmse']:.3e}" in text
    # the hold's scale: how far the truth ran from the held value, and the frames' own error, held ones included
    held = ~fresh_next[:-1]
    gap = np.abs(X[1:, 0] - truth[:-1, 0])
    assert pos["hold"]["cycles"] == int(held.sum())
    assert pos["hold"]["travel_max"] == pytest.approx(float(gap[held].max()), rel=1e-12)
    assert pos["hold"]["travel_max"] > 1e-3                 # the motor moves from 2.0 s, the hold ends at 2.1 s
    assert pos["hold"]["frames_rmse"] == pytest.approx(_rmse(X[1:, 0], truth[:-1, 0]), rel=1e-12)
    assert f"position held for {int(held.sum())} cycles" in text and f"{pos['hold']['frames_rmse']:.3e}" in text
    # inside the hold alone: the estimates and the held frames against the truth, the same cycles
    assert pos["hold"]["estimate_rmse_inside"] == pytest.approx(_rmse(est[:-1, 0][held], truth[:-1, 0][held]),
                                                                rel=1e-12)
    assert pos["hold"]["frames_rmse_inside"] == pytest.approx(_rmse(X[1:, 0][held], truth[:-1, 0][held]), rel=1e-12)
    ratio = 100 * pos["hold"]["estimate_rmse_inside"] / pos["hold"]["frames_rmse_inside"]
    assert f"the held frames {pos['hold']['frames_rmse_inside']:.3e} ({ratio:.1f} %)" in text
    # the velocity, differenced from the held position, is not fresh through the hold and one frame after
    vel = r["identification"]["velocity"]["hold"]
    assert vel["cycles"] == int(held.sum()) + 1 and f"velocity held for {vel['cycles']} cycles" in text
    assert r["not_valid"] == {"Qm": {"held": int((~V[:, 0]).sum()), "derived": 0},
                              "V": {"held": 0, "derived": int((~V[:, 1]).sum())}}


def test_the_sensor_error_is_the_encoders_quantisation_and_zero_without_it() -> None:
    moving = Scenario(duration=0.15, start=2.2, hold_duration=0.0, seed=2)
    exact, _ = _scored(moving.replace(encoder_resolution=0.0, velocity_from_position=False))
    for name in ("position", "velocity"):
        assert exact["identification"][name]["measurement_vs_truth"]["rmse"] == 0.0
    quantised, _ = _scored(moving)
    pos = quantised["identification"]["position"]["measurement_vs_truth"]["rmse"]
    vel = quantised["identification"]["velocity"]["measurement_vs_truth"]["rmse"]
    count = moving.encoder_resolution
    assert count / 4 < pos < count                          # floor quantiser: uniform in [0, count)
    assert count / moving.period / 6 < vel < count / moving.period  # differences of two such errors / T


def test_a_drain_cut_short_is_reported_beside_the_missing_estimates() -> None:
    rec = run_replay(Scenario(duration=0.03), "virtual")
    r = score(rec)
    assert r["drain"]["capped"] is False and r["drain"]["s"] >= 0.3  # the default: 0.3 s of quiet
    assert "the drain stopped" not in report.table(r)
    rec.meta["drain_capped"] = True
    text = report.table(score(rec))
    assert f"the drain stopped after {rec.meta['drain_s']:.1f} s" in text and "--drain" in text
