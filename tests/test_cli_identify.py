"""``pyrhonn identify``: a CSV from the oscillator gives the metrics that the
Identifier and pyrhonn.metrics give directly; every bad file or option exits
2 with one line naming the file and the line."""
from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
from figure_capture import capture_figures

from pyrhonn import Identifier, presets
from pyrhonn.cli import main
from pyrhonn.configfile import ConfigFile, loads, save_config
from pyrhonn.metrics import absolute_deviation, rmse
from pyrhonn.plants import Corruption, Trajectory, oscillator

WARMUP = 3


def write_csv(path: Path, traj: Trajectory, *, validity: bool = True, extra: bool = True) -> None:
    """The trajectory as a user would export it: t, states, input, validity flags and an unused
    text column; invalid measurements alternate between an empty cell and 'nan'."""
    names = list(traj.state_names) + list(traj.input_names)
    header = ["t", *names] + ([f"{s}_valid" for s in traj.state_names] if validity else []) + \
        (["note"] if extra else [])
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        for k in range(traj.n_samples):
            cells = [repr(float(traj.t[k]))]
            for j in range(traj.n_states):
                ok = traj.valid[k, j]
                cells.append(repr(float(traj.X_meas[k, j])) if ok else ("" if k % 2 else "nan"))
            cells += [repr(float(v)) for v in traj.U[k]]
            if validity:
                cells += [str(int(v)) for v in traj.valid[k]]
            if extra:
                cells.append(f"sample {k}")
            w.writerow(cells)


@pytest.fixture(scope="module")
def dropout_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Trajectory]:
    traj = oscillator.simulate(dt=0.2, horizon=30.0, corruption=Corruption(dropout=0.1, seed=7))
    assert not traj.valid.all()
    path = tmp_path_factory.mktemp("data") / "osc.csv"
    write_csv(path, traj)
    return path, traj


def direct_metrics(traj: Trajectory, Xhat: np.ndarray, warmup: int) -> tuple[np.ndarray, np.ndarray]:
    """RMSE and absolute deviation per state from the Identifier's own run: the prediction made at
    sample k against the measurement at k+1, valid targets only, pairs k >= warmup."""
    r, ad = [], []
    for j in range(traj.n_states):
        keep = traj.valid[1:, j].copy()
        keep[:warmup] = False
        truth, est = traj.X_meas[1:, j][keep][:, None], Xhat[:-1, j][keep][:, None].astype(np.float64)
        r.append(rmse(truth, est)[0])
        ad.append(absolute_deviation(truth, est)[0])
    return np.array(r), np.array(ad)


