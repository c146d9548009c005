"""``pyrhonn show-config``: shipped configs by name, files by path, --list, bad names and files."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from pyrhonn import presets
from pyrhonn.cli import main
from pyrhonn.configfile import ConfigFile, save_config, shipped_names, shipped_text


def test_shipped_config_prints_its_toml_text_and_a_summary(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["show-config", "example1"]) == 0
    out = capsys.readouterr().out
    assert out.startswith(shipped_text("example1").rstrip("\n"))
    summary = out[out.index("Summary of pyrhonn/configs/example1.toml"):]
    assert "4 states: x1 = x1, x2 = x2, x3 = x3, x4 = x4" in summary and "1 input: u1 = u" in summary
    assert "neuron 2: x2(k+1) = w2' z2, 4 terms" in summary
    assert "bipolar S, beta = 0.01, P0 = 1e+08 I, Q = 500000 I, R = 10000, eta = 1" in summary
    assert "z2[2] = S(x2) * S(x1)" in summary and "z2[3] = S(x1(k-1))" in summary
    assert "z1[4] = u1" in summary and "= u\n" in summary   # the input's name beside its term variable
    assert summary.count("why: ") == 4 and "not told the 3 s delay" in summary


def test_a_file_is_shown_by_path_with_names_in_the_terms(tmp_path: Path,
                                                         capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "robot.toml"
    cf = ConfigFile.from_config(presets.example1(), state_names=("theta", "omega", "i_a", "i_b"),
                                input_names=("volts",), description="My plant.", why=("a", "", "c", ""))
    save_config(cf, path)
    assert main(["show-config", str(path)]) == 0
    out = capsys.readouterr().out
    assert out.startswith(path.read_text().rstrip("\n"))
    assert "neuron 2: x2(k+1) (omega) = w2' z2" in out
    assert "z2[2] = S(x2) * S(x1)   = S(omega) * S(theta)" in out
    assert "z2[3] = S(x1(k-1))      = S(theta(k-1))" in out
    assert "My plant." in out and out.count("why: ") == 2


def test_list_shows_every_shipped_config(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["show-config", "--list"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [line.split()[0] for line in lines] == list(shipped_names())
    assert lines[0].startswith("example1") and "Example 1" in lines[0]


@pytest.mark.parametrize("argv, message", [
    (["no_such_config"], "unknown config 'no_such_config'; shipped configs: example1"),
    (["missing.toml"], "No such file or directory"),
    ([], "give a config name or path"),
    (["example1", "--list"], "give either NAME_OR_PATH or --list, not both"),
])
def test_bad_arguments_exit_2_with_one_line(argv: list[str], message: str,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["show-config", *argv]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert captured.err.startswith("pyrhonn show-config: error: ") and message in captured.err
    assert captured.err.count("\n") == 1 and "Traceback" not in captured.err


def test_an_invalid_file_exits_2_naming_file_and_key(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(shipped_text("example1").replace("beta = 0.01", "beta = -0.01"))
    assert main(["show-config", str(path)]) == 2
    assert f"{path}: defaults.beta: must be > 0" in capsys.readouterr().err


def test_console_module_shows_a_shipped_config() -> None:
    out = subprocess.run([sys.executable, "-m", "pyrhonn.cli", "show-config", "example1"],
                         capture_output=True, text=True, check=True)
    assert 'format = "pyrhonn-config"' in out.stdout and "Summary of" in out.stdout
