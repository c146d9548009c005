"""``pyrhonn identify --can-log``: a bus recording (written by python-can's own loggers from frames sent
on the ``virtual`` bus, or a candump log) gives the same identification as the CSV of the same
samples; lost, late and flagged frames become not-valid samples; every bad input exits 2 naming the
option, key, signal or line; the outputs are written whole."""
from __future__ import annotations

import contextlib
import csv
import json
import re
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Iterator

import can
import cantools
import numpy as np
import pytest

from pyrhonn.cli import main
from pyrhonn.configfile import loads, shipped_text
from docs_blocks import ROOT, blocks_by, code_blocks, run, transcript_matches, transcript_steps  # noqa: E402
from pyrhonn.plants import oscillator

PERIOD = 0.01  # s between samples on the bus (the trajectory's own dt does not matter to the identifier)
T0 = 1_700_000_000.0  # the log's wall clock

DBC = """VERSION ""

NS_ :

BS_:

BU_: PLANT CTRL

BO_ 256 StatesA: 8 PLANT
 SG_ X1 : 0|32@1- (1,0) [-1e9|1e9] "" CTRL
 SG_ X2 : 32|32@1- (1,0) [-1e9|1e9] "" CTRL

BO_ 257 StatesB: 8 PLANT
 SG_ X3 : 0|28@1- (1e-06,0) [-100|100] "" CTRL
 SG_ X3Valid : 28|1@1+ (1,0) [0|1] "" CTRL
 SG_ X4 : 32|28@1- (1e-06,0) [-100|100] "" CTRL
 SG_ X4Valid : 60|1@1+ (1,0) [0|1] "" CTRL

BO_ 512 Command: 5 CTRL
 SG_ U : 0|32@1- (1,0) [-1e9|1e9] "" PLANT
 SG_ Seq : 32|8@1+ (1,0) [0|255] "" PLANT

BO_ 768 Mux: 8 PLANT
 SG_ Page M : 0|8@1+ (1,0) [0|255] "" CTRL
 SG_ A m0 : 8|16@1- (0.001,0) [-30|30] "" CTRL
 SG_ AValid m1 : 24|1@1+ (1,0) [0|1] "" CTRL

SIG_VALTYPE_ 256 X1 : 1;
SIG_VALTYPE_ 256 X2 : 1;
SIG_VALTYPE_ 512 U : 1;
"""

BUS = """
[bus]
sample_period = 0.01
clock = "StatesA"

[bus.signals]
x1 = "StatesA.X1"
x2 = "StatesA.X2"
x3 = "StatesB.X3"
x4 = "StatesB.X4"
u = "Command.U"

[bus.valid]
x3 = "StatesB.X3Valid"
x4 = "StatesB.X4Valid"
"""

# the faults of the recording, by sample index
LOST_A = {17, 40, 41}  # StatesA (the clock) never sent: x1, x2 not valid, the clock interpolated
LOST_B = {25}  # StatesB never sent: x3, x4 not valid
LATE_B = {60}  # StatesB sent 0.7 periods late, into sample 61's window, where 61's own frame supersedes it
FLAG_X4 = {33, 34}  # X4Valid = 0: x4 not valid (x3 is)


@dataclass(frozen=True)
class Recording:
    frames: list[can.Message]  # in time order, absolute timestamps
    X: np.ndarray  # (K, 4) the values the frames decode to (NaN where not valid)
    valid: np.ndarray  # (K, 4)
    U: np.ndarray  # (K, 1)


