"""hil.trajectory and Scenario(trajectory=...): a recorded LIM trajectory
replayed through the rig model instead of the simulated plant."""
from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

pytest.importorskip("can")
pytest.importorskip("cantools")

from hil.scenario import Scenario  # noqa: E402
from hil.score import score  # noqa: E402
from hil.trajectory import COLUMNS, read_trajectory, write_trajectory  # noqa: E402
from hil.transport import run_replay  # noqa: E402
from pyrhonn.cli import main as pyrhonn_main  # noqa: E402
from pyrhonn.plants import lim  # noqa: E402

T = 3e-4


def _plant(seconds: float, step: float = T):
    K = int(round(seconds / step))
    return lim.simulate(dt=step, horizon=K * step, inputs=lim.LimInput(start=2.0), holds=())


@pytest.fixture(scope="module")
def plant_file(tmp_path_factory):
    """The simulated LIM, 0..2.4 s at the rig's period, as a trajectory file."""
    path = tmp_path_factory.mktemp("traj") / "lim.csv"
    tr = _plant(2.4)
    write_trajectory(path, tr.t, tr.X, tr.U)
    return path


def test_the_plants_trajectory_read_back_from_a_file_gives_the_same_frames_and_truth(plant_file) -> None:
    kw = dict(duration=0.45, start=1.9, seed=5, frame_loss=0.02)     # the hold ends, the motor starts
    a, b = Scenario(**kw).build(), Scenario(**kw, trajectory=str(plant_file)).build()
    for name in ("t", "X", "U", "valid", "truth_next", "lost"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert not b.valid[:, 0].all() and b.valid[:, 0].any()


def _synthetic(n: int, step: float, t0: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    t = t0 + step * np.arange(n)
    X = np.column_stack([0.01 * np.sin(3 * t + j) for j in range(6)])
    U = np.column_stack([10 * np.cos(2 * t), 10 * np.sin(2 * t)])
    return t, X, U


def test_a_finer_log_is_sampled_every_period(tmp_path) -> None:
    t, X, U = _synthetic(400, T / 3, t0=5.0)
    path = tmp_path / "fine.csv"
    write_trajectory(path, t, X, U)
    rt = read_trajectory(path, T)
    assert rt.every == 3 and rt.step == pytest.approx(T / 3)
    assert np.array_equal(rt.t, t[::3]) and np.array_equal(rt.X, X[::3]) and np.array_equal(rt.U, U[::3])
    # times are the file's own: a scenario starts inside it
    plan = Scenario(duration=0.03, start=5.003, hold_duration=0.0, encoder_resolution=0.0,
                    velocity_from_position=False, trajectory=str(path)).build()
    assert np.array_equal(plan.X, X[30:330:3]) and np.array_equal(plan.truth_next, X[33:333:3])


@settings(max_examples=25, deadline=None)
@given(st.lists(st.floats(-1e3, 1e3, allow_nan=False, allow_subnormal=False), min_size=16, max_size=16),
       st.integers(2, 9))
def test_written_values_read_back_exactly(values, n) -> None:
    import tempfile
    from pathlib import Path

    rng = np.random.default_rng(len(values) + n)
    X = np.resize(np.asarray(values), (n, 6)) * rng.random((n, 6))
    U = np.resize(np.asarray(values[::-1]), (n, 2))
    t = T * np.arange(n)
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "x.csv"
        write_trajectory(path, t, X, U)
        rt = read_trajectory(path, T)
    assert np.array_equal(rt.X, X) and np.array_equal(rt.U, U) and np.array_equal(rt.t, t)


def _write_rows(path, rows: list[str], header: str = ",".join(COLUMNS)) -> None:
    path.write_text("\n".join([header, *rows]) + "\n")


def _row(t: float, v: str = "0") -> str:
    return ",".join([repr(t)] + [v] * 8)


@pytest.mark.parametrize("header, rows, message", [
    (",".join(COLUMNS[1:]), [",".join(["0"] * 8)] * 3, "line 1: missing column 't'"),
    (",".join(COLUMNS[:-1]), [",".join(["0"] * 8)] * 3, "missing column 'u_b'"),
    (None, [_row(0.0), _row(T), _row(2.5 * T)], "line 4: time step"),
    (None, [_row(0.0), _row(0.7e-4), _row(1.4e-4)], "does not divide the rig's period"),
    (None, [_row(0.0), _row(T, "nan"), _row(2 * T)], "line 3, column 'q_m': missing value"),
    (None, [_row(0.0), _row(T, "x"), _row(2 * T)], "line 3, column 'q_m': not a number"),
    (",".join(COLUMNS) + ",q_m_valid", [_row(0.0) + ",1", _row(T) + ",0", _row(2 * T) + ",1"],
     "line 3: q_m marked not valid"),
    (None, [_row(0.0)], "one sample only"),
])
def test_a_defective_trajectory_file_is_refused_naming_the_file_and_line(tmp_path, header, rows, message) -> None:
    path = tmp_path / "bad.csv"
    _write_rows(path, rows, header if header is not None else ",".join(COLUMNS))
    with pytest.raises(ValueError, match="bad.csv") as err:
        read_trajectory(path, T)
    assert message in str(err.value)


def test_a_trajectory_too_short_or_missing_is_refused_by_the_scenario(tmp_path, plant_file) -> None:
    with pytest.raises(ValueError, match=r"trajectory: .*covers t = 0\.\.2\.4 s.*needs 2\.3\.\.2\.6 s"):
        Scenario(duration=0.3, start=2.3, trajectory=str(plant_file)).build()
    with pytest.raises(ValueError, match="trajectory: cannot read"):
        Scenario(trajectory=str(tmp_path / "nowhere.csv"))
    with pytest.raises(ValueError, match="trajectory_sha256: given without a trajectory"):
        Scenario(trajectory_sha256="ab")
    with pytest.raises(ValueError, match="trajectory: expected a file path"):
        Scenario(trajectory=3)
    far = tmp_path / "far.csv"                    # 99 m: more than the Measurement frame can carry
    _write_rows(far, [_row(0.0), _row(T, "0").replace(",0,", ",99,", 1), _row(2 * T)])
    with pytest.raises(ValueError, match=r"Qm = 99 at t = 0\.0003 s is outside the DBC range \[-8, 8\]"):
        Scenario(duration=2 * T, hold_duration=0.0, trajectory=str(far)).build()


def test_the_scenario_pins_the_file_and_a_replaced_file_pins_its_own(tmp_path, plant_file) -> None:
    sc = Scenario(duration=0.03, start=1.0, trajectory=str(plant_file))
    assert len(sc.trajectory_sha256) == 64 and sc.trajectory == str(plant_file.resolve())
    copy = tmp_path / "copy.csv"
    copy.write_bytes(plant_file.read_bytes())
    other = tmp_path / "other.csv"
    tr = _plant(1.2)
    write_trajectory(other, tr.t, tr.X, tr.U)
    assert sc.replace(trajectory=str(copy)).trajectory_sha256 == sc.trajectory_sha256
    assert sc.replace(trajectory=str(other)).trajectory_sha256 != sc.trajectory_sha256
    assert Scenario.from_dict(sc.to_dict()) == sc


def test_a_replayed_trajectory_is_scored_against_the_file_and_a_changed_file_refuses_a_re_score(tmp_path,
                                                                                                capsys) -> None:
    path = tmp_path / "lim.csv"
    tr = _plant(2.4)
    write_trajectory(path, tr.t, tr.X, tr.U)
    log, out = tmp_path / "run.blf", tmp_path / "report"
    argv = ["hil", "replay", "--transport", "virtual", "--trajectory", str(path), "--duration", "0.3", "--start",
            "1.95", "--log", str(log), "--out", str(out)]
    assert pyrhonn_main(argv) == 0
    text = capsys.readouterr().out
    assert f"trajectory {path.resolve()}" in text and "truth: against the trajectory file's x(k+1)" in text
    assert "Identifier.run: equal" in text and "all accounted for" in text
    live = json.loads((out / "report.json").read_text())
    assert live["scenario"]["trajectory"] == str(path.resolve())
    assert pyrhonn_main(["hil", "score", str(log), "--json"]) == 0
    again = json.loads(capsys.readouterr().out)
    assert again["identification"] == live["identification"] and again["frames"] == live["frames"]
    # the truth really is the file's: scored again by hand
    r = score(run_replay(Scenario(duration=0.3, start=1.95, trajectory=str(path)), "virtual"))
    k0 = int(round(1.95 / T))
    est = r["_series"]["est"]
    assert r["identification"]["velocity"]["rmse"] == pytest.approx(
        float(np.sqrt(np.mean((est[:, 1] - tr.X[k0 + 1:k0 + 1 + est.shape[0], 1]) ** 2))), rel=1e-12)
    with path.open("a") as f:                      # the file changes after the run
        f.write(_row(2.4 + T) + "\n")
    assert pyrhonn_main(["hil", "score", str(log)]) == 2
    assert "has changed since this scenario was made" in capsys.readouterr().err


@pytest.mark.parametrize("argv, message", [
    (["hil", "replay", "--trajectory", "x.csv", "--input-start", "1"], "--input-start"),
    (["hil", "trajectory", "o.csv", "--step", "7e-5"], "--step"),
    (["hil", "trajectory", "o.csv", "--duration", "0"], "--duration"),
    (["hil", "trajectory", "o.csv", "--input-start", "-1"], "--input-start"),
    (["hil", "trajectory", "/nonexistent/dir/o.csv", "--duration", "0.01"], "/nonexistent/dir/o.csv"),
])
def test_bad_trajectory_options_exit_2(tmp_path, monkeypatch, cli_error, argv, message) -> None:
    monkeypatch.chdir(tmp_path)
    assert message in cli_error(argv)


def test_the_exported_trajectory_replays(tmp_path, capsys) -> None:
    path = tmp_path / "lim.csv"
    assert pyrhonn_main(["hil", "trajectory", str(path), "--duration", "0.6", "--step", "1e-4"]) == 0
    assert "wrote 6001 samples" in capsys.readouterr().out
    rt = read_trajectory(path, T)
    assert rt.every == 3 and rt.t[-1] == pytest.approx(0.6)
    assert pyrhonn_main(["hil", "replay", "--transport", "virtual", "--trajectory", str(path), "--duration",
                         "0.3"]) == 0
    assert "Identifier.run: equal" in capsys.readouterr().out
