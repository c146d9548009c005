"""Bad lengths and bad logs: refused up front with one clear error.

- ``hil score`` / ``read_log`` on a log that is not a BLF (random bytes,
  empty, truncated) or with a sidecar that is not a JSON object.
- Simulated runs longer than ``pyrhonn.plants.trajectory.MAX_SAMPLES``
  samples (or oscillator RK4 steps), through the API and every CLI that
  simulates, before anything of that size is allocated.
- The sample times of a long run (t ~ 3600 s) are uniform despite float64
  rounding; genuinely non-uniform times are still refused; a replay that the
  DBC cannot carry says which options put the plant there.
- ``hil replay``/``score``/``bench``: output paths checked before the run,
  --cycles named, options a transport would ignore refused.
"""
from __future__ import annotations

import json
import re
import shutil
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("can")
pytest.importorskip("cantools")

import hil.transport  # noqa: E402
from hil.rig import read_log  # noqa: E402
from pyrhonn.cli import main as pyrhonn_main  # noqa: E402
from pyrhonn.plants import lim, oscillator, robot  # noqa: E402
from pyrhonn.plants import trajectory as plant_trajectory  # noqa: E402
from pyrhonn.plants.trajectory import MAX_SAMPLES, Trajectory, sample_times  # noqa: E402

T = 3e-4  # the rig's period


@pytest.fixture(scope="module")
def recorded_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A real 0.01 s virtual run's log (and its sidecar)."""
    log = tmp_path_factory.mktemp("run") / "run1.blf"
    assert pyrhonn_main(["hil", "replay", "--transport", "virtual", "--duration", "0.01", "--log", str(log)]) == 0
    assert log.is_file() and Path(str(log) + ".json").is_file()
    return log


@pytest.fixture
def no_replay(monkeypatch: pytest.MonkeyPatch) -> None:
    """Fail the test if the CLI gets as far as replaying."""
    def refuse(*args, **kwargs):
        raise AssertionError("the replay ran although its options were bad")

    monkeypatch.setattr(hil.transport, "run_replay", refuse)


def _copy_log(run: Path, folder: Path, name: str, content: bytes | None = None,
              sidecar: str | None = None) -> Path:
    log = folder / name
    if content is None:
        shutil.copyfile(run, log)
    else:
        log.write_bytes(content)
    side = Path(str(log) + ".json")
    if sidecar is None:
        shutil.copyfile(Path(str(run) + ".json"), side)
    else:
        side.write_text(sidecar)
    return log


# -- 1. logs that are not logs --------------------------------------------------------------------


@pytest.mark.parametrize("content", [np.random.default_rng(7).bytes(3000), b"", "head"],
                         ids=["random bytes", "empty", "truncated header"])
def test_score_of_a_log_that_is_not_a_blf_exits_2_naming_the_log(recorded_run, tmp_path, cli_error,
                                                                 content) -> None:
    data = recorded_run.read_bytes()[:10] if content == "head" else content
    log = _copy_log(recorded_run, tmp_path, "junk.blf", data)
    with pytest.raises(ValueError, match=rf"^log: {log}: "):
        read_log(log)
    err = cli_error(["hil", "score", str(log)])
    assert f"log: {log}: " in err and len(err.strip().splitlines()) == 1


@pytest.mark.parametrize("sidecar", ['"abc"', "42", "null", "[]", "{}"])
def test_a_sidecar_that_is_not_a_json_object_with_a_scenario_is_refused_naming_it(recorded_run, tmp_path,
                                                                                  cli_error, sidecar) -> None:
    log = _copy_log(recorded_run, tmp_path, "run.blf", sidecar=sidecar)
    with pytest.raises(ValueError, match=rf"^log: {log}\.json: not a hil log sidecar"):
        read_log(log)
    assert f"log: {log}.json: not a hil log sidecar" in cli_error(["hil", "score", str(log)])


@pytest.mark.parametrize("field, value", [("first_run_event", [1]), ("t0_ns", "0"), ("first_timestamp", "x"),
                                          ("t0_ns", 2 ** 70), ("rx_pickup_us", 5), ("rx_pickup_us", {"n": "1"})])
def test_a_sidecar_field_of_the_wrong_type_is_refused_naming_the_sidecar_and_field(recorded_run, tmp_path,
                                                                                    cli_error, field,
                                                                                    value) -> None:
    meta = json.loads(Path(str(recorded_run) + ".json").read_text())
    meta[field] = value
    log = _copy_log(recorded_run, tmp_path, "run.blf", sidecar=json.dumps(meta))
    err = cli_error(["hil", "score", str(log)])
    assert f"log: {log}.json: not a hil log sidecar ({field}:" in err