def _recording() -> Recording:
    """The oscillator's samples as frames: StatesA at each sample (with a deterministic jitter of up to
    0.1 period), StatesB 0.15 period later, Command 0.3 period later; with the faults above."""
    db = cantools.database.load_string(DBC, database_format="dbc")
    traj = oscillator.simulate(dt=0.2, horizon=24.0)
    K = traj.n_samples
    rng = np.random.default_rng(11)
    jitter = np.round(rng.uniform(-0.1, 0.1, K) * PERIOD, 6)
    frames: list[can.Message] = []
    X = np.full((K, 4), np.nan)
    valid = np.zeros((K, 4), dtype=bool)
    U = np.empty((K, 1))

    def frame(name: str, t: float, values: dict[str, float]) -> dict[str, float]:
        msg = db.get_message_by_name(name)
        data = msg.encode(values, scaling=True)
        frames.append(can.Message(timestamp=round(t, 6), arbitration_id=msg.frame_id, is_extended_id=False,
                                  data=data, dlc=len(data)))
        return msg.decode(data)  # what the log holds

    for k in range(K):
        tk = T0 + k * PERIOD + jitter[k]
        x = traj.X_meas[k]
        if k not in LOST_A:
            got = frame("StatesA", tk, {"X1": x[0], "X2": x[1]})
            X[k, :2] = got["X1"], got["X2"]
            valid[k, :2] = True
        if k not in LOST_B:
            late = 0.7 * PERIOD if k in LATE_B else 0.0
            got = frame("StatesB", tk + 0.15 * PERIOD + late,
                        {"X3": x[2], "X3Valid": 1, "X4": x[3], "X4Valid": 0 if k in FLAG_X4 else 1})
            if k not in LATE_B:
                X[k, 2] = got["X3"]
                valid[k, 2] = True
                if k not in FLAG_X4:
                    X[k, 3] = got["X4"]
                    valid[k, 3] = True
        U[k, 0] = frame("Command", tk + 0.3 * PERIOD, {"U": traj.U[k, 0], "Seq": k % 256})["U"]
    frames.sort(key=lambda m: m.timestamp)
    return Recording(frames=frames, X=X, valid=valid, U=U)


def _log_through_virtual_bus(frames: list[can.Message], path: Path) -> None:
    """Send ``frames`` on python-can's virtual bus (keeping their timestamps) and record what a second
    node receives with ``can.Logger``, which picks the writer by the file's suffix."""
    channel = f"canlog-{path.name}"
    with can.Bus(interface="virtual", channel=channel, preserve_timestamps=True) as tx, \
            can.Bus(interface="virtual", channel=channel) as rx:
        logger = can.Logger(str(path))
        try:
            for m in frames:
                tx.send(m)
                got = rx.recv(timeout=5.0)
                assert got is not None
                logger.on_message_received(got)
        finally:
            logger.stop()


def _candump(frames: list[can.Message], path: Path) -> None:
    """A candump -l log, written by hand: ``(time) interface id#data``."""
    lines = [f"({m.timestamp:.6f}) vcan0 {m.arbitration_id:03X}#{bytes(m.data).hex().upper()}" for m in frames]
    path.write_text("\n".join(lines) + "\n")


@pytest.fixture(scope="module")
def rec() -> Recording:
    return _recording()


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory, rec: Recording) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("bus")
    (d / "plant.dbc").write_text(DBC)
    (d / "cfg.toml").write_text(shipped_text("example1") + BUS)
    out = {"dbc": d / "plant.dbc", "config": d / "cfg.toml"}
    for suffix in ("blf", "asc"):
        out[suffix] = d / f"run.{suffix}"
        _log_through_virtual_bus(rec.frames, out[suffix])
    out["log"] = d / "run.log"
    _candump(rec.frames, out["log"])
    return out


def _csv_of(rec: Recording, path: Path) -> None:
    """The same samples as the CSV a user would export: t, states (empty where not valid), u, flags."""
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["t", "x1", "x2", "x3", "x4", "u", "x1_valid", "x2_valid", "x3_valid", "x4_valid"])
        for k in range(rec.X.shape[0]):
            w.writerow([repr(k * PERIOD)] + [repr(float(v)) if ok else "" for v, ok in zip(rec.X[k], rec.valid[k])]
                       + [repr(float(rec.U[k, 0]))] + [str(int(v)) for v in rec.valid[k]])


