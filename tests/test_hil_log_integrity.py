"""A hil log is whole or refused: its sidecar records the frame count and the
log's SHA-256; a log cut short, changed, without a sidecar, or of a run
stopped by SIGINT/SIGTERM (marked partial) is refused by ``hil score`` and
``hil replay --from-log`` with a message saying which; an interrupted write
leaves the previous log or none."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

can = pytest.importorskip("can")
pytest.importorskip("cantools")

import hil.transport  # noqa: E402
from hil.rig import read_log, write_log  # noqa: E402
from hil.scenario import Scenario  # noqa: E402
from hil.transport import run_replay  # noqa: E402
from killing import kill_while_writing  # noqa: E402
from pyrhonn.cli import main as pyrhonn_main  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
MEAS_ID = 0x100


@pytest.fixture(scope="module")
def run_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A whole 1 s virtual run recorded as BLF (about 7,000 frames)."""
    log = tmp_path_factory.mktemp("run") / "run.blf"
    assert pyrhonn_main(["hil", "replay", "--transport", "virtual", "--duration", "1.0", "--log", str(log)]) == 0
    return log


def _copy(log: Path, folder: Path, name: str) -> Path:
    dst = folder / name
    dst.write_bytes(log.read_bytes())
    Path(str(dst) + ".json").write_bytes(Path(str(log) + ".json").read_bytes())
    return dst


def _refusals(log: Path, cli_error) -> list[str]:
    """What ``hil score`` and ``hil replay --from-log`` say about ``log`` (each must exit 2)."""
    return [cli_error(["hil", "score", str(log)]),
            cli_error(["hil", "replay", "--transport", "virtual", "--from-log", str(log)])]


def test_the_sidecar_records_the_frame_count_and_the_logs_sha256(run_log) -> None:
    import hashlib

    meta = json.loads(Path(str(run_log) + ".json").read_text())
    assert meta["sha256"] == hashlib.sha256(run_log.read_bytes()).hexdigest()
    assert meta["frames"] == len(read_log(run_log).events) > 6000 and meta["partial"] is None


