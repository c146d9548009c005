"""``identify --can-log`` reads a bus log a chunk of frames at a time: the same predictions, samples, metrics
and refusals as the log read whole, wherever the chunks fall (a gap, a late frame, a lost clock frame or a
frame pair split between chunks, chunks of one frame), in every format; the frames held stay bounded
whatever the log's length; metrics.json lists a bounded number of gaps."""
from __future__ import annotations

import json
from pathlib import Path
from typing import Callable

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

can = pytest.importorskip("can")
cantools = pytest.importorskip("cantools")

from pyrhonn import buslogstream  # noqa: E402
from pyrhonn.buslog import AlignedSummary, BusMap, SignalRef, read_bus_log  # noqa: E402
from pyrhonn.buslogstream import BusStream  # noqa: E402
from pyrhonn.cli import bus_input, main  # noqa: E402
from pyrhonn.configfile import loads, shipped_text  # noqa: E402
from pyrhonn.gaps import LISTED, SegmentTracker, segments_of  # noqa: E402
from test_cli_identify_canlog import BUS, DBC, PERIOD, T0, _candump, _log_through_virtual_bus, _recording  # noqa: E402

#: Command frames dropped: lost samples (gaps) inside the run, one of them two samples long
LOST_U = {9, 50, 51, 77}