# -- 2. huge simulated lengths --------------------------------------------------------------------


@pytest.mark.parametrize("simulate, kwargs", [
    (lim.simulate, {"horizon": 1e9}),
    (robot.simulate, {"horizon": 1e9}),
    (oscillator.simulate, {"dt": 1e-12}),  # the RK4 grid's own limit: see the next tests
    (lambda **kw: sample_times(**kw), {"dt": 1e-4, "horizon": 1e300}),
])
def test_a_run_longer_than_max_samples_is_refused_up_front_naming_the_horizon(simulate, kwargs) -> None:
    tracemalloc.start()
    try:
        with pytest.raises(ValueError, match=r"^horizon: \S+ s at dt \S+ s is \S+ samples \(limit 2\.5e7\)"):
            simulate(**kwargs)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 10 * 2 ** 20  # refused before anything of that size was allocated


def test_the_max_samples_message_reads_as_the_horizon_dt_and_count() -> None:
    with pytest.raises(ValueError, match=r"^horizon: 1e9 s at dt 0\.0001 s is 1e13 samples \(limit 2\.5e7\)"):
        lim.simulate(horizon=1e9)


def test_the_limit_is_exact_and_covers_the_oscillators_internal_rk4_grid(monkeypatch) -> None:
    monkeypatch.setattr(plant_trajectory, "MAX_SAMPLES", 101)
    assert sample_times(0.01, 1.0).size == 101                      # exactly the limit: accepted
    with pytest.raises(ValueError, match=r"^horizon: 1\.01 s at dt 0\.01 s is 102 samples \(limit 101\)"):
        sample_times(0.01, 1.01)
    # 27 samples at dt = 0.02, but 105 points of the 5 ms RK4 grid: the grid is what would exhaust memory
    with pytest.raises(ValueError, match=r"^horizon: 0\.52 s at step 0\.005 s is 105 RK4 grid points \(limit 101\)"):
        oscillator.simulate(dt=0.02, horizon=0.52)
    with pytest.raises(ValueError, match=r"^horizon: .* RK4 grid points"):
        oscillator.integrate(horizon=0.505)
    assert oscillator.integrate(horizon=0.5)[0].size == 101
    with pytest.raises(ValueError, match=r"^horizon: .* samples \(limit 101\)"):
        robot.simulate(dt=0.01, horizon=1.01)


def test_max_samples_covers_the_longest_documented_hil_run() -> None:
    # hil's Scenario takes start and duration up to 3600 s each, at the 0.3 ms period
    assert int(round(7200 / T)) + 1 <= MAX_SAMPLES


@pytest.mark.parametrize("argv, message", [
    (["reproduce", "example3", "--horizon", "1e10"], "--horizon: 1e10 s at dt 0.0001 s is 1e14 samples"),
    (["tune", "--example", "example1", "--config", "example1", "--trials", "1", "--dt", "1e-12"],
     "--horizon: 100 s at dt 1e-12 s is 1e14 samples"),
    (["tune", "--example", "example2", "--config", "example2", "--trials", "1", "--horizon", "1e13"],
     "--horizon: 1e13 s at dt 0.01 s is 1e15 samples"),
    (["tune", "--example", "example3", "--config", "example3", "--trials", "1", "--horizon", "1e9"],
     "--horizon: 1e9 s at dt 0.0001 s is 1e13 samples"),
    (["hil", "trajectory", "t.csv", "--duration", "3600", "--step", "3e-9"],
     "--duration: 3600 s at --step 3e-9 s is 1.2e12 samples (limit 2.5e7)"),
])
def test_cli_commands_refuse_a_huge_simulated_length_in_one_line(tmp_path, monkeypatch, cli_error, argv,
                                                                 message) -> None:
    monkeypatch.chdir(tmp_path)
    if argv[0] == "reproduce":
        argv = [*argv, "--out", str(tmp_path / "out")]
    if argv[0] == "tune":
        argv = [*argv, "--out", str(tmp_path / "tuned.toml")]
    err = cli_error(argv)
    errors = [ln for ln in err.splitlines() if ": error: " in ln]  # reproduce prints its progress too
    assert len(errors) == 1 and message in errors[0], err
    assert not (tmp_path / "t.csv").exists() and not (tmp_path / "tuned.toml").exists()