def read_predictions(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as fh:
        return list(csv.DictReader(fh))


@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_metrics_and_predictions_match_the_identifier_run_directly(
        dropout_run: tuple[Path, Trajectory], tmp_path: Path, dtype: str,
        capsys: pytest.CaptureFixture[str]) -> None:
    data, traj = dropout_run
    out = tmp_path / "out"
    assert main(["identify", str(data), "--config", "example1", "--out", str(out), "--warmup", str(WARMUP),
                 "--dtype", dtype, "--no-plots"]) == 0
    printed = capsys.readouterr().out
    assert "ignored columns: note" in printed

    ident = Identifier(presets.example1(dtype))
    X = np.where(traj.valid, traj.X_meas, np.nan).astype(dtype)
    Xhat = ident.run(X, traj.U.astype(dtype), traj.valid)
    r, ad = direct_metrics(traj, Xhat, WARMUP)

    report = json.loads((out / "metrics.json").read_text())
    assert report["dtype"] == dtype and report["samples"] == traj.n_samples and report["warmup"] == WARMUP
    got_r = np.array([report["states"][s]["rmse"] for s in traj.state_names])
    got_ad = np.array([report["states"][s]["absolute_deviation"] for s in traj.state_names])
    np.testing.assert_allclose(got_r, r, rtol=1e-12, atol=0)
    np.testing.assert_allclose(got_ad, ad, rtol=1e-12, atol=0)
    for j, s in enumerate(traj.state_names):
        assert report["states"][s]["scored"] == int(traj.valid[1 + WARMUP:, j].sum())
        assert report["states"][s]["invalid_samples"] == int((~traj.valid[:, j]).sum())
        assert report["next_prediction"][s] == float(Xhat[-1, j])

    rows = read_predictions(out / "predictions.csv")
    assert len(rows) == traj.n_samples
    assert [int(r["line"]) for r in rows] == list(range(2, traj.n_samples + 2))
    hat = np.array([[float(r[f"{s}_hat"]) for s in traj.state_names] for r in rows])
    np.testing.assert_array_equal(hat[1:], Xhat[:-1].astype(np.float64))
    np.testing.assert_array_equal(hat[0], np.zeros(4))  # x0
    for k, row in enumerate(rows):
        for j, s in enumerate(traj.state_names):
            if k and traj.valid[k, j]:
                assert float(row[f"{s}_err"]) == traj.X_meas[k, j] - hat[k, j]
            else:
                assert row[f"{s}_err"] == ""


def test_without_validity_columns_every_sample_is_scored_as_metrics_rmse_does(tmp_path: Path) -> None:
    traj = oscillator.simulate(dt=0.2, horizon=20.0)
    data = tmp_path / "clean.csv"
    write_csv(data, traj, validity=False, extra=False)
    assert main(["identify", str(data), "--config", "example1", "--out", str(tmp_path / "o"), "--no-plots"]) == 0
    Xhat = Identifier(presets.example1()).run(traj.X_meas, traj.U)
    report = json.loads((tmp_path / "o" / "metrics.json").read_text())
    got = np.array([report["states"][s]["rmse"] for s in traj.state_names])
    np.testing.assert_allclose(got, rmse(traj.X_meas[1:], Xhat[:-1]), rtol=1e-12, atol=0)
    got = np.array([report["states"][s]["absolute_deviation"] for s in traj.state_names])
    np.testing.assert_allclose(got, absolute_deviation(traj.X_meas[1:], Xhat[:-1]), rtol=1e-12, atol=0)


def test_plots_are_one_png_per_state(dropout_run: tuple[Path, Trajectory], tmp_path: Path) -> None:
    data, traj = dropout_run
    out = tmp_path / "plots"
    assert main(["identify", str(data), "--config", "example1", "--out", str(out), "--warmup", "2"]) == 0
    for name in traj.state_names:
        png = (out / f"{name}.png").read_bytes()
        assert png.startswith(b"\x89PNG\r\n\x1a\n") and len(png) > 10_000


def test_plot_axes_carry_the_given_units_and_the_legend_names_the_not_valid_shading(
        dropout_run: tuple[Path, Trajectory], tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from pyrhonn.cli import identify as identify_cli

    data, traj = dropout_run
    saved = capture_figures(monkeypatch, identify_cli)
    first, *rest = traj.state_names
    assert main(["identify", str(data), "--config", "example1", "--out", str(tmp_path / "o"),
                 "--units", f"{first}=rad, t=s"]) == 0
    top, bottom = saved[first].axes
    assert top.get_ylabel() == f"{first} [rad]" and bottom.get_ylabel() == "error [rad]"
    assert bottom.get_xlabel() == "t [s]"
    for name in rest:
        assert saved[name].axes[0].get_ylabel() == f"{name} (no unit given)"
    shaded = [name for name in traj.state_names
              if identify_cli.NOT_VALID_LABEL in [t.get_text() for t in saved[name].axes[0].get_legend().get_texts()]]
    with open(data) as fh:
        header = next(csv.reader(fh))
    assert shaded and all(f"{name}_valid" in header for name in shaded)  # only states with dropouts are shaded


@pytest.mark.parametrize("units, message", [("x9=m", "--units: x9: not a state"), ("x1", "expected NAME=UNIT"),
                                            ("a=m,a=s", "given twice")])
def test_bad_units_are_named(dropout_run: tuple[Path, Trajectory], tmp_path: Path, units: str, message: str,
                             capsys: pytest.CaptureFixture[str]) -> None:
    data, _ = dropout_run
    try:
        code = main(["identify", str(data), "--config", "example1", "--out", str(tmp_path / "o"), "--units", units])
    except SystemExit as exc:  # argparse's own usage error
        code = exc.code
    assert code == 2 and message in capsys.readouterr().err


# -- bad files --------------------------------------------------------------------------------------

CONFIG = '''\
format = "pyrhonn-config"
version = 1
n_states = 2
n_inputs = 1
state_names = ["a", "b"]
input_names = ["u"]
[defaults]
activation = "bipolar"
beta = 0.5
p0 = 10.0
q = 0.01
r = 1.0
[[neurons]]
terms = ["S(x1)", "S(x2)", "u1", "1"]
[[neurons]]
terms = ["S(x2)", "S(x1)*u1", "1"]
'''

GOOD = "t,a,b,u,b_valid\n0,1,2,0.5,1\n0.1,1.1,2.1,0.4,1\n0.2,1.2,,0.3,0\n0.3,1.3,2.3,0.2,1\n"


@pytest.fixture
def config(tmp_path: Path) -> Path:
    path = tmp_path / "cfg.toml"
    path.write_text(CONFIG)
    return path


def identify(data: Path, config: Path, *extra: str) -> int:
    return main(["identify", str(data), "--config", str(config), "--out", str(data.parent / "out"), "--no-plots",
                 *extra])


def test_the_small_good_file_runs(tmp_path: Path, config: Path, capsys: pytest.CaptureFixture[str]) -> None:
    data = tmp_path / "data.csv"
    data.write_text(" t , a, b ,u,b_valid\r\n" + GOOD.split("\n", 1)[1].replace("\n", "\r\n") + "\r\n\r\n")
    assert identify(data, config) == 0
    report = json.loads((tmp_path / "out" / "metrics.json").read_text())
    assert report["samples"] == 4 and report["states"]["b"]["scored"] == 2
    assert "ignored columns" not in capsys.readouterr().out


BAD_DATA: list[tuple[str, bytes, str]] = [
    ("empty file", b"", ": empty file"),
    ("blank lines only", b"\n \n", ": empty file"),
    ("header only", b"t,a,b,u\n", ": line 1: header only, no data rows"),
    ("blank header line", b"\nt,a,b,u\n0,1,2,3\n", ": line 1: empty line where the header row was expected"),
    ("duplicate column", b"t,a,b,u,a\n0,1,2,3,4\n", ": line 1: duplicate column 'a' (columns 2 and 5)"),
    ("empty column name", b"t,a,,b,u\n0,1,2,3,4\n", ": line 1: column 3 has an empty name"),
    ("missing column", b"t,a,u\n0,1,2\n0.1,1,2\n", ": line 1: missing column 'b' ("),
    ("missing columns", b"t,a\n0,1\n0.1,1\n", ": line 1: missing columns 'b', 'u' ("),
    ("too few fields", GOOD.replace("0.1,1.1,2.1,0.4,1", "0.1,1.1,2.1,0.4").encode(),
     ": line 3: expected 5 fields as in the header, got 4"),
    ("too many fields", GOOD.replace("0.3,1.3,2.3,0.2,1", "0.3,1.3,2.3,0.2,1,7").encode(),
     ": line 5: expected 5 fields as in the header, got 6"),
    ("text in a state", GOOD.replace("2.1", "abc").encode(), ": line 3, column 'b': not a number: 'abc'"),
    ("python float syntax", GOOD.replace("1.1", "1_1").encode(), ": line 3, column 'a': not a number: '1_1'"),
    ("infinity", GOOD.replace("1.1", "inf").encode(), ": line 3, column 'a': not finite: 'inf'"),
    ("overflow", GOOD.replace("1.1", "1e999").encode(), ": line 3, column 'a': '1e999' is out of the float64 range"),
    ("NaN without validity column", GOOD.replace("1.2", "nan").encode(),
     ": line 4, column 'a': missing value (empty or NaN) but the state is marked valid (no a_valid column"),
    ("empty cell without validity column", GOOD.replace("1.3", "").encode(),
     ": line 5, column 'a': missing value (empty or NaN) but the state is marked valid"),
    ("NaN marked valid", GOOD.replace("2.1,0.4,1", "NaN,0.4,1").encode(),
     ": line 3, column 'b': missing value (empty or NaN) but the state is marked valid (b_valid = 1)"),
    ("bad validity flag", GOOD.replace("0.4,1", "0.4,yes").encode(),
     ": line 3, column 'b_valid': expected 0 or 1, got 'yes'"),
    ("missing input", GOOD.replace("0.4", "").encode(), ": line 3, column 'u': missing input value"),
    ("missing time", GOOD.replace("0.2,1.2", ",1.2").encode(), ": line 4, column 't': missing time"),
    ("time not increasing", GOOD.replace("0.2,1.2", "0.1,1.2").encode(),
     ": line 4, column 't': time 0.1 is not after 0.1 on line 3"),
    ("blank line inside", GOOD.replace("0.2,1.2", "\n0.2,1.2").encode(), ": line 4: empty line inside the data"),
    ("not UTF-8", GOOD.replace("0.2,1.2", "0.2,1.2\xe9").encode("latin-1"), ": line 4: not UTF-8 text"),
    ("unclosed quote", GOOD.replace("0.2,1.2", '0.2,"1.2').encode(), ": line 4: malformed CSV"),
    ("text after a quote", GOOD.replace("0.2,1.2", '0.2,"1.2"x').encode(), ": line 4: malformed CSV"),
    ("one data row", b"t,a,b,u\n0,1,2,3\n", ": line 2: only one data row"),
]


@pytest.mark.parametrize("content, message", [(c, m) for _, c, m in BAD_DATA], ids=[i for i, _, _ in BAD_DATA])
def test_bad_data_file_exits_2_naming_the_line(tmp_path: Path, config: Path, content: bytes, message: str,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    data = tmp_path / "data.csv"
    data.write_bytes(content)
    assert identify(data, config) == 2
    captured = capsys.readouterr()
    assert captured.err.startswith(f"pyrhonn identify: error: {data}{message}"), captured.err
    assert captured.err.count("\n") == 1 and "Traceback" not in captured.err
    assert not (tmp_path / "out").exists()


def test_a_missing_value_in_an_invalid_state_is_accepted(tmp_path: Path, config: Path) -> None:
    data = tmp_path / "data.csv"
    data.write_text(GOOD.replace("2.3,0.2,1", "nan,0.2,0"))
    assert identify(data, config) == 0


@pytest.mark.parametrize("change, message", [
    ({"--warmup": "3"}, "--warmup 3: leaves nothing to score (4 data rows give 3 one-step-ahead pairs)"),
    ({"--config": "no_such_config"}, "unknown config 'no_such_config'; shipped configs: example1"),
    ({"--config": "missing.toml"}, "No such file or directory"),
    ({"data": "missing.csv"}, "No such file or directory"),
])
def test_bad_options_exit_2(tmp_path: Path, config: Path, change: dict[str, str], message: str,
                            capsys: pytest.CaptureFixture[str]) -> None:
    data = tmp_path / "data.csv"
    data.write_text(GOOD)
    argv = {"data": str(data), "--config": str(config), "--out": str(tmp_path / "out")}
    argv.update({k: (str(tmp_path / v) if v.endswith((".csv", ".toml")) else v) for k, v in change.items()})
    args = [argv.pop("data")] + [x for kv in argv.items() for x in kv]
    assert main(["identify", *args, "--no-plots"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("pyrhonn identify: error: ") and message in err and "Traceback" not in err


@pytest.mark.parametrize("args", [["--warmup", "-1"], ["--warmup", "x"], ["--valid-suffix", ""],
                                  ["--dtype", "float16"], []])
def test_malformed_options_are_usage_errors(tmp_path: Path, config: Path, args: list[str]) -> None:
    data = tmp_path / "data.csv"
    data.write_text(GOOD)
    base = ["identify", str(data), "--no-plots"] + ([] if not args else ["--config", str(config)])
    with pytest.raises(SystemExit) as info:
        main(base + args)
    assert info.value.code == 2


def test_a_bad_config_exits_2_naming_its_file_and_key(tmp_path: Path, config: Path,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    data = tmp_path / "data.csv"
    data.write_text(GOOD)
    config.write_text(CONFIG.replace('"S(x1)*u1"', '"S(x3)*u1"'))
    assert identify(data, config) == 2
    assert f"{config}: neurons[1].terms[1]: 'S(x3)': state index 3 out of range 1..2" in capsys.readouterr().err
    config.write_text(CONFIG.replace('"S(x1)*u1"', '"S(x1(k-200))"'))   # beyond the compiled capacity
    assert identify(data, config) == 2
    assert f"{config}: neurons[1].terms[1][0].delay: 200 exceeds the compiled capacity" in capsys.readouterr().err


def test_a_validity_suffix_that_names_another_column_is_refused(tmp_path: Path,
                                                                 capsys: pytest.CaptureFixture[str]) -> None:
    config = tmp_path / "cfg.toml"
    config.write_text(CONFIG.replace('["a", "b"]', '["a", "a_ok"]'))
    data = tmp_path / "data.csv"
    data.write_text("a,a_ok,u\n1,2,3\n1,2,3\n")
    assert identify(data, config, "--valid-suffix", "_ok") == 2
    assert "--valid-suffix: the validity column of state 'a' would be 'a_ok'" in capsys.readouterr().err


def test_identifier_failure_names_the_data_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    config = tmp_path / "cfg.toml"
    save_config(ConfigFile.from_config(loads(CONFIG.replace('"S(x1)", "S(x2)", "u1", "1"', '"x1^2"')).config),
                config)
    data = tmp_path / "data.csv"
    data.write_text("x1,x2,u1\n1,2,3\n1,2,3\n1e200,2,3\n1,2,3\n")
    assert identify(data, config) == 2
    err = capsys.readouterr().err
    assert f"{data}: line 4: the identifier stopped: neurons[0]: weights or prediction would not be finite" in err
    data.write_text("x1,x2,u1\n1,2,3\n1e39,2,3\n1,2,3\n")
    assert identify(data, config, "--dtype", "float32") == 2
    assert f"{data}: line 3, column 'x1': 1e+39 overflows float32" in capsys.readouterr().err


def test_an_output_that_is_the_data_or_the_config_file_is_refused_before_anything_is_written(
        tmp_path: Path, cli_error) -> None:
    data = tmp_path / "predictions.csv"  # the measurements, named as identify names its own output
    data.write_text(GOOD)
    cfg = tmp_path / "cfg.toml"
    cfg.write_text(CONFIG)
    err = cli_error(["identify", str(data), "--config", str(cfg), "--out", str(tmp_path)])
    assert f"would overwrite the data file {data} with its predictions.csv" in err
    assert data.read_text() == GOOD and not (tmp_path / "metrics.json").exists()
    cfg = tmp_path / "metrics.json"  # a config by any name: the second output
    cfg.write_text(CONFIG)
    (tmp_path / "data.csv").write_text(GOOD)
    err = cli_error(["identify", str(tmp_path / "data.csv"), "--config", str(cfg), "--out", str(tmp_path)])
    assert "would overwrite the config file" in err and cfg.read_text() == CONFIG


def test_an_empty_output_folder_name_is_refused(tmp_path: Path, config: Path, cli_error) -> None:
    data = tmp_path / "data.csv"
    data.write_text(GOOD)
    assert "--out: empty" in cli_error(["identify", str(data), "--config", str(config), "--out", " "])


# -- interrupted runs ------------------------------------------------------------------------------------


def _outputs(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in folder.iterdir() if not p.name.startswith(".")}


def test_identify_killed_into_an_existing_out_leaves_whole_files_and_marks_a_mixed_folder(tmp_path: Path) -> None:
    """5 times, ``pyrhonn identify`` (a process) is killed (SIGKILL) at a random moment after it starts
    writing into an --out that holds a previous run's outputs: every file there is then whole (the
    previous run's or the new one's), and a folder whose files are not all from one run is marked
    INCOMPLETE; never a truncated file in a folder that looks finished."""
    import os
    import signal
    import subprocess
    import sys
    import time

    from pyrhonn.atomic import MARKER

    runs = {}
    for seed in (7, 8):  # two data files, two sets of outputs, each from a complete run
        traj = oscillator.simulate(dt=0.02, horizon=100.0, corruption=Corruption(dropout=0.1, seed=seed))
        write_csv(tmp_path / f"d{seed}.csv", traj)
        assert main(["identify", str(tmp_path / f"d{seed}.csv"), "--config", "example1", "--out",
                     str(tmp_path / f"ref{seed}")]) == 0
        runs[seed] = _outputs(tmp_path / f"ref{seed}")
    assert set(runs[7]) == set(runs[8]) and MARKER not in runs[7]
    out = tmp_path / "out"
    out.mkdir()
    for name, data in runs[7].items():
        (out / name).write_bytes(data)
    rng = np.random.default_rng(3)
    started = 0

    def listing() -> list[tuple[str, int, int]]:
        """The folder's entries while the process writes: a temporary file may be renamed away
        between the scan and its stat (then it is left out)."""
        entries = []
        for e in os.scandir(out):
            try:
                st = e.stat()
            except FileNotFoundError:
                continue
            entries.append((e.name, st.st_size, st.st_mtime_ns))
        return sorted(entries)

    for _ in range(5):
        before = listing()
        # the pyrhonn this interpreter imports (the installed one), from a folder that cannot shadow it
        proc = subprocess.Popen([sys.executable, "-m", "pyrhonn.cli", "identify", str(tmp_path / "d8.csv"),
                                 "--config", "example1", "--out", str(out)], cwd=str(tmp_path),
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:
            while proc.poll() is None and listing() == before:  # until it starts writing
                time.sleep(0.002)
            started += listing() != before
            time.sleep(float(rng.uniform(0.0, 1.5)))
            proc.send_signal(signal.SIGKILL)
        finally:
            proc.wait()
        now = _outputs(out)
        marked = now.pop(MARKER, None) is not None
        for name, data in now.items():
            assert data in (runs[7][name], runs[8][name]), f"{name}: neither run's whole file"
        if not marked:
            assert now in (runs[7], runs[8]), "a folder not marked INCOMPLETE mixes two runs"
    assert started == 5  # every process got as far as writing into --out (it was killed, not broken)
    # a run that finishes removes the marker and leaves the new outputs
    assert main(["identify", str(tmp_path / "d8.csv"), "--config", "example1", "--out", str(out)]) == 0
    assert _outputs(out) == runs[8]
