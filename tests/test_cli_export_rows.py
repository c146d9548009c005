"""``pyrhonn export --data --fit-rows``: the identifier learns the rows named, nothing else."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pyrhonn.cli import main
from pyrhonn.plants import oscillator


def write(path: Path, X: np.ndarray, U: np.ndarray) -> None:
    rows = ["x1,x2,x3,x4,u"] + [",".join(repr(float(v)) for v in (*x, *u)) for x, u in zip(X, U)]
    path.write_text("\n".join(rows) + "\n")


def test_fit_rows_learn_only_those_samples(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    traj = oscillator.simulate(dt=0.2, horizon=40.0)
    whole, part = tmp_path / "whole.csv", tmp_path / "part.csv"
    write(whole, traj.X_meas, traj.U)
    write(part, traj.X_meas[50:150], traj.U[50:150])
    assert main(["export", "--config", "example1", "--data", str(whole), "--fit-rows", "50:150",
                 "--out", str(tmp_path / "a.h")]) == 0
    assert "samples 50..149 of 201" in capsys.readouterr().out
    assert main(["export", "--config", "example1", "--data", str(part), "--out", str(tmp_path / "a2.h"),
                 "--name", "a"]) == 0
    # the same weights and covariances, to the digit: the header of the rows alone
    strip = [line for line in (tmp_path / "a.h").read_text().splitlines() if "trained" not in line]
    strip2 = [line for line in (tmp_path / "a2.h").read_text().splitlines() if "trained" not in line]
    assert strip == strip2
    assert main(["export", "--config", "example1", "--data", str(whole), "--out", str(tmp_path / "b.h")]) == 0
    assert (tmp_path / "b.h").read_text() != (tmp_path / "a.h").read_text()


@pytest.mark.parametrize("extra, message", [
    (["--fit-rows", "9:3"], "--fit-rows: expected 0 <= A < B"),
    (["--fit-rows", "a:b"], "--fit-rows: expected A:B"),
    (["--fit-rows", "500:"], "--fit-rows: 500: leaves fewer than 2 of the 201 samples"),
])
def test_bad_fit_rows_are_named(tmp_path: Path, capsys: pytest.CaptureFixture[str], extra: list[str],
                                message: str) -> None:
    traj = oscillator.simulate(dt=0.2, horizon=40.0)
    whole = tmp_path / "whole.csv"
    write(whole, traj.X_meas, traj.U)
    out = tmp_path / "x.h"
    assert main(["export", "--config", "example1", "--data", str(whole), "--out", str(out), *extra]) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


def test_fit_rows_need_data(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["export", "--config", "example1", "--out", str(tmp_path / "x.h"), "--fit-rows", "0:5"]) == 2
    assert "--fit-rows: needs --data" in capsys.readouterr().err