def test_reproduce_refuses_an_oscillator_run_whose_rk4_grid_is_too_long(tmp_path, monkeypatch, cli_error) -> None:
    # 51 samples at 0.2 s, but 2001 points of the 5 ms RK4 grid (a small limit: the run stays short if it runs)
    monkeypatch.setattr(plant_trajectory, "MAX_SAMPLES", 1000)
    err = cli_error(["reproduce", "example1", "--dt", "0.2", "--horizon", "10", "--no-horizon-study", "--out",
                     str(tmp_path / "out")])
    assert "error: --horizon: 10 s at step 0.005 s is 2001 RK4 grid points (limit 1000)" in err


# -- 3. long runs: uniform times, and where the DBC's range is left -------------------------------


def _hour_trajectory(t: np.ndarray, dt: float = T) -> Trajectory:
    n = t.size
    X = np.zeros((n, 1))
    return Trajectory(t=t, X=X, U=np.zeros((n, 1)), valid=np.ones((n, 1), dtype=bool), X_meas=X.copy(),
                      state_names=("x",), input_names=("u",), dt=dt)


@pytest.mark.parametrize("k0", [7_000_000, 12_000_000 - 2000])  # t ~ 2100 s and ~ 3600 s
def test_the_sample_times_of_an_hour_long_run_are_uniform_despite_float64_rounding(k0) -> None:
    # exactly the times sample_times gives samples k0.. of a run at the rig's period
    t = np.arange(k0, k0 + 2001, dtype=np.float64) * T
    assert not np.allclose(np.diff(t), T, rtol=1e-9, atol=1e-12 * T)  # what the old check demanded
    assert _hour_trajectory(t).n_samples == 2001
    # and for t from 0, as a plant's run
    full = sample_times(T, 3600.0)
    assert _hour_trajectory(full[-3000:] - 0.0).t[-1] == pytest.approx(3600.0)


def test_non_uniform_times_are_still_refused_at_an_hour() -> None:
    t = np.arange(12_000_000 - 1000, 12_000_001, dtype=np.float64) * T
    shifted = t.copy()
    shifted[500] += 1e-3 * T
    with pytest.raises(ValueError, match=r"^t: samples must be uniformly spaced by dt = 0\.0003 \(t\[500\]"):
        _hour_trajectory(shifted)
    drift = t[0] + np.arange(t.size) * T * (1 + 1e-7)                # a slightly wrong step
    with pytest.raises(ValueError, match=r"^t: samples must be uniformly spaced"):
        _hour_trajectory(drift)
    with pytest.raises(ValueError, match=r"^t: samples must be uniformly spaced"):
        _hour_trajectory(t, dt=2 * T)
    nan = t.copy()
    nan[3] = np.nan
    with pytest.raises(ValueError, match=r"^t: samples must be uniformly spaced"):
        _hour_trajectory(nan)


def test_a_replay_outside_the_dbc_range_names_the_options_that_put_the_plant_there(cli_error, no_replay) -> None:
    err = cli_error(["hil", "replay", "--transport", "virtual", "--duration", "0.01", "--start", "100"])
    assert "outside the DBC range" in err
    assert ("t is the trajectory time: start 100 s and duration 0.01 s take the simulated LIM, driven from "
            "input_start 2 s, outside what the DBC can carry") in err


# -- 4. hil replay / score / bench options --------------------------------------------------------


def test_replay_refuses_a_log_in_a_missing_folder_before_replaying(tmp_path, cli_error, no_replay) -> None:
    err = cli_error(["hil", "replay", "--transport", "virtual", "--duration", "0.01", "--log",
                     str(tmp_path / "nodir" / "r.blf")])
    assert err.startswith("pyrhonn hil: error: --log: folder") and "does not exist" in err
    (tmp_path / "d.blf").mkdir()
    assert "--log: " in cli_error(["hil", "replay", "--transport", "virtual", "--duration", "0.01", "--log",
                                   str(tmp_path / "d.blf")])


def test_a_log_in_the_out_folder_the_replay_creates_is_accepted(tmp_path, capsys) -> None:
    from pyrhonn.cli import main

    out = tmp_path / "new" / "run"  # neither folder exists yet: --out makes it, --log writes into it
    assert main(["hil", "replay", "--transport", "virtual", "--duration", "0.01", "--out", str(out), "--log",
                 str(out / "run.blf")]) == 0, capsys.readouterr().err
    assert (out / "run.blf").is_file() and (out / "run.blf.json").is_file()