def _predictions(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as fh:
        return [{k: v for k, v in row.items() if k.endswith(("_hat", "_err"))} for row in csv.DictReader(fh)]


def _identify(files: dict[str, Path], log: str, out: Path, *extra: str) -> int:
    return main(["identify", "--can-log", str(files[log]), "--dbc", str(files["dbc"]), "--config",
                 str(files["config"]), "--out", str(out), "--warmup", "5", "--no-plots", *extra])


@pytest.mark.parametrize("log", ["blf", "asc", "log"])
def test_a_bus_log_identifies_as_the_csv_of_the_same_samples(files: dict[str, Path], rec: Recording, log: str,
                                                             tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    _csv_of(rec, tmp_path / "same.csv")
    assert main(["identify", str(tmp_path / "same.csv"), "--config", str(files["config"]), "--out",
                 str(tmp_path / "csv"), "--warmup", "5", "--no-plots"]) == 0
    assert _identify(files, log, tmp_path / "bus") == 0
    printed = capsys.readouterr().out
    assert f"identified {files[log]}: {rec.X.shape[0]} samples" in printed
    assert _predictions(tmp_path / "bus" / "predictions.csv") == _predictions(tmp_path / "csv" / "predictions.csv")
    by_bus = json.loads((tmp_path / "bus" / "metrics.json").read_text())
    by_csv = json.loads((tmp_path / "csv" / "metrics.json").read_text())
    assert by_bus["states"] == by_csv["states"] and by_bus["next_prediction"] == by_csv["next_prediction"]
    assert by_bus["samples"] == rec.X.shape[0]
    # the aligned samples, written beside: the same identification again, from the CSV path
    assert main(["identify", str(tmp_path / "bus" / "samples.csv"), "--config", str(files["config"]), "--out",
                 str(tmp_path / "again"), "--warmup", "5", "--no-plots"]) == 0
    assert _predictions(tmp_path / "again" / "predictions.csv") == _predictions(tmp_path / "csv" / "predictions.csv")


def test_lost_late_and_flagged_frames_are_not_valid_samples_never_filled_in(files: dict[str, Path], rec: Recording,
                                                                            tmp_path: Path) -> None:
    from pyrhonn.buslog import BusMap, read_bus_log
    from pyrhonn.configfile import load_config

    cf = load_config(files["config"])
    assert isinstance(cf.bus, BusMap)
    a = read_bus_log(files["blf"], files["dbc"], cf.bus, cf.state_names, cf.input_names)
    assert a.valid.shape == rec.valid.shape
    np.testing.assert_array_equal(a.valid, rec.valid)
    for k in LOST_A:
        assert not a.valid[k, :2].any() and np.isnan(a.X[k, :2]).all()
    for k in LOST_B | LATE_B:
        assert not a.valid[k, 2:].any() and np.isnan(a.X[k, 2:]).all()
    for k in FLAG_X4:
        assert a.valid[k, 2] and not a.valid[k, 3]
    np.testing.assert_array_equal(a.X[rec.valid], rec.X[rec.valid])  # every valid value is its own frame's
    np.testing.assert_array_equal(a.U, rec.U)
    assert a.clock_missing == len(LOST_A)  # samples inserted where the clock's frames were lost
    np.testing.assert_allclose(np.diff(a.t), PERIOD, atol=0.21 * PERIOD)
    s = a.stats
    assert s["x1"].missing == len(LOST_A) and s["x3"].missing == len(LOST_B | LATE_B)
    assert s["x3"].superseded == len(LATE_B)  # the late frame, replaced by the next sample's own
    assert s["x4"].flagged == len(FLAG_X4) and s["x3"].flagged == 0
    assert s["x4"].used == int(rec.valid[:, 3].sum())


def test_a_missing_input_inside_the_run_is_a_gap_and_the_ends_are_cut(files: dict[str, Path], rec: Recording,
                                                                      tmp_path: Path) -> None:
    cmd = 512
    commands = [i for i, m in enumerate(rec.frames) if m.arbitration_id == cmd]
    gap = [m for i, m in enumerate(rec.frames) if i != commands[50]]
    _candump(gap, tmp_path / "gap.log")
    assert main(["identify", "--can-log", str(tmp_path / "gap.log"), "--dbc", str(files["dbc"]), "--config",
                 str(files["config"]), "--out", str(tmp_path / "out"), "--no-plots"]) == 0
    report = json.loads((tmp_path / "out" / "metrics.json").read_text())
    assert report["gaps"]["gap_list"][0]["first_lost"]["sample"] == 50 and report["gaps"]["lost_samples"] == 1
    with (tmp_path / "out" / "samples.csv").open(newline="") as fh:
        row = list(csv.DictReader(fh))[50]
    assert row["lost"] == "1" and row["u"] == "" and row["x1"] == ""  # never filled in
    # the same log from after the gap runs; so does one whose first and last commands are lost
    assert main(["identify", "--can-log", str(tmp_path / "gap.log"), "--dbc", str(files["dbc"]), "--config",
                 str(files["config"]), "--out", str(tmp_path / "after"), "--start", "0.505", "--no-plots"]) == 0
    report = json.loads((tmp_path / "after" / "metrics.json").read_text())
    assert report["bus"]["samples_cut_before"] == 51 and report["samples"] == rec.X.shape[0] - 51
    ends = [m for i, m in enumerate(rec.frames) if i not in (commands[0], commands[-1])]
    _candump(ends, tmp_path / "ends.log")
    assert main(["identify", "--can-log", str(tmp_path / "ends.log"), "--dbc", str(files["dbc"]), "--config",
                 str(files["config"]), "--out", str(tmp_path / "ends"), "--no-plots"]) == 0
    report = json.loads((tmp_path / "ends" / "metrics.json").read_text())
    assert report["samples"] == rec.X.shape[0] - 2
    assert (report["bus"]["samples_cut_before"], report["bus"]["samples_cut_after"]) == (1, 1)


def test_signals_given_on_the_command_line_replace_the_config_table(files: dict[str, Path], tmp_path: Path) -> None:
    """The shipped example1 has no [bus] table: --signal and --sample-period give it."""
    args = ["identify", "--can-log", str(files["log"]), "--dbc", str(files["dbc"]), "--config", "example1",
            "--sample-period", "0.01", "--no-plots", "--warmup", "5"]
    signals = ["x1=StatesA.X1", "x2=StatesA.X2", "x3=StatesB.X3", "x4=StatesB.X4", "u=Command.U"]
    for s in signals:
        args += ["--signal", s]
    assert main(args + ["--out", str(tmp_path / "cli")]) == 0
    with (tmp_path / "cli" / "samples.csv").open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    # without the validity flags of [bus.valid], only the lost frames are not valid
    assert {k for k, r in enumerate(rows) if r["x4_valid"] == "0"} == LOST_B | LATE_B
    assert {k for k, r in enumerate(rows) if r["x1_valid"] == "0"} == LOST_A


def test_the_bus_table_survives_a_config_round_trip(files: dict[str, Path]) -> None:
    from pyrhonn.configfile import dumps

    cf = loads(files["config"].read_text(), "cfg.toml")
    assert loads(dumps(cf)) == cf
    assert str(cf.bus.signals["x3"]) == "StatesB.X3" and cf.bus.sample_period == 0.01


@pytest.mark.parametrize("table, message", [
    ('[bus]\nsample_perod = 0.01\n', "cfg.toml: bus.sample_perod: unknown key; did you mean 'sample_period'?"),
    ('[bus.signals]\nx9 = "StatesA.X1"\n', "cfg.toml: bus.signals.x9: 'x9' is not one of the config's states"),
    ('[bus.signals]\nx1 = "StatesA X1"\n', "cfg.toml: bus.signals.x1: expected \"Message.Signal\""),
    ('[bus.signals]\nx1 = 3\n', "cfg.toml: bus.signals.x1: expected a string"),
    ('[bus]\nsample_period = -1\n', "cfg.toml: bus.sample_period: must be > 0"),
    ('[bus]\nwindow_start = 0.5\n', "cfg.toml: bus.window_start: must be in -1.0..0.0"),
    ('[bus.valid]\nx1 = "StatesA.X1"\n', "bus.valid.x1: a validity flag for 'x1', which bus.signals does not map"),
])
def test_a_bad_bus_table_is_refused_naming_its_key(tmp_path: Path, table: str, message: str) -> None:
    with pytest.raises(ValueError) as exc:
        loads(shipped_text("example1") + table, "cfg.toml")
    assert message in str(exc.value)


def _with_bus(tmp_path: Path, bus: str) -> Path:
    path = tmp_path / "bad.toml"
    path.write_text(shipped_text("example1") + bus)
    return path


@pytest.mark.parametrize("change, message", [
    ({"x3": "StatesB.X33"}, "bus.signals.x3: 'StatesB.X33': message StatesB has no signal 'X33'; did you mean 'X3'?"),
    ({"x3": "StatesC.X3"}, "bus.signals.x3: 'StatesC.X3': no message 'StatesC' in"),
    ({"x2": "StatesA.X1"}, "bus.signals.x2: 'StatesA.X1' is also the signal of 'x1'"),
    ({"clock": "Commands"}, "bus.clock: no message 'Commands' in"),
    ({"sample_period": 0.02}, "bus.sample_period: sample period 0.02 s, but the clock message StatesA's frames come "
                              "every 0.00995898 s (median of 117 intervals)"),
    ({"x4_flag": "StatesA.X1"}, "bus.valid.x4: 'StatesA.X1' is in message StatesA, but x4's value StatesB.X4 is in "
                                "StatesB"),
    ({"x3": "Mux.A", "x3_flag": "Mux.AValid"}, "bus.valid.x3: mixed multiplexing: 'Mux.AValid' is sent only under "
                                               "multiplexer value(s) [1]"),
    ({"x3": "Mux.A"}, "bus.signals.x3: Mux.A: "),
])
def test_bad_signals_exit_2_naming_the_config_key(files: dict[str, Path], tmp_path: Path, change: dict[str, object],
                                                  message: str, cli_error) -> None:
    signals = {"x1": "StatesA.X1", "x2": "StatesA.X2", "x3": "StatesB.X3", "x4": "StatesB.X4", "u": "Command.U"}
    flags = {"x3": "StatesB.X3Valid", "x4": "StatesB.X4Valid"}
    top = {"sample_period": 0.01, "clock": "StatesA"}
    for key, value in change.items():
        if key.endswith("_flag"):
            flags[key[:-5]] = value
        elif key in top:
            top[key] = value
        else:
            signals[key] = value
            flags.pop(key, None)
    bus = "\n[bus]\n" + "".join(f"{k} = {json.dumps(v)}\n" for k, v in top.items()) + "[bus.signals]\n" + \
        "".join(f'{k} = "{v}"\n' for k, v in signals.items()) + "[bus.valid]\n" + \
        "".join(f'{k} = "{v}"\n' for k, v in flags.items())
    err = cli_error(["identify", "--can-log", str(files["blf"]), "--dbc", str(files["dbc"]), "--config",
                     str(_with_bus(tmp_path, bus)), "--out", str(tmp_path / "out")])
    assert message in err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("what, message", [
    ("dbc", "--dbc {dbc}: not a DBC file cantools can parse"),
    ("no-messages", "{log}: none of its 3 frames is one of the messages the signals come from"),
    ("extension", "--can-log {log}: unsupported log format '.trc'"),
    ("candump-line", "--can-log {log}: line 3: cannot read it as a candump log"),
    ("blf", "--can-log {log}: truncated: its BLF header records"),
    ("empty", "--can-log {log}: empty file"),
    ("missing", "--can-log {log}: no such file"),
])
def test_bad_files_exit_2_naming_the_file_and_line(files: dict[str, Path], tmp_path: Path, what: str, message: str,
                                                  cli_error) -> None:
    dbc, log = files["dbc"], files["log"]
    if what == "dbc":
        dbc = tmp_path / "bad.dbc"
        dbc.write_text(DBC.replace("BO_ 257 StatesB: 8 PLANT", "BO_ 257 StatesB 8 PLANT"))
    elif what == "no-messages":
        log = tmp_path / "other.log"
        log.write_text("(1.000000) vcan0 123#00\n(1.010000) vcan0 124#00\n(1.020000) vcan0 123#00\n")
    elif what == "extension":
        log = tmp_path / "run.trc"
        log.write_text("x")
    elif what == "candump-line":
        log = tmp_path / "bad.log"
        log.write_text("(1.000000) vcan0 100#0000000000000000\n\n(1.010000) vcan0 100#00GG\n")
    elif what == "blf":
        log = tmp_path / "cut.blf"
        log.write_bytes(files["blf"].read_bytes()[:3000])
    elif what == "empty":
        log = tmp_path / "empty.asc"
        log.write_bytes(b"")
    else:
        log = tmp_path / "none.blf"
    err = cli_error(["identify", "--can-log", str(log), "--dbc", str(dbc), "--config", str(files["config"]),
                     "--out", str(tmp_path / "out")])
    assert message.format(dbc=dbc, log=log) in err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("args, message", [
    (["DATA.csv"], "--can-log: give either DATA.csv (DATA.csv) or --can-log, not both"),
    (["--dbc", None], "--dbc: required with --can-log"),
    (["--signal", "x1"], "--signal x1: expected NAME=Message.Signal"),
    (["--signal", "y=StatesA.X1"], "--signal y=StatesA.X1: 'y' is not one of the states and inputs"),
    (["--sample-period", "0"], "--sample-period: must be > 0"),
    (["--clock", "Nope"], "--clock: no message 'Nope' in"),
    (["--start", "0.5", "--stop", "0.2"], "--stop 0.2: must be after --start 0.5"),
    (["--start", "9"], "--start/--stop: no sample between 9.0 and None s"),
    (["--counter", "StatesA.X1"], "--counter: 'StatesA.X1' is not a counter: expected an unsigned integer signal"),
    (["--counter", "Command.Seq"], "--counter: 'Command.Seq' is in message Command, not in the clock message StatesA"),
])
def test_bad_options_exit_2_naming_the_option(files: dict[str, Path], tmp_path: Path, args: list[str | None],
                                              message: str, cli_error) -> None:
    argv = ["identify", "--can-log", str(files["log"]), "--dbc", str(files["dbc"]), "--config", str(files["config"]),
            "--out", str(tmp_path / "out")]
    if args[:2] == ["--dbc", None]:
        argv = argv[:3] + argv[5:]
    else:
        argv += [a for a in args if a is not None]
    assert message in cli_error(argv)


def test_bus_options_without_a_log_are_refused(files: dict[str, Path], cli_error) -> None:
    assert "--dbc: only with --can-log" in cli_error(["identify", "data.csv", "--config", "example1", "--dbc", "x"])
    assert "give DATA.csv, or --can-log" in cli_error(["identify", "--config", "example1"])


@pytest.mark.parametrize("streamed", [True, False])
def test_outputs_are_replaced_whole_and_an_interrupted_run_marks_the_folder(
        files: dict[str, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch, streamed: bool) -> None:
    """A second run into the same --out that fails while writing samples.csv leaves every file of the
    first run whole, no temporary file, and the INCOMPLETE marker: a log streamed (samples.csv staged,
    then copied into the folder) or read whole (--steps-ahead: written into the folder)."""
    from pyrhonn import atomic
    from pyrhonn.atomic import MARKER

    out = tmp_path / "out"
    assert _identify(files, "blf", out) == 0
    first = {p.name: p.read_bytes() for p in out.iterdir()}
    assert MARKER not in first and {"samples.csv", "predictions.csv", "metrics.json"} <= set(first)
    real_replacing = atomic.replacing

    @contextlib.contextmanager
    def failing(path: Path, *args: object, **kw: object) -> Iterator[IO[bytes]]:
        with real_replacing(path, *args, **kw) as fh:  # type: ignore[arg-type]
            yield fh
            if Path(path).name == "samples.csv":  # the disk fills while samples.csv is written into the folder
                raise OSError(28, "No space left on device")

    monkeypatch.setattr(atomic, "replacing", failing)
    assert _identify(files, "asc", out, "--warmup", "6", *([] if streamed else ["--steps-ahead", "1"])) == 2
    now = {p.name: p.read_bytes() for p in out.iterdir()}
    assert now.pop(MARKER, None) is not None  # the folder says it was not finished
    assert now == first  # each output is the first run's, whole; no temporary file left behind


def test_hil_score_on_a_recording_without_a_sidecar_says_what_it_needs_and_offers_identify(
        files: dict[str, Path], cli_error) -> None:
    for log in (files["blf"], files["log"]):
        err = cli_error(["hil", "score", str(log)])
        assert f"no sidecar {log.name}.json" in err
        assert "the truth it scores against" in err
        assert f"pyrhonn identify --can-log {log} --dbc FILE --config CFG" in err


def test_a_counter_keeps_a_late_burst_of_clock_frames_in_place(files: dict[str, Path], rec: Recording,
                                                               tmp_path: Path, cli_error) -> None:
    """The Command sender stalls for 6 periods and then sends its backlog at once: numbered by their
    counter, the frames keep their samples (every input in place); by time alone, the stall reads as lost
    samples, whose inputs are then missing: lost samples, a gap (never filled in)."""
    stalled = range(30, 36)
    burst = [can.Message(timestamp=round(T0 + 35 * PERIOD + 0.3 * PERIOD + 1e-5 * (k - 30), 6),
                         arbitration_id=m.arbitration_id, data=m.data, dlc=m.dlc, is_extended_id=False)
             for k, m in zip(stalled, [m for m in rec.frames if m.arbitration_id == 512][30:36])]
    commands = [m for m in rec.frames if m.arbitration_id == 512]
    late = [m for m in rec.frames if not (m.arbitration_id == 512 and any(m is commands[k] for k in stalled))]
    _candump(sorted(late + burst, key=lambda m: m.timestamp), tmp_path / "burst.log")
    args = ["identify", "--can-log", str(tmp_path / "burst.log"), "--dbc", str(files["dbc"]), "--config",
            str(files["config"]), "--clock", "Command", "--no-plots"]
    assert main(args + ["--out", str(tmp_path / "t")]) == 0
    assert json.loads((tmp_path / "t" / "metrics.json").read_text())["gaps"]["lost_samples"] == 5
    assert main(args + ["--counter", "Command.Seq", "--out", str(tmp_path / "n")]) == 0
    with (tmp_path / "n" / "samples.csv").open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == rec.X.shape[0]
    assert [float(r["u"]) for r in rows] == rec.U[:, 0].tolist()  # every input from its own frame
    # the states' frames came on time, but the samples they belong to bunched up in the burst: those
    # samples' windows hold no frame of StatesA, so x1 is not valid there (and never filled in)
    assert all(rows[k]["x1_valid"] == "0" and rows[k]["x1"] == "" for k in range(30, 35))


def test_the_can_log_pages_hil_recording_prints_what_the_page_shows(tmp_path: Path) -> None:
    """docs/can-log.md's transcript, run as written: the recording is the Measurement frames of `pyrhonn hil
    replay --transport virtual --duration 4` (its default scenario) at their sampling instants, so that what
    identify prints depends on no host's timing; the config is firmware-lim with the page's [bus] table."""
    from hil.scenario import Scenario

    page = "docs/can-log.md"
    (body,) = blocks_by(page, "test_cli_identify_canlog.py::test_the_can_log_pages_hil_recording_prints_what_the_page_shows")
    (table,) = [b for lang, b, _, _ in code_blocks((ROOT / page).read_text(encoding="utf-8"))
                if lang == "toml" and b.startswith("[bus]")]
    (tmp_path / "lim.toml").write_text(shipped_text("firmware-lim") + "\n" + table)
    plan = Scenario(duration=4.0).build()
    with can.BLFWriter(str(tmp_path / "lim.blf")) as log:
        for t, msg in zip(plan.t, plan.frames()):
            msg.timestamp = T0 + float(t)
            log.on_message_received(msg)
    (tmp_path / "firmware_sim").symlink_to(ROOT / "firmware_sim", target_is_directory=True)
    steps = transcript_steps(body)
    assert [cmd.split()[:3] for cmd, _ in steps] == [["pyrhonn", "identify", "--can-log"]]
    for cmd, expected in steps:
        printed = run(["bash", "-ec", cmd], tmp_path, page)
        assert transcript_matches(printed, expected), f"{page}: `{cmd}` prints\n{printed}\nnot\n{expected}"
    # what the page says of the not-valid samples: the replay's own hold, as its report counts them
    shown = dict(re.findall(r"^  \w+ \(Measurement\.(\w+)\): (\d+) samples not valid", expected, flags=re.M))
    assert {k: int(v) for k, v in shown.items()} == {k: v["held"] + v["derived"] for k, v in plan.not_valid.items()}
