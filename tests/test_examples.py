"""The scripts of examples/ run as a user runs them and reach what they state (each checks its own
result and exits 1 otherwise): the Python API on arrays, a user's plant with an input dead time
and a dropout, the CSV pipeline, an exported identifier compiled into C, a bus recording."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"


def run_example(args: list[str], cwd: Path) -> str:
    env = dict(os.environ, PATH=f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}",
               MPLBACKEND="Agg")
    env.pop("PYTHONPATH", None)  # the installed pyrhonn, never the source tree's
    res = subprocess.run(args, cwd=cwd, env=env, capture_output=True, text=True, timeout=300, check=False)
    assert res.returncode == 0, f"{args} exited {res.returncode}:\n{res.stdout[-3000:]}\n{res.stderr[-3000:]}"
    return res.stdout


def test_python_api_example_learns_arrays_and_resumes_bit_for_bit(tmp_path: Path) -> None:
    out = run_example([sys.executable, str(EXAMPLES / "python_api.py")], tmp_path)
    assert "the restored identifier continues bit for bit: True" in out and out.rstrip().endswith("OK"), out


def test_own_plant_example_finds_the_dead_time_and_bridges_the_dropout(tmp_path: Path) -> None:
    out = run_example([sys.executable, str(EXAMPLES / "own_plant_delay_dropout.py")], tmp_path)
    assert "input dead time found in the data: 4 samples" in out and out.rstrip().endswith("OK"), out


def test_csv_pipeline_example_selects_validates_and_exports(tmp_path: Path) -> None:
    out = run_example(["bash", str(EXAMPLES / "csv_pipeline.sh"), str(tmp_path / "out")], tmp_path)
    assert "PASS" in out, out
    for name in ("model.toml", "validation/validation.json", "model.h", "model_capacity.h"):
        assert (tmp_path / "out" / name).is_file(), name


@pytest.mark.skipif(shutil.which("cc") is None, reason="no C compiler (cc) on PATH")
def test_firmware_example_steps_the_exported_identifier_in_c(tmp_path: Path) -> None:
    out = run_example(["bash", str(EXAMPLES / "firmware.sh"), str(tmp_path / "out")], tmp_path)
    assert "samples stepped in C" in out and out.rstrip().endswith("OK"), out


def test_bus_recording_example_identifies_a_candump_log_with_its_dbc(tmp_path: Path) -> None:
    out = run_example([sys.executable, str(EXAMPLES / "bus_recording.py"), str(tmp_path / "out")], tmp_path)
    assert "4 for lost clock frames" in out and out.rstrip().endswith("OK"), out
    assert (tmp_path / "out" / "id" / "samples.csv").is_file()