@pytest.mark.parametrize("suffix", [".blf", ".asc"])
def test_a_log_cut_short_after_it_was_written_is_refused_naming_the_missing_frames(run_log, tmp_path, cli_error,
                                                                                  suffix) -> None:
    log = tmp_path / f"run{suffix}"
    write_log(read_log(run_log), log)
    data = log.read_bytes()
    if suffix == ".asc":  # cut at a line boundary: the reader sees a clean, shorter log
        cut = data.index(b"\n", len(data) * 2 // 5) + 1
    else:                 # cut inside a compressed container: the reader stops at the cut
        cut = len(data) * 2 // 5
    log.write_bytes(data[:cut])
    expected = json.loads(Path(str(log) + ".json").read_text())["frames"]
    kept = 0
    try:
        reader = can.ASCReader(log) if suffix == ".asc" else can.BLFReader(log)
        for _ in reader:
            kept += 1
    except Exception:  # noqa: BLE001 - the BLF reader fails at the cut
        pass
    assert 0 < expected - kept < expected or suffix == ".blf"
    message = f"{expected - kept} of the {expected} frames its sidecar records are missing"
    with pytest.raises(ValueError, match=message):
        read_log(log)
    for err in _refusals(log, cli_error):
        assert message in err and "cut short" in err


def test_a_log_without_a_sidecar_is_refused_plainly(run_log, tmp_path, cli_error) -> None:
    log = tmp_path / "run.blf"
    log.write_bytes(run_log.read_bytes())
    for err in _refusals(log, cli_error):
        assert "no sidecar run.blf.json" in err and "nothing says the log is whole" in err


def test_a_sidecar_without_a_checksum_is_refused_plainly(run_log, tmp_path, cli_error) -> None:
    log = _copy(run_log, tmp_path, "run.blf")
    side = Path(str(log) + ".json")
    meta = json.loads(side.read_text())
    del meta["sha256"]
    side.write_text(json.dumps(meta))
    for err in _refusals(log, cli_error):
        assert "records no frame count and checksum" in err


def test_a_log_changed_after_it_was_written_is_refused_by_its_checksum(run_log, tmp_path, cli_error) -> None:
    log = tmp_path / "run.asc"
    write_log(read_log(run_log), log)
    lines = log.read_bytes().split(b"\n")
    i = next(i for i, ln in enumerate(lines) if b" Tx        100 " in ln)  # a Measurement frame
    changed = lines[i].replace(b" 20 00 00 ", b" 20 01 00 ", 1)            # one data byte (Seq) changed
    assert changed != lines[i]
    lines[i] = changed
    log.write_bytes(b"\n".join(lines))
    for err in _refusals(log, cli_error):
        assert "its SHA-256 does not match the one its sidecar run.asc.json records" in err


# -- SIGINT / SIGTERM during a replay ------------------------------------------------------------------------


@pytest.fixture
def signal_at_frame_40(monkeypatch: pytest.MonkeyPatch):
    """``arm(signum)``: the next replay sends ``signum`` to this process right after Measurement frame 40
    (as a user's Ctrl-C or a service manager's SIGTERM would, at a known moment). A SIGTERM that the
    command line does not catch fails the test instead of ending the test session."""
    armed: dict[str, int] = {}
    real = hil.transport.run_replay

    def replay(*args, **kwargs):
        kwargs["extra_frames"] = lambda k: (os.kill(os.getpid(), armed["signum"]) or []) if k == 40 else []
        return real(*args, **kwargs)

    def unhandled(signum, _frame):
        raise AssertionError("SIGTERM reached the test: the replay did not handle it")

    monkeypatch.setattr(hil.transport, "run_replay", replay)
    before = signal.signal(signal.SIGTERM, unhandled)
    yield lambda signum: armed.update(signum=signum)
    signal.signal(signal.SIGTERM, before)


@pytest.mark.parametrize("signum, code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_sigint_and_sigterm_during_a_replay_leave_a_whole_log_marked_partial(tmp_path, capsys, cli_error,
                                                                            signal_at_frame_40, signum,
                                                                            code) -> None:
    log = tmp_path / "run.blf"
    signal_at_frame_40(signum)
    assert pyrhonn_main(["hil", "replay", "--transport", "virtual", "--duration", "0.3", "--log", str(log)]) == code
    err = capsys.readouterr().err
    name = signal.Signals(signum).name
    assert f"interrupted by {name}" in err and "marked partial" in err
    meta = json.loads(Path(str(log) + ".json").read_text())
    assert meta["partial"].startswith(f"interrupted by {name}")
    rec = read_log(log, partial=True)  # whole and readable: every frame up to the signal
    assert len(rec.events) == meta["frames"]
    sent = [m for _, d, m in rec.events if d == "tx" and m.arbitration_id == MEAS_ID]
    assert len(sent) == 41
    for refusal in _refusals(log, cli_error):
        assert f"a partial log (interrupted by {name}" in refusal and "did not finish" in refusal
    # scored anyway on request: said partial, and not accounted for (exit 1)
    assert pyrhonn_main(["hil", "score", str(log), "--partial"]) == 1
    assert f"PARTIAL LOG: interrupted by {name}" in capsys.readouterr().out


@pytest.mark.parametrize("signum, code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_signal_sent_to_a_replay_process_leaves_a_partial_log(tmp_path, cli_error, signum, code) -> None:
    """The same from outside, as a user or a service manager does it, on a real process."""
    log = tmp_path / "run.blf"
    # the pyrhonn this interpreter imports (the installed one; the source tree has no compiled core)
    proc = subprocess.Popen([sys.executable, "-m", "pyrhonn.cli", "hil", "replay", "--transport", "virtual",
                             "--duration", "10", "--log", str(log)], stderr=subprocess.PIPE, text=True,
                            stdout=subprocess.DEVNULL, cwd=str(tmp_path))
    try:
        first = proc.stderr.readline()  # printed once the handlers are in place, right before the run
        assert "cycles over virtual" in first, first
        time.sleep(3.0)                 # into the run, usually (any moment after that line leaves a partial log)
        proc.send_signal(signum)
        rest = proc.communicate(timeout=300)[1]
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == code, rest
    meta = json.loads(Path(str(log) + ".json").read_text())
    assert meta["partial"].startswith(f"interrupted by {signal.Signals(signum).name}")
    assert len(read_log(log, partial=True).events) == meta["frames"]
    assert all("a partial log" in refusal for refusal in _refusals(log, cli_error))


def test_a_log_write_killed_at_any_moment_leaves_a_whole_log_or_a_refused_one(tmp_path) -> None:
    """20 times: a child process writes two different runs in turn over one log and is killed
    (SIGKILL) at a random moment; the log reads back whole, as one of them, or (killed between the log
    and its sidecar) is refused; never a part of a log passed off as a run."""
    runs = [run_replay(Scenario(duration=d, seed=s), "virtual") for d, s in ((0.3, 1), (0.6, 2))]
    path = tmp_path / "run.blf"
    write_log(runs[0], path)
    counts = {len(r.events) for r in runs}
    assert len(counts) == 2
    rng = np.random.default_rng(5)
    seen = set()
    for _ in range(20):
        kill_while_writing([lambda: write_log(runs[1], path), lambda: write_log(runs[0], path)], rng,
                           max_delay=0.3)
        reader = can.BLFReader(path)   # the log file itself is always one whole run (never a prefix) ...
        frames = sum(1 for _ in reader)
        reader.stop()
        assert frames in counts
        try:
            assert len(read_log(path).events) == frames
            seen.add(frames)
        except ValueError as exc:  # ... and killed between the log and its sidecar, the pair is refused
            assert "SHA-256 does not match" in str(exc) or "frames its sidecar records are missing" in str(exc)
            seen.add("refused")
    assert counts <= seen


def test_a_replay_interrupted_while_writing_its_report_leaves_the_out_folder_marked_incomplete(
        tmp_path, monkeypatch, capsys) -> None:
    import hil.report
    from pyrhonn.atomic import MARKER, incomplete

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    out, log = tmp_path / "report", tmp_path / "run.blf"
    monkeypatch.setattr(hil.report, "figures", interrupted)  # Ctrl-C after report.json and report.txt
    argv = ["hil", "replay", "--transport", "virtual", "--duration", "0.05", "--out", str(out), "--log", str(log)]
    assert pyrhonn_main(argv) == 130
    assert "pyrhonn hil" in incomplete(out) and json.loads((out / "report.json").read_text())["frames"]
    assert len(read_log(log).events) > 0  # the log was written before the report: whole, not partial
    monkeypatch.undo()
    assert pyrhonn_main(argv) == 0
    assert not (out / MARKER).exists() and (out / "position.png").is_file()


def test_a_replay_interrupted_before_its_first_frame_leaves_an_empty_partial_log(tmp_path, monkeypatch,
                                                                                 cli_error) -> None:
    def interrupted(*args, **kwargs):  # Ctrl-C while the transport is being set up
        raise KeyboardInterrupt

    log = tmp_path / "run.asc"
    write_log(run_replay(Scenario(duration=0.03), "virtual"), log)  # a previous run's log at that path
    monkeypatch.setattr(hil.transport, "run_replay", interrupted)
    assert pyrhonn_main(["hil", "replay", "--transport", "virtual", "--duration", "0.3", "--log", str(log)]) == 130
    assert read_log(log, partial=True).events == []
    assert all("a partial log (interrupted by SIGINT before the first frame" in refusal
               for refusal in _refusals(log, cli_error))


@pytest.mark.parametrize("signum, code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_signal_while_the_log_is_written_after_the_run_waits_for_the_whole_log(tmp_path, monkeypatch, capsys,
                                                                                signum, code) -> None:
    import hil.rig

    real = hil.rig.write_log

    def signalled_mid_write(rec, path):
        os.kill(os.getpid(), signum)  # arrives while this log is being written
        return real(rec, path)

    def unhandled(_signum, _frame):
        raise AssertionError("SIGTERM reached the test: the log write did not hold it")

    monkeypatch.setattr(hil.rig, "write_log", signalled_mid_write)
    before = signal.signal(signal.SIGTERM, unhandled)
    try:
        log = tmp_path / "run.blf"
        assert pyrhonn_main(["hil", "replay", "--transport", "virtual", "--duration", "0.05", "--log",
                             str(log)]) == code
    finally:
        signal.signal(signal.SIGTERM, before)
    assert "after the run; the log is complete" in capsys.readouterr().err
    rec = read_log(log)  # whole, and not partial: the run itself had finished
    assert sum(1 for _, d, m in rec.events if d == "tx" and m.arbitration_id == MEAS_ID) == Scenario(
        duration=0.05).cycles
