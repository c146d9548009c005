"""Recordings with lost frames identify the firmware's way: a lost Measurement splits the record into
segments (the frame after the gap is not stepped, the identifier restarts on the next), every gap is
counted and reported per segment, the result is the same from a candump, BLF, ASC or MDF4 log and from the
CSV of the same samples with the same gaps, and its predictions are the firmware's Estimates."""
from __future__ import annotations

import csv
import functools
import json
from pathlib import Path

import numpy as np
import pytest

can = pytest.importorskip("can")
pytest.importorskip("cantools")

from pyrhonn import firmware  # noqa: E402
from pyrhonn.cli import main  # noqa: E402
from pyrhonn.configfile import load_shipped, shipped_text  # noqa: E402
from pyrhonn.firmware import FirmwareApp  # noqa: E402
from pyrhonn.gaps import segments_of  # noqa: E402
from pyrhonn.plants import lim  # noqa: E402

PERIOD = 3e-4
T0 = 1_700_000_000.0
N = 700
# lost Measurement frames: single ones, a run of three, and two gaps one frame apart (the frame between
# them reveals the first and is followed by the second)
LOST = frozenset({57, 200, 333, 334, 335, 540, 542})
STATES = ("q_m", "v", "lambda_a", "lambda_b", "i_a", "i_b")
BUS = "\n[bus]\nsample_period = 0.0003\nclock = \"Measurement\"\n\n[bus.signals]\n" + "".join(
    f"{n} = \"Measurement.{s}\"\n" for n, s in zip(STATES + ("u_a", "u_b"), firmware.STATE_SIGNALS
                                                    + firmware.INPUT_SIGNALS)) + "\n[bus.valid]\n" + "".join(
    f"{n} = \"Measurement.{s}\"\n" for n, s in zip(STATES, firmware.VALID_SIGNALS))


@functools.cache
def _frames() -> tuple[can.Message, ...]:
    """Every Measurement of the LIM example (x_valid 0 on a few, a dropout), at 0.3 ms, Seq from 65400
    (it wraps); the lost ones included."""
    traj = lim.simulate(dt=PERIOD, horizon=2.4)
    k0 = int(round(2.0 / PERIOD))
    out = []
    for k in range(N):
        valid = [not (k in (100, 101) and j == 1) for j in range(6)]
        m = firmware.measurement_message(65400 + k, traj.X[k0 + k], traj.U[k0 + k], valid)
        m.timestamp = round(T0 + k * PERIOD, 6)
        out.append(m)
    return tuple(out)


def _write_log(frames: list[can.Message], path: Path) -> None:
    if path.suffix == ".log":  # candump -l, CAN FD: id##flags data
        path.write_text("".join(f"({m.timestamp:.6f}) vcan0 {m.arbitration_id:03X}##{1 if m.bitrate_switch else 0}"
                                f"{bytes(m.data).hex().upper()}\n" for m in frames))
        return
    with can.Logger(str(path)) as logger:
        for m in frames:
            logger.on_message_received(m)


def _csv(frames: list[can.Message], path: Path) -> None:
    """The same samples as CSV: decoded values, validity flags, and lost = 1 on the lost samples."""
    meas = firmware.database().get_message_by_name("Measurement")
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["t", *STATES, "u_a", "u_b", *(f"{s}_valid" for s in STATES), "lost"])
        for k, m in enumerate(frames):
            if k in LOST:
                w.writerow([repr(k * PERIOD)] + [""] * 8 + ["0"] * 6 + ["1"])
                continue
            d = meas.decode(bytes(m.data), decode_choices=False)
            ok = [bool(d[v]) for v in firmware.VALID_SIGNALS]
            w.writerow([repr(k * PERIOD)] + [repr(float(d[s])) if f else "" for s, f in zip(firmware.STATE_SIGNALS, ok)]
                       + [repr(float(d[s])) for s in firmware.INPUT_SIGNALS] + [str(int(f)) for f in ok] + ["0"])


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("gaps")
    kept = [m for k, m in enumerate(_frames()) if k not in LOST]
    out = {"config": d / "lim.toml", "dbc": d / "rhonn_id.dbc", "csv": d / "same.csv"}
    out["config"].write_text(shipped_text("firmware-lim") + BUS)
    out["dbc"].write_text(firmware.database().as_dbc_string())
    for suffix in ("log", "blf", "asc", "mf4"):
        out[suffix] = d / f"run.{suffix}"
        _write_log(kept, out[suffix])
    _csv(list(_frames()), out["csv"])
    return out