def _frames(K: int | None = None) -> list[can.Message]:
    rec = _recording()
    commands = [m for m in rec.frames if m.arbitration_id == 512]
    gone = {id(commands[k]) for k in LOST_U}
    frames = [m for m in rec.frames if id(m) not in gone]
    if K is not None:  # the recording repeated to K samples (times shifted on)
        n = len(rec.X)
        frames = [can.Message(timestamp=round(m.timestamp + r * n * PERIOD, 6), arbitration_id=m.arbitration_id,
                              data=m.data, dlc=m.dlc, is_extended_id=False)
                  for r in range(-(-K // n)) for m in frames]
    return frames


def _write(frames: list[can.Message], path: Path) -> Path:
    if path.suffix == ".log":
        _candump(frames, path)
    elif path.suffix == ".mf4":
        with can.Logger(str(path)) as logger:
            for m in frames:
                logger.on_message_received(m)
    else:
        _log_through_virtual_bus(frames, path)
    return path


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("stream")
    (d / "plant.dbc").write_text(DBC)
    (d / "cfg.toml").write_text(shipped_text("example1") + BUS)
    frames = _frames()
    out = {"dbc": d / "plant.dbc", "config": d / "cfg.toml"}
    for suffix in ("log", "asc", "blf", "mf4"):
        out[suffix] = _write(frames, d / f"run.{suffix}")
    return out


Run = Callable[..., tuple[int, dict[str, bytes], str, str]]


@pytest.fixture
def identify(logs: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str],
             monkeypatch: pytest.MonkeyPatch) -> Run:
    """``identify(log, *extra, streamed=True, chunk=None)``: exit code, output files, stdout, stderr; streamed
    (and never read whole), read whole (False: the reference), or as the command chooses (None)."""
    count = [0]

    def run(log: Path, *extra: str, streamed: bool | None = True,
            chunk: int | None = None) -> tuple[int, dict[str, bytes], str, str]:
        count[0] += 1
        out = tmp_path / f"out{count[0]}"
        with monkeypatch.context() as m:
            if chunk is not None:
                m.setattr(buslogstream, "CHUNK_FRAMES", chunk)
            if streamed:
                def whole(*_: object) -> None:
                    raise AssertionError("the log was read whole")
                m.setattr(bus_input, "read", whole)
            elif streamed is not None:
                m.setattr(bus_input, "stream", bus_input.read)
            try:
                code = main(["identify", "--can-log", str(log), "--dbc", str(logs["dbc"]), "--config",
                             str(logs["config"]), "--out", str(out), "--warmup", "5", "--no-plots", *extra])
            except SystemExit as exc:
                code = int(exc.code or 0)
        got = capsys.readouterr()
        files = {p.name: p.read_bytes() for p in sorted(out.iterdir())} if out.is_dir() else {}
        return code, files, got.out.replace(str(out), "OUT"), got.err

    return run


def _same(a: tuple[int, dict[str, bytes], str, str], b: tuple[int, dict[str, bytes], str, str]) -> None:
    assert a[0] == b[0] == 0, (a[3], b[3])
    assert sorted(a[1]) == sorted(b[1]) == ["metrics.json", "predictions.csv", "samples.csv"]
    for name in ("predictions.csv", "samples.csv"):
        assert a[1][name] == b[1][name], name  # byte for byte
    ma, mb = json.loads(a[1]["metrics.json"]), json.loads(b[1]["metrics.json"])
    assert ma == mb
    assert a[2] == b[2]


@pytest.mark.parametrize("fmt", ["log", "asc", "blf", "mf4"])
def test_a_streamed_log_gives_the_whole_logs_outputs_byte_for_byte(logs: dict[str, Path], identify: Run,
                                                                   fmt: str) -> None:
    whole = identify(logs[fmt], streamed=False)
    report = json.loads(whole[1]["metrics.json"])
    assert report["gaps"]["lost_samples"] == len(LOST_U) and report["gaps"]["gaps"] == 3
    assert b",lost\n" in whole[1]["samples.csv"].split(b"\n", 1)[0] + b"\n"
    for chunk in (1, 2, 5, 64, None):  # a chunk of one frame; frame pairs and gaps split; the default
        _same(identify(logs[fmt], chunk=chunk), whole)


def test_start_stop_and_a_counter_stream_to_the_whole_logs_outputs(logs: dict[str, Path], identify: Run) -> None:
    for extra in (["--start", "0.3", "--stop", "0.9"], ["--clock", "Command", "--counter", "Command.Seq"],
                  ["--start", "0.2"]):
        whole = identify(logs["log"], *extra, streamed=False)
        for chunk in (1, 3, None):
            _same(identify(logs["log"], *extra, chunk=chunk), whole)


def test_without_lost_samples_the_samples_file_has_no_lost_column(logs: dict[str, Path], identify: Run,
                                                                   tmp_path: Path) -> None:
    log = tmp_path / "clean.log"
    _candump(_recording().frames, log)
    whole = identify(log, streamed=False)
    assert b"lost" not in whole[1]["samples.csv"].split(b"\n", 1)[0]
    _same(identify(log, chunk=3), whole)


def test_frames_out_of_order_beyond_what_is_held_are_read_whole_to_the_same_result(logs: dict[str, Path],
                                                                                   identify: Run,
                                                                                   tmp_path: Path) -> None:
    frames = _frames()
    late = frames.pop(40)  # logged 200 frames later than its time
    frames.insert(240, late)
    log = tmp_path / "shuffled.log"
    _candump(frames, log)
    whole = identify(log, streamed=False)
    with pytest.raises(AssertionError, match="read whole"):
        identify(log, chunk=8)  # it cannot be streamed ...
    _same(identify(log, chunk=8, streamed=None), whole)  # ... so the command reads it whole
    _same(identify(log, streamed=None), whole)  # a chunk holds it: streamed


def test_a_slightly_out_of_order_log_streams_to_the_whole_logs_outputs(logs: dict[str, Path], identify: Run,
                                                                        tmp_path: Path) -> None:
    frames = _frames()
    for i in range(10, len(frames) - 3, 17):  # neighbours swapped: two channels interleaving
        frames[i], frames[i + 1] = frames[i + 1], frames[i]
    log = tmp_path / "swapped.log"
    _candump(frames, log)
    _same(identify(log, chunk=16), identify(log, streamed=False))


@pytest.mark.parametrize("fmt", ["log", "asc", "blf"])
def test_a_truncated_log_is_refused_or_read_in_part_as_when_read_whole(logs: dict[str, Path], identify: Run,
                                                                       tmp_path: Path, fmt: str) -> None:
    raw = logs[fmt].read_bytes()
    cut = tmp_path / f"cut.{fmt}"
    cut.write_bytes(raw[:int(len(raw) * 0.37)])
    refused = identify(cut, chunk=4)
    assert refused[0] == 2 and "truncated" in refused[3] and not refused[1]
    assert refused[3] == identify(cut, streamed=False)[3]
    _same(identify(cut, "--partial-log", chunk=4), identify(cut, "--partial-log", streamed=False))


def test_a_refusal_found_at_the_end_writes_nothing_and_says_what_the_whole_read_says(
        logs: dict[str, Path], identify: Run) -> None:
    """The clock's frames disagree with the sample period: known once every interval is counted, after
    samples went through the identifier; nothing is written, and the message is the whole read's."""
    streamed = identify(logs["log"], "--sample-period", "0.007", chunk=4, streamed=None)
    assert streamed[0] == 2 and "sample period 0.007 s" in streamed[3] and not streamed[1]
    assert streamed[3] == identify(logs["log"], "--sample-period", "0.007", streamed=False)[3]


def _held(K: int, chunk: int, dbc: Path, log: Path) -> int:
    _candump(_frames(K), log)
    cf = loads(shipped_text("example1") + BUS)
    assert cf.bus is not None
    s = BusStream(log, dbc, cf.bus, cf.state_names, cf.input_names, chunk_frames=chunk)
    samples = sum(c.n_samples for c in s.chunks())
    assert s.summary is not None and samples == s.summary.n_samples > K * 0.9
    return s.peak_frames


def test_the_frames_held_are_bounded_by_the_chunk_whatever_the_logs_length(logs: dict[str, Path],
                                                                           tmp_path: Path) -> None:
    short = _held(500, 16, logs["dbc"], tmp_path / "short.log")
    long = _held(4000, 16, logs["dbc"], tmp_path / "long.log")
    assert long <= 16 + 4 + 8  # a chunk, its held-back quarter, a period's frames
    assert long <= short + 4
    assert _held(500, 64, logs["dbc"], tmp_path / "wider.log") > long  # the knob is what bounds it


def test_metrics_list_a_bounded_number_of_gaps_and_count_them_all() -> None:
    rng = np.random.default_rng(8)
    T = 6000
    lost = rng.random(T) < 0.05
    lost[0] = lost[-1] = False
    lost[3000:3040] = True  # the largest gap, far after the first ones
    valid = np.ones((T, 1), dtype=bool)
    lines = np.arange(2, T + 2)
    whole = segments_of(lost)
    tracker = SegmentTracker(("a",))
    for a in range(0, T, 777):
        tracker.feed(lost[a:a + 777], valid[a:a + 777], lines[a:a + 777], None)
    tracker.finish()
    report = tracker.report()
    assert report == whole.report(None, lines, valid, ("a",))
    assert report["gaps"] == len(whole.gaps) > 2 * LISTED and report["lost_samples"] == int(lost.sum())
    assert report["segment_count"] == len(whole.bounds)
    assert len(report["gap_list"]) == 2 * LISTED and len(report["segments"]) == 2 * LISTED
    assert report["listed"] == {**report["listed"], "limit": LISTED, "complete": False}
    listed = [g["first_lost"]["sample"] for g in report["gap_list"]]
    assert listed == sorted(listed) and listed[:LISTED] == [g.first for g in whole.gaps[:LISTED]]
    assert 3000 in listed  # the largest is listed
    smallest_listed = min(g["lost"] for g in report["gap_list"][LISTED:])
    assert all(g.lost <= smallest_listed for g in whole.gaps[LISTED:] if g.first not in listed)



@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
# a log whose clock intervals' median is the mean of an interval inside the period's tolerance and one above it
@example(K=49, seed=249055, chunk=1, counter=False, window=-1.0, drop=0.28125, stretch=False)
@given(K=st.integers(3, 90), seed=st.integers(0, 2**31), chunk=st.integers(1, 40), counter=st.booleans(),
       window=st.sampled_from([-1.0, -0.5, -0.2, 0.0]), drop=st.floats(0.0, 0.3), stretch=st.booleans())
def test_streamed_samples_equal_the_whole_reads_on_random_logs(tmp_path: Path, K: int, seed: int, chunk: int,
                                                             counter: bool, window: float, drop: float,
                                                             stretch: bool) -> None:
    """Random logs (frames lost, jittered, late into the next window, repeated clock frames, a counter that
    wraps): the chunks of a streamed read are the samples and counts of the log read whole, or the streamed
    read defers to the whole read, which refuses the log."""
    rng = np.random.default_rng(seed)
    db = cantools.database.load_string(DBC, database_format="dbc")
    frames: list[tuple[float, int, bytes]] = []
    for k in range(K):
        tk = T0 + k * PERIOD + float(rng.uniform(-0.2, 0.2)) * PERIOD
        for name, dt, values in (("StatesA", 0.0, {"X1": float(rng.normal()), "X2": float(rng.normal())}),
                                 ("StatesB", 0.15, {"X3": 0.5, "X3Valid": int(rng.random() > 0.1), "X4": -0.25,
                                                    "X4Valid": 1}),
                                 ("Command", 0.3, {"U": float(rng.normal()), "Seq": (k + 250) % 256})):
            if rng.random() < drop:
                continue
            late = PERIOD * float(rng.uniform(0.5, 1.2)) if rng.random() < 0.05 else 0.0
            msg = db.get_message_by_name(name)
            frames.append((round(tk + dt * PERIOD + late, 6), msg.frame_id, msg.encode(values)))
            if name == "StatesA" and rng.random() < 0.05:  # a repeat of the clock frame
                frames.append((round(tk + 0.1 * PERIOD, 6), msg.frame_id, msg.encode(values)))
    frames.sort(key=lambda f: f[0])
    log = tmp_path / "random.log"
    (tmp_path / "plant.dbc").write_text(DBC)
    log.write_text("".join(f"({t:.6f}) vcan0 {i:03X}#{d.hex().upper()}\n" for t, i, d in frames))
    cf = loads(shipped_text("example1") + BUS)
    assert cf.bus is not None
    bus = BusMap(signals=cf.bus.signals, valid=cf.bus.valid, sample_period=PERIOD,
                 clock="Command" if counter else "StatesA", window_start=window,
                 counter=SignalRef("Command", "Seq") if counter else None)
    span = {"start": 0.05, "stop": 0.6} if stretch else {}
    try:
        whole = read_bus_log(log, tmp_path / "plant.dbc", bus, cf.state_names, cf.input_names, **span)
    except ValueError:
        whole = None
    try:
        s = BusStream(log, tmp_path / "plant.dbc", bus, cf.state_names, cf.input_names, chunk_frames=chunk, **span)
        chunks = list(s.chunks())
    except buslogstream.Reread:
        assert whole is None, "a log read whole gave samples, but the streamed read deferred"
        return
    assert whole is not None, "the streamed read gave samples where the whole read refuses the log"
    got = {name: np.concatenate([getattr(c, name) for c in chunks]) for name in ("X", "U", "valid", "t", "lost")}
    for name in ("X", "U", "valid", "t", "lost"):
        assert np.array_equal(got[name], getattr(whole, name), equal_nan=name in ("X", "U")), name
    assert s.summary == AlignedSummary(**{f: getattr(whole, f) for f in AlignedSummary.__dataclass_fields__})
