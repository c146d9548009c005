"""``pyrhonn identify --free-run-from K --steps-ahead H``: the report's one-step, free-run and
k-step figures are pyrhonn.simulation's on the same data, scored on samples >= K; predictions.csv
carries the aligned columns; bad settings exit 2 naming the option."""
from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from pyrhonn import Identifier, presets
from pyrhonn.cli import main
from pyrhonn.metrics import rmse, rrse
from pyrhonn.plants import Corruption, Trajectory, oscillator
from pyrhonn.simulation import simulate

from test_cli_identify import write_csv

K, H = 90, 4


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Trajectory, dict, list[dict[str, str]]]:
    traj = oscillator.simulate(dt=0.2, horizon=30.0, corruption=Corruption(dropout=0.05, seed=3))
    base = tmp_path_factory.mktemp("validation")
    data = base / "osc.csv"
    write_csv(data, traj)
    out = base / "out"
    assert main(["identify", str(data), "--config", "example1", "--out", str(out), "--free-run-from", str(K),
                 "--steps-ahead", str(H), "--warmup", "2"]) == 0
    report = json.loads((out / "metrics.json").read_text())
    with (out / "predictions.csv").open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    return out, traj, report, rows


def _direct(traj: Trajectory):
    X = np.where(traj.valid, traj.X_meas, np.nan)
    return simulate(Identifier(presets.example1()), X, traj.U, traj.valid, free_run_from=K, steps=H)


def test_report_figures_are_the_simulation_scored_on_the_unlearnt_samples(run) -> None:
    _, traj, report, _ = run
    sim = _direct(traj)
    assert report["version"] == 2 and report["free_run_from"] == K and report["ahead_steps"] == H
    for kind, estimate, first in (("one_step", sim.one_step, K), ("free_run", sim.free_run, K),
                                  ("steps_ahead", sim.ahead, K), ("one_step_learning", sim.one_step, 3)):
        stop = K if kind == "one_step_learning" else traj.n_samples
        for j, name in enumerate(traj.state_names):
            rows = np.zeros(traj.n_samples, dtype=bool)
            rows[first:stop] = True
            rows &= traj.valid[:, j]
            x, xh = traj.X_meas[rows, j][:, None], estimate[rows, j][:, None]
            got = report[kind]["states"][name]
            assert got["scored"] == int(rows.sum()), (kind, name)
            assert got["rmse"] == pytest.approx(rmse(x, xh)[0], rel=1e-12), (kind, name)
            assert got["rrse"] == pytest.approx(rrse(x, xh)[0], rel=1e-12), (kind, name)
    assert report["states"] == report["one_step"]["states"]
    assert report["free_run"]["from_line"] == K + 2 and report["free_run"]["diverged_at_line"] is None
    # fed its own outputs the network drifts: a harder test than one step ahead on this chaotic plant
    for name in traj.state_names:
        assert report["free_run"]["states"][name]["rrse"] > report["one_step"]["states"][name]["rrse"]


def test_predictions_csv_holds_the_aligned_free_run_and_k_step_columns(run) -> None:
    _, traj, _, rows = run
    sim = _direct(traj)
    assert len(rows) == traj.n_samples
    for j, name in enumerate(traj.state_names):
        free = [r[f"{name}_free_run"] for r in rows]
        ahead = [r[f"{name}_ahead{H}"] for r in rows]
        assert free[:K] == [""] * K and ahead[:H] == [""] * H
        np.testing.assert_array_equal([float(v) for v in free[K:]], sim.free_run[K:, j])
        np.testing.assert_array_equal([float(v) for v in ahead[H:]], sim.ahead[H:, j])
        np.testing.assert_array_equal([float(r[f"{name}_hat"]) for r in rows], sim.one_step[:, j])


def test_plots_show_the_free_run(run) -> None:
    out, traj, _, _ = run
    for name in traj.state_names:
        assert (out / f"{name}.png").read_bytes().startswith(b"\x89PNG")


def test_without_the_options_the_report_has_no_free_run_or_k_step_section(tmp_path: Path) -> None:
    traj = oscillator.simulate(dt=0.2, horizon=10.0)
    data = tmp_path / "d.csv"
    write_csv(data, traj, validity=False, extra=False)
    assert main(["identify", str(data), "--config", "example1", "--out", str(tmp_path / "o"), "--no-plots"]) == 0
    report = json.loads((tmp_path / "o" / "metrics.json").read_text())
    assert "free_run" not in report and "steps_ahead" not in report and "one_step_learning" not in report
    assert report["free_run_from"] is None and report["ahead_steps"] is None
    with (tmp_path / "o" / "predictions.csv").open(newline="") as fh:
        header = next(csv.reader(fh))
    assert not any(h.endswith("_free_run") or "_ahead" in h for h in header)


@pytest.mark.parametrize("args, message", [
    (["--free-run-from", "51"], "--free-run-from 51: beyond the data (51 rows, samples 0..50)"),
    (["--steps-ahead", "51"], "--steps-ahead 51: needs more than 51 data rows, the file has 51"),
])
def test_settings_beyond_the_data_exit_2_naming_the_option(tmp_path: Path, args: list[str], message: str,
                                                           capsys: pytest.CaptureFixture[str]) -> None:
    traj = oscillator.simulate(dt=0.2, horizon=10.0)
    data = tmp_path / "d.csv"
    write_csv(data, traj, validity=False, extra=False)
    assert main(["identify", str(data), "--config", "example1", "--out", str(tmp_path / "o"), "--no-plots",
                 *args]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("args", [["--free-run-from", "-1"], ["--free-run-from", "x"], ["--steps-ahead", "0"],
                                  ["--steps-ahead", "1.5"]])
def test_malformed_settings_are_usage_errors(tmp_path: Path, args: list[str]) -> None:
    with pytest.raises(SystemExit) as info:
        main(["identify", str(tmp_path / "d.csv"), "--config", "example1", *args])
    assert info.value.code == 2
