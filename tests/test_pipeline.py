"""From a recording to firmware without writing a term by hand, on the command line:
``pyrhonn select`` -> ``tune`` -> ``identify --free-run-from`` -> ``export``; the exported
float32 header, compiled with the C core, continues exactly as the Python identifier does."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from pyrhonn import Identifier
from pyrhonn.cli import main
from pyrhonn.configfile import load_named
from pyrhonn.plants import oscillator

from test_cli_identify import write_csv
from test_export import CC, run_driver

SPLIT = 200


@pytest.mark.skipif(CC is None, reason="no C compiler on PATH")
def test_select_tune_identify_free_run_and_export_to_firmware(tmp_path: Path,
                                                             capsys: pytest.CaptureFixture[str]) -> None:
    traj = oscillator.simulate(dt=0.2, horizon=60.0)
    data, learn = tmp_path / "run.csv", tmp_path / "learn.csv"
    write_csv(data, traj, validity=False, extra=False)
    with data.open() as fh:  # the first SPLIT samples: what the firmware's weights are trained on
        learn.write_text("".join(line for _, line in zip(range(SPLIT + 1), fh)))

    assert main(["select", str(data), "--states", "x1,x2,x3,x4", "--inputs", "u", "--out",
                 str(tmp_path / "selected.toml"), "--max-delay", "15", "--delay-step", "5", "--degree", "2",
                 "--max-terms", "10"]) == 0
    assert main(["tune", "--data", str(data), "--config", str(tmp_path / "selected.toml"), "--out",
                 str(tmp_path / "tuned.toml"), "--trials", "4", "--dtype", "float32"]) == 0
    tuned = load_named(str(tmp_path / "tuned.toml"))
    assert tuned.config.dtype == "float32" and tuned.config.max_delay >= 5  # delayed taps were selected

    out = tmp_path / "identified"
    assert main(["identify", str(data), "--config", str(tmp_path / "tuned.toml"), "--out", str(out),
                 "--free-run-from", str(SPLIT), "--steps-ahead", "5", "--no-plots"]) == 0
    report = json.loads((out / "metrics.json").read_text())
    for kind in ("one_step", "free_run", "steps_ahead"):
        for name in ("x1", "x2", "x3", "x4"):
            st = report[kind]["states"][name]
            assert st["scored"] == traj.n_samples - SPLIT
            assert st["rmse"] is not None and st["rrse"] is not None, (kind, name)
    # one step ahead from measured values, with weights that never saw these samples: still useful
    assert max(report["one_step"]["states"][s]["rrse"] for s in ("x1", "x2", "x3", "x4")) < 0.7

    assert main(["export", "--config", str(tmp_path / "tuned.toml"), "--data", str(learn), "--out",
                 str(tmp_path / "exported.h"), "--name", "EXPORTED"]) == 0
    assert "trained online on" in capsys.readouterr().out
    X, U = traj.X_meas.astype(np.float32), traj.U.astype(np.float32)
    valid = np.ones(X.shape, dtype=bool)
    trained = Identifier(tuned.config)
    trained.run(X[:SPLIT], U[:SPLIT])
    python = Identifier(trained.as_config()).run(X[SPLIT:], U[SPLIT:])
    # built with the capacity header the export wrote: the firmware's RAM sized for this identifier
    firmware = run_driver(tmp_path, "float32", X[SPLIT:], U[SPLIT:], valid[SPLIT:],
                          defines=('-DRHONN_USER_CAPACITY="exported_capacity.h"',))
    np.testing.assert_array_equal(firmware.astype(np.float32), python)
    assert (tmp_path / "exported_capacity.h").exists()


def test_export_command_refuses_bad_options_naming_them(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    cases = [
        (["--config", "example1", "--out", str(tmp_path / "x.c")], "--out"),
        (["--config", "example1", "--out", str(tmp_path / "x.h"), "--warm-start"], "--warm-start: needs --data"),
        (["--config", "example1", "--out", str(tmp_path / "x.h"), "--name", "int"], "name: 'int' is a C keyword"),
        (["--config", "example1", "--out", str(tmp_path / "x.h"), "--data", str(tmp_path / "none.csv")],
         "No such file"),
    ]
    for args, message in cases:
        assert main(["export", *args]) == 2
        err = capsys.readouterr().err
        assert message in err and "Traceback" not in err, err
    assert not list(tmp_path.glob("x*.h"))


def test_export_names_the_line_of_a_value_the_firmware_precision_cannot_hold(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    data = tmp_path / "big.csv"
    data.write_text("x1,x2,x3,x4,u\n1,1,1,1,0\n1,1e39,1,1,0\n")
    assert main(["export", "--config", "example1", "--data", str(data), "--dtype", "float32", "--out",
                 str(tmp_path / "e.h")]) == 2
    err = capsys.readouterr().err
    assert "line 3, column 'x2': 1e+39 overflows float32" in err and not (tmp_path / "e.h").exists()


def test_export_command_writes_the_config_as_is_without_data(tmp_path: Path) -> None:
    assert main(["export", "--config", "firmware-lim", "--out", str(tmp_path / "lim.h"), "--dtype", "float32"]) == 0
    text = (tmp_path / "lim.h").read_text()
    assert "static const rhonn_config lim" in text and (tmp_path / "lim_capacity.h").exists()