def test_replay_refuses_an_out_that_is_a_file_before_replaying_and_leaves_it(tmp_path, cli_error,
                                                                               no_replay) -> None:
    afile = tmp_path / "afile"
    afile.write_text("keep me\n")
    log = tmp_path / "r.blf"
    err = cli_error(["hil", "replay", "--transport", "virtual", "--duration", "0.01", "--out", str(afile),
                     "--log", str(log)])
    assert "--out" in err and str(afile) in err
    assert afile.read_text() == "keep me\n" and not log.exists()


def test_score_refuses_an_out_that_is_a_file_before_printing_a_report(recorded_run, tmp_path, capsys,
                                                                      cli_error) -> None:
    afile = tmp_path / "afile"
    afile.write_text("keep me\n")
    capsys.readouterr()
    err = cli_error(["hil", "score", str(recorded_run), "--out", str(afile)])
    assert "--out" in err and afile.read_text() == "keep me\n"


def test_replay_with_out_and_log_still_writes_both(tmp_path, capsys) -> None:
    out, log = tmp_path / "new" / "report", tmp_path / "r.asc"
    assert pyrhonn_main(["hil", "replay", "--transport", "virtual", "--duration", "0.01", "--out", str(out),
                         "--log", str(log)]) == 0
    assert (out / "report.json").is_file() and log.is_file() and Path(str(log) + ".json").is_file()
    assert not list(tmp_path.glob(".pyrhonn-*")) and not list(out.glob(".pyrhonn-*"))  # no probe left


@pytest.mark.parametrize("cycles", ["99999999999999999999999", "12000001", "1" + "0" * 400])
def test_bench_names_cycles_when_they_make_too_long_a_run(cli_error, no_replay, cycles) -> None:
    err = cli_error(["hil", "bench", "--transport", "virtual", "--cycles", cycles])
    assert err.startswith("pyrhonn hil: error: --cycles: ") and "longer than a run may be" in err
    assert len(err) < 400


@pytest.mark.parametrize("command", [["replay", "--duration", "0.01"], ["bench", "--cycles", "10"]])
@pytest.mark.parametrize("transport, option", [
    ("virtual", ["--port", "5"]), ("virtual", ["--runner", "/usr/bin/true"]),
    ("virtual", ["--firmware", "python"]), ("virtual", ["--firmware", "runner"]),
    ("socketcan", ["--port", "5"]), ("socketcan", ["--firmware", "runner"]),
])
def test_options_the_transport_would_ignore_are_refused_naming_them(cli_error, no_replay, command, transport,
                                                                    option) -> None:
    err = cli_error(["hil", *command, "--transport", transport, *option])
    assert err.startswith(f"pyrhonn hil: error: {option[0]}: "), err


@pytest.mark.parametrize("content, message", [(b"[" * 100_000 + b"]" * 100_000, "JSON nested too deeply"),
                                              (b" " * (1 << 20) + b"{}", "larger than 1,048,576 bytes")])
def test_a_sidecar_too_deep_or_too_large_is_refused_naming_it(tmp_path, content: bytes, message: str) -> None:
    from hil.rig import read_log

    log = tmp_path / "r.blf"
    log.write_bytes(b"x")
    (tmp_path / "r.blf.json").write_bytes(content)
    with pytest.raises(ValueError, match=rf"^log: {re.escape(str(tmp_path))}/r\.blf\.json: .*{message}"):
        read_log(log)


@pytest.mark.parametrize("argv, message", [
    (["replay", "--transport", "virtual", "--duration", "0.01", "--input-start", "nan"], "--input-start: must be finite"),
    (["replay", "--transport", "virtual", "--duration", "0.01", "--delay", "-1"], "--delay: must be >= 0"),
    (["replay", "--transport", "virtual", "--duration", "0.01", "--frame-loss", "2"], "--frame-loss: must be <= 0.5"),
    (["trajectory", "t.csv", "--input-start", "inf"], "--input-start: expected finite seconds >= 0, got inf"),
])
def test_scenario_errors_name_the_command_line_option(tmp_path, monkeypatch, cli_error, no_replay, argv,
                                                       message) -> None:
    monkeypatch.chdir(tmp_path)
    err = cli_error(["hil", *argv])
    assert err.startswith(f"pyrhonn hil: error: {message}"), err
    assert not (tmp_path / "t.csv").exists()