def _predictions(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as fh:
        return [{k: v for k, v in row.items() if k.endswith(("_hat", "_err"))} for row in csv.DictReader(fh)]


@pytest.fixture(scope="module")
def runs(files: dict[str, Path], tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("runs")
    out = {}
    for what in ("log", "blf", "asc", "mf4", "csv"):
        source = [str(files[what])] if what == "csv" else ["--can-log", str(files[what]), "--dbc", str(files["dbc"])]
        assert main(["identify", *source, "--config", str(files["config"]), "--out", str(d / what),
                     "--no-plots"]) == 0, what
        out[what] = d / what
    return out


def test_a_lossy_log_identifies_equal_in_every_format_and_to_the_csv_with_the_same_gaps(
        files: dict[str, Path], runs: dict[str, Path], tmp_path: Path) -> None:
    want = _predictions(runs["csv"] / "predictions.csv")
    assert len(want) == N
    metrics = {what: json.loads((p / "metrics.json").read_text()) for what, p in runs.items()}
    for what in ("log", "blf", "asc", "mf4"):
        assert _predictions(runs[what] / "predictions.csv") == want, what
        assert metrics[what]["states"] == metrics["csv"]["states"], what
        spans = [[(s["first"]["sample"], s["last"]["sample"]) for s in metrics[w]["gaps"]["segments"]]
                 for w in (what, "csv")]
        assert spans[0] == spans[1], what
    # the aligned samples written beside carry the same gaps: identified again, the same
    assert main(["identify", str(runs["blf"] / "samples.csv"), "--config", str(files["config"]),
                 "--out", str(tmp_path / "again"), "--no-plots"]) == 0
    assert _predictions(tmp_path / "again" / "predictions.csv") == want


def test_every_gap_is_counted_and_each_segment_reported(runs: dict[str, Path],
                                                         capsys: pytest.CaptureFixture[str]) -> None:
    g = json.loads((runs["asc"] / "metrics.json").read_text())["gaps"]
    # 541 reveals the gap at 540 and is not stepped; 543 reveals the one at 542: no segment between them
    assert g["lost_samples"] == len(LOST) and g["gaps"] == 5 and g["restarts"] == 4
    assert [x["lost"] for x in g["gap_list"]] == [1, 1, 3, 1, 1]
    assert [x["rejected"]["sample"] for x in g["gap_list"]] == [58, 201, 336, 541, 543]
    assert [(s["first"]["sample"], s["last"]["sample"]) for s in g["segments"]] == [
        (0, 56), (59, 199), (202, 332), (337, 539), (544, N - 1)]
    # the dropouts (v's flag 0 on samples 100 and 101) are counted in the segment that holds them
    assert [s["dropouts"]["v"] for s in g["segments"]] == [0, 2, 0, 0, 0]
    assert all(s["dropouts"]["q_m"] == 0 for s in g["segments"])
    rows = _predictions(runs["asc"] / "predictions.csv")
    for k in sorted(LOST) + [58, 201, 336, 541, 543]:  # nothing predicted for a sample not stepped
        assert rows[k]["q_m_hat"] == "" and rows[k]["q_m_err"] == ""
    for k in (59, 202, 337, 544):  # the first sample of a segment: its x̂ was made before the gap, not scored
        assert rows[k]["q_m_hat"] != "" and rows[k]["q_m_err"] == ""
    assert rows[60]["q_m_err"] != "" and rows[100]["v_err"] == ""  # a dropout: not valid, predicted through
    assert rows[100]["v_hat"] != ""


def test_the_predictions_are_the_firmware_estimates_on_the_same_stream(files: dict[str, Path],
                                                                        runs: dict[str, Path]) -> None:
    app = FirmwareApp(None, load_shipped("firmware-lim").config)
    est_sig = firmware.database().get_message_by_name("Estimate")
    got: dict[int, list[int]] = {}
    for k, m in enumerate(_frames()):
        if k in LOST:
            continue
        for e in app.handle(m):
            got[k] = [int(v) for v in firmware.decode_estimate(e, scaling=False).xhat]
    c = app.counters
    g = json.loads((runs["log"] / "metrics.json").read_text())["gaps"]
    assert (c["lost_frames"], c["seq_gaps"], c["restarts"], c["rejected_seq_jump"]) == (
        g["lost_samples"], g["gaps"], g["restarts"], g["rejected_after_gap"])
    segs = segments_of(np.array([k in LOST for k in range(N)]))
    assert sorted(got) == list(np.flatnonzero(segs.stepped))  # the firmware stepped the same samples
    rows = _predictions(runs["log"] / "predictions.csv")
    checked = 0
    for k in got:  # the firmware's Estimate of frame k is x̂(k+1): row k+1, where k+1 is stepped in the segment
        if k + 1 < N and segs.stepped[k + 1] and not segs.starts()[k + 1]:
            ours = [est_sig.get_signal_by_name(s + "Hat").scaled_to_raw(float(rows[k + 1][f"{n}_hat"]))
                    for s, n in zip(firmware.STATE_SIGNALS, STATES)]
            assert [int(v) for v in ours] == got[k], k
            checked += 1
    assert checked > N - 20


def test_segments_of_refuses_a_record_that_starts_or_ends_lost() -> None:
    with pytest.raises(ValueError, match="sample 0 is lost"):
        segments_of(np.array([True, False, False]))
    with pytest.raises(ValueError, match="expected a non-empty"):
        segments_of(np.zeros(3, dtype=np.int8))


def test_a_csv_whose_first_row_is_lost_is_refused_naming_the_line(files: dict[str, Path], tmp_path: Path,
                                                                  cli_error) -> None:
    lines = files["csv"].read_text().splitlines()
    header, first = lines[0], lines[1].split(",")
    first[-1] = "1"
    (tmp_path / "bad.csv").write_text("\n".join([header, ",".join(first), *lines[2:]]) + "\n")
    err = cli_error(["identify", str(tmp_path / "bad.csv"), "--config", str(files["config"]), "--out",
                     str(tmp_path / "o")])
    assert "line 2, column 'lost': the first data row cannot be a lost sample" in err


def test_a_free_run_ends_with_its_segment_and_k_step_predictions_restart_after_a_gap(
        files: dict[str, Path], tmp_path: Path) -> None:
    assert main(["identify", str(files["csv"]), "--config", str(files["config"]), "--out", str(tmp_path / "o"),
                 "--free-run-from", "250", "--steps-ahead", "3", "--no-plots"]) == 0
    with (tmp_path / "o" / "predictions.csv").open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    free = [k for k, r in enumerate(rows) if r["q_m_free_run"] != ""]
    assert free == list(range(250, 333))  # from K to the end of its segment (the gap at 333)
    ahead = {k for k, r in enumerate(rows) if r["q_m_ahead3"] != ""}
    for a, b in [(0, 57), (59, 200), (202, 333), (337, 540), (544, N)]:  # the first 3 of every segment have none
        assert ahead & set(range(a, b)) == set(range(a + 3, b))
    m = json.loads((tmp_path / "o" / "metrics.json").read_text())
    assert m["free_run"]["states"]["q_m"]["scored"] == 333 - 250
    assert all(np.isfinite(s["rmse"]) for kind in ("one_step", "free_run", "steps_ahead")
               for s in m[kind]["states"].values())


def test_commands_that_need_a_record_without_gaps_refuse_a_lost_sample_naming_its_line(files: dict[str, Path],
                                                                                     tmp_path: Path, cli_error) -> None:
    err = cli_error(["export", "--config", str(files["config"]), "--out", str(tmp_path / "e.h"), "--data",
                     str(files["csv"])])
    assert f"{files['csv']}: line {min(LOST) + 2}, column 'lost': a lost sample; this command needs a record " \
           "without gaps" in err and not (tmp_path / "e.h").exists()


def test_numbered_by_the_sequence_counter_across_its_wrap_the_gaps_are_the_same(
        files: dict[str, Path], runs: dict[str, Path], tmp_path: Path) -> None:
    assert main(["identify", "--can-log", str(files["blf"]), "--dbc", str(files["dbc"]), "--config",
                 str(files["config"]), "--counter", "Measurement.Seq", "--out", str(tmp_path / "n"), "--no-plots"]) == 0
    assert _predictions(tmp_path / "n" / "predictions.csv") == _predictions(runs["csv"] / "predictions.csv")
    g = json.loads((tmp_path / "n" / "metrics.json").read_text())["gaps"]
    assert g["lost_samples"] == len(LOST) and g["gaps"] == 5
