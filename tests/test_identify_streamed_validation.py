"""``pyrhonn identify --free-run-from K --steps-ahead H`` streams the record: the one-step pass, the free run
and the H-step branches carried across chunks give the record-held-whole outputs (predictions.csv byte for
byte, metrics.json equal, the printed report equal) wherever the chunks fall (K on a chunk boundary or just
after one, a branch across one, H longer than a chunk, chunks of one row), with gaps, in float32 and
float64, for a diverging free run and one that leaves the data's range only by the whole record's measure,
for CSV files, bus logs and signal MDF4; the rows held are bounded by the chunk and H; settings that need
the record's length keep their messages and write nothing."""
from __future__ import annotations

import contextlib
import io
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pyrhonn import Identifier
from pyrhonn.identifier import IdentifierError
from pyrhonn.simulation import simulate
from pyrhonn.cli import identify as identify_cli
from pyrhonn.cli import main
from pyrhonn.config import Factor, IdentifierConfig, NeuronConfig
from pyrhonn.configfile import ConfigFile, dumps, load_shipped, shipped_text
from pyrhonn.gaps import SegmentTracker, segments_of, simulate_segments
from pyrhonn.residuals import departure, divergence_range
from pyrhonn.simulationstream import SimulationStream

from test_long_recordings import record  # noqa: F401 (the fixture: a LIM record with gaps and dropouts)

LIM = load_shipped("firmware-lim")
T = 96
LOST = np.zeros(T, dtype=bool)
LOST[[20, 21, 22, 51, 53, 80]] = True  # a run of three, two gaps one sample apart, a single one


def _trajectory(dtype: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(5)
    k = np.arange(T)[:, None]
    X = np.hstack([np.sin(k * 0.05 * (j + 1)) * (1 + j) for j in range(6)])
    U = np.hstack([np.sin(k * 0.2) * 150.0, np.cos(k * 0.2) * 150.0])
    valid = (rng.random((T, 6)) > 0.05) & ~LOST[:, None]
    X[~valid] = np.nan
    U[LOST] = np.nan  # a lost sample has no inputs
    return X.astype(dtype), U.astype(dtype), valid


def _streamed(cfg: IdentifierConfig, X: np.ndarray, U: np.ndarray, valid: np.ndarray, cuts: list[int],
              K: int | None, H: int | None) -> tuple[SimulationStream, dict[str, np.ndarray], int]:
    engine = SimulationStream(Identifier(cfg), free_run_from=K, steps=H)
    tracker = SegmentTracker(tuple(LIM.state_names))
    got: dict[str, list[np.ndarray]] = {"one": [], "free": [], "ahead": [], "free_rows": [], "ahead_rows": [],
                                        "starts": [], "tracker_starts": []}
    most = 0
    bounds = [0, *sorted(set(c for c in cuts if 0 < c < T)), T]
    for a, b in zip(bounds[:-1], bounds[1:]):
        stepped, starts = tracker.feed(LOST[a:b], valid[a:b], np.arange(a, b), None)
        got["tracker_starts"].append(starts)
        rows = engine.feed(X[a:b], U[a:b], valid[a:b], stepped)
        most = max(most, engine._X.shape[0] - (b - a))  # rows held from before this chunk
        for r in [rows] if rows is not None else []:
            got["one"].append(r.one_step)
            got["starts"].append(r.starts)
            for key, v in (("free", r.free_run), ("ahead", r.ahead), ("free_rows", r.free_rows),
                           ("ahead_rows", r.ahead_rows)):
                if v is not None:
                    got[key].append(v)
    tracker.finish()
    last = engine.finish()
    if last is not None:
        got["one"].append(last.one_step)
        got["starts"].append(last.starts)
        for key, v in (("free", last.free_run), ("ahead", last.ahead), ("free_rows", last.free_rows),
                       ("ahead_rows", last.ahead_rows)):
            if v is not None:
                got[key].append(v)
    return engine, {k: np.concatenate(v) for k, v in got.items() if v}, most


@settings(max_examples=30, deadline=None)
@given(dtype=st.sampled_from(["float32", "float64"]),
       cuts=st.lists(st.integers(1, T - 1), max_size=12),
       K=st.one_of(st.none(), st.integers(0, T - 1)), H=st.one_of(st.none(), st.integers(1, 12)))
def test_the_streamed_simulation_is_the_whole_records_bit_for_bit_wherever_the_chunks_fall(
        dtype: str, cuts: list[int], K: int | None, H: int | None) -> None:
    cfg = LIM.config.replace(dtype=dtype)
    X, U, valid = _trajectory(dtype)
    ref, free_rows, ahead_rows = simulate_segments(Identifier(cfg), X, U, valid, segments_of(LOST),
                                                   free_run_from=K, steps=H)
    engine, got, most = _streamed(cfg, X, U, valid, cuts, K, H)
    assert most <= (H or 0)  # what waits for the next chunk: the rows whose branch needs its inputs
    np.testing.assert_array_equal(got["one"], ref.one_step)
    np.testing.assert_array_equal(got["starts"], got["tracker_starts"])  # the segments' first samples
    np.testing.assert_array_equal(engine.next_prediction, ref.next_prediction)
    if K is not None:
        assert ref.free_run is not None
        np.testing.assert_array_equal(got["free"], ref.free_run)
        np.testing.assert_array_equal(got["free_rows"], free_rows)
        assert engine.free_run_diverged == ref.free_run_diverged
    if H is not None:
        assert ref.ahead is not None
        np.testing.assert_array_equal(got["ahead"], ref.ahead)
        np.testing.assert_array_equal(got["ahead_rows"], ahead_rows)


def test_the_rows_held_do_not_grow_with_the_record() -> None:
    cfg = LIM.config
    X, U, valid = _trajectory(cfg.dtype)
    _, _, most = _streamed(cfg, X, U, valid, list(range(0, T, 3)), 10, 7)
    assert 0 < most <= 7


def test_the_stream_refuses_bad_settings_and_chunks_naming_them() -> None:
    ident = Identifier(LIM.config)
    with pytest.raises(ValueError, match="^free_run_from: expected a whole number >= 0"):
        SimulationStream(ident, free_run_from=-1)
    with pytest.raises(ValueError, match="^steps: expected a whole number >= 1"):
        SimulationStream(ident, steps=0)
    engine = SimulationStream(ident, steps=2)
    X, U, valid = _trajectory(LIM.config.dtype)
    ok = np.ones(4, dtype=bool)
    with pytest.raises(ValueError, match=rf"^U: expected a {LIM.config.dtype} array of shape \(4, 2\)"):
        engine.feed(X[:4], U[:4, :1], valid[:4], ok)
    with pytest.raises(ValueError, match=r"^U\[0, 0\]: not finite"):
        engine.feed(X[20:24], U[20:24], valid[20:24], ok)
    assert engine._X.shape[0] == 0 and engine.finish() is None  # nothing taken


def test_a_non_finite_value_is_named_by_its_sample_in_the_record() -> None:
    engine = SimulationStream(Identifier(LIM.config), steps=2)
    X, U, valid = _trajectory(LIM.config.dtype)
    ok = np.ones(8, dtype=bool)
    assert engine.feed(X[:8], U[:8], valid[:8], ok) is not None
    stepped = ok.copy()
    stepped[:2] = False  # two samples of the next chunk lost: the bad input is its third stepped row
    U_bad = U[8:16].copy()
    U_bad[4, 1] = np.inf
    with pytest.raises(ValueError, match=r"^U\[12, 1\]: not finite"):
        engine.feed(X[8:16], U_bad, valid[8:16], stepped)


def test_a_failure_of_the_identifier_names_the_sample_in_the_record_and_stops_the_stream() -> None:
    cfg = IdentifierConfig(n_states=1, n_inputs=1, neurons=(NeuronConfig(
        terms=((Factor.x(0),), (Factor.u(0),)), w0=np.array([2.0, 0.5])),))
    X = np.full((60, 1), 0.1)
    X[37] = 1e308  # its prediction 2e308 is not finite
    U, V = np.ones((60, 1)), np.ones((60, 1), dtype=bool)
    with pytest.raises(IdentifierError) as whole:
        simulate(Identifier(cfg), X, U, V, steps=3)
    engine = SimulationStream(Identifier(cfg), steps=3)
    with pytest.raises(IdentifierError) as streamed:
        for a in range(0, 60, 10):
            engine.feed(X[a:a + 10], U[a:a + 10], V[a:a + 10], np.ones(10, dtype=bool))
    assert str(streamed.value) == str(whole.value) and "at sample 37" in str(whole.value)
    assert streamed.value.sample == 37
    with pytest.raises(ValueError, match="^the stream stopped: .*at sample 37"):
        engine.finish()


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), cuts=st.lists(st.integers(1, 59), max_size=6),
       drift=st.floats(0.0, 0.2), constant=st.booleans())
def test_where_a_free_run_leaves_the_range_found_chunk_by_chunk_is_the_whole_records(
        seed: int, cuts: list[int], drift: float, constant: bool) -> None:
    """Measurements whose range widens as they come (a state constant for a while, one never valid), a free
    run that drifts off and may stop being finite: the first line outside the whole record's range."""
    rng = np.random.default_rng(seed)
    T, n = 60, 3
    X = np.cumsum(rng.standard_normal((T, n)), axis=0)
    if constant:  # not moving for 40 samples, then barely: its range is widened by nothing until it moves
        X[:, 0] = 2.0 + np.r_[np.zeros(40), 0.01 * rng.standard_normal(T - 40)]
    valid = rng.random((T, n)) > 0.2
    valid[:, 2] = False  # never measured: the whole real line
    free = X + drift * np.arange(T)[:, None] ** 1.5 * rng.standard_normal(n)
    if constant:  # near the constant, outside the whole record's narrow range from the start
        free[:, 0] = X[:, 0] + rng.uniform(0.1, 0.5, T)
    free[rng.random((T, n)) < 0.02] = np.nan
    rows = rng.random(T) > 0.1
    lines = np.arange(2, T + 2)
    low, high = divergence_range(X, valid)
    gone = [int(k) for k in departure(free, rows, low, high) if k >= 0]
    watch = identify_cli._RangeWatch(n)
    bounds = [0, *sorted(set(cuts)), T]
    for a, b in zip(bounds[:-1], bounds[1:]):
        watch.add(X[a:b], valid[a:b], free[a:b], rows[a:b], lines[a:b])
    assert watch.left_line() == (int(lines[min(gone)]) if gone else None)
    watch.close()


# -- through pyrhonn identify ------------------------------------------------------------------------


def _identify(monkeypatch: pytest.MonkeyPatch, args: list[str], out: Path, whole: bool = False,
              piece: int | None = None) -> tuple[int, dict[str, bytes], str]:
    """exit code, output files, stdout (the output folder as OUT); the record held whole or streamed in
    pieces of ``piece`` rows."""
    printed = io.StringIO()
    with monkeypatch.context() as m:
        m.setattr(identify_cli, "_WHOLE_RECORD", whole)
        m.setattr(identify_cli, "_PIECE_ROWS", piece)
        with contextlib.redirect_stdout(printed):
            code = main(["identify", *args, "--out", str(out), "--no-plots"])
    files = {p.name: p.read_bytes() for p in sorted(out.iterdir())} if out.is_dir() else {}
    return code, files, printed.getvalue().replace(str(out), "OUT")


def _same(a: tuple[int, dict[str, bytes], str], b: tuple[int, dict[str, bytes], str]) -> dict[str, Any]:
    assert a[0] == b[0] == 0
    assert sorted(a[1]) == sorted(b[1])
    for name in a[1]:
        if name != "metrics.json":
            assert a[1][name] == b[1][name], name  # byte for byte
    report = json.loads(a[1]["metrics.json"])
    assert report == json.loads(b[1]["metrics.json"])
    assert a[2] == b[2]
    return report


@pytest.mark.parametrize("extra, pieces", [
    (["--free-run-from", "50", "--steps-ahead", "4"], [50, 49, 3, 1]),  # K on a boundary, one after; H > chunk
    (["--free-run-from", "31", "--steps-ahead", "9", "--warmup", "3", "--dtype", "float64"], [16, 5]),  # K in a gap
    (["--free-run-from", "78", "--steps-ahead", "1", "--dtype", "float32"], [7, 2]),
    (["--steps-ahead", "6", "--dtype", "float32"], [30, 1]),
])
def test_identify_streams_a_csv_with_gaps_to_the_whole_records_outputs(
        record: tuple[Path, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch, extra: list[str],  # noqa: F811
        pieces: list[int]) -> None:
    data, config = record
    args = [str(data), "--config", str(config), *extra]
    whole = _identify(monkeypatch, args, tmp_path / "whole", whole=True)
    report = json.loads(whole[1]["metrics.json"])
    assert report["gaps"]["gaps"] == 4
    for piece in [*pieces, None]:
        _same(_identify(monkeypatch, args, tmp_path / f"s{piece}", piece=piece), whole)


def _unstable(path: Path, w: float) -> Path:
    """x̂(k+1) = w x(k) + 0.5 u(k): with |w| > 1 its free run grows without bound."""
    cfg = IdentifierConfig(n_states=1, n_inputs=1, neurons=(NeuronConfig(
        terms=((Factor.x(0),), (Factor.u(0),)), w0=np.array([w, 0.5])),))
    path.write_text(dumps(ConfigFile.from_config(cfg, state_names=("y",), input_names=("u",))))
    return path


def _plant_csv(path: Path, y: np.ndarray, u: np.ndarray) -> Path:
    path.write_text("y,u\n" + "".join(f"{float(a)!r},{float(b)!r}\n" for a, b in zip(y, u)))
    return path


def test_a_diverging_free_run_streams_to_the_whole_records_outputs(tmp_path: Path,
                                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    rng = np.random.default_rng(3)
    u = np.repeat(rng.uniform(-1, 1, 40), 5)
    y = np.convolve(u, [0.0, 0.5, 0.3, 0.1])[:u.size]
    data = _plant_csv(tmp_path / "run.csv", y, u)
    args = [str(data), "--config", str(_unstable(tmp_path / "cfg.toml", 2.0)), "--free-run-from", "3",
            "--steps-ahead", "3", "--dtype", "float32"]
    whole = _identify(monkeypatch, args, tmp_path / "whole", whole=True)
    report = json.loads(whole[1]["metrics.json"])
    line = report["free_run"]["diverged_at_line"]
    assert line is not None and f"the free run diverged at line {line}" in whole[2]
    for piece in (1, 7, 64, None):
        _same(_identify(monkeypatch, args, tmp_path / f"s{piece}", piece=piece), whole)


def test_where_the_free_run_leaves_the_range_is_measured_on_the_whole_record(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The free run leaves the range of the first 180 samples long before it leaves the whole record's,
    which a late excursion widens: the streamed run names the same line as the record held whole."""
    k = np.arange(200)
    u = np.ones(200)
    y = 0.5 + 0.1 * np.sin(0.3 * k)
    y[185] = 400.0  # late and large: the whole record's range, [-400, 800], is far wider than its beginning's
    data = _plant_csv(tmp_path / "run.csv", y, u)
    # weights frozen from sample 0: x̂(k) = 25 (1.02^k - 1), out of [0.4, 0.6] widened at once, of [-400, 800]
    # only at sample 177
    args = [str(data), "--config", str(_unstable(tmp_path / "cfg.toml", 1.02)), "--free-run-from", "0"]
    whole = _identify(monkeypatch, args, tmp_path / "whole", whole=True)
    line = json.loads(whole[1]["metrics.json"])["free_run"]["left_range_at_line"]
    assert line == 177 + 2
    for piece in (1, 10, 33, None):
        report = _same(_identify(monkeypatch, args, tmp_path / f"s{piece}", piece=piece), whole)
        assert report["free_run"]["left_range_at_line"] == line


@pytest.mark.parametrize("args, message", [
    (["--free-run-from", "200"], "--free-run-from 200: beyond the data (200 rows, samples 0..199)"),
    (["--steps-ahead", "200"], "--steps-ahead 200: needs more than 200 data rows, the file has 200"),
    (["--free-run-from", "5", "--warmup", "199"], "--warmup 199: leaves nothing to score"),
])
def test_settings_known_only_at_the_end_keep_their_message_and_write_nothing(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], args: list[str],
        message: str) -> None:
    u = np.sin(np.arange(200) * 0.1)
    data = _plant_csv(tmp_path / "run.csv", 0.5 * u, u)
    code, files, _ = _identify(monkeypatch, [str(data), "--config", str(_unstable(tmp_path / "c.toml", 0.5)),
                                             *args], tmp_path / "out", piece=7)
    err = capsys.readouterr().err
    assert code == 2 and message in err and "Traceback" not in err
    assert files == {}


@pytest.mark.parametrize("args, message", [
    (["--free-run-from", "300"], "--free-run-from 300: beyond the data (200 rows, samples 0..199)"),
    (["--steps-ahead", "3"], "line 7, column 'y': 1e+39 overflows float32 (--dtype float32)"),
])
def test_a_defect_found_while_streaming_is_said_after_the_settings_as_when_held_whole(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], args: list[str],
        message: str) -> None:
    """A value that overflows float32 in the record's first chunk: a --free-run-from beyond the record is
    named first, as the record held whole names it; alone, the value is named by its line."""
    u = np.sin(np.arange(200) * 0.1)
    y = 0.5 * u
    y[5] = 1e39
    data = _plant_csv(tmp_path / "run.csv", y, u)
    full = [str(data), "--config", str(_unstable(tmp_path / "c.toml", 0.5)), "--dtype", "float32", *args]
    for whole, piece in ((True, None), (False, 7), (False, None)):
        code, files, _ = _identify(monkeypatch, full, tmp_path / f"out{piece}", whole=whole, piece=piece)
        err = capsys.readouterr().err
        assert code == 2 and message in err and "Traceback" not in err, (whole, err)
        assert files == {}


@pytest.mark.parametrize("args, message", [
    (["--steps-ahead", "3"], "run.csv: line 39: the identifier stopped: neurons[0]: weights or prediction would "
                             "not be finite at sample 37"),
    (["--steps-ahead", "80"], "--steps-ahead 80: needs more than 80 data rows, the file has 60"),
])
def test_a_failure_of_the_identifier_while_streaming_says_what_the_record_held_whole_says(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], args: list[str],
        message: str) -> None:
    y = np.full(60, 0.1)
    y[37] = 1e308  # its prediction 2e308 is not finite
    data = _plant_csv(tmp_path / "run.csv", y, np.ones(60))
    full = [str(data), "--config", str(_unstable(tmp_path / "c.toml", 2.0)), *args]
    for whole, piece in ((True, None), (False, 10), (False, 1)):
        code, files, _ = _identify(monkeypatch, full, tmp_path / f"out{piece}", whole=whole, piece=piece)
        err = capsys.readouterr().err
        assert code == 2 and message in err and "Traceback" not in err, (whole, err)
        assert files == {}


def test_a_bus_log_streams_a_free_run_and_k_step_predictions_to_the_whole_logs_outputs(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    pytest.importorskip("cantools")
    can = pytest.importorskip("can")
    from test_buslog_streaming import _frames, _write
    from test_cli_identify_canlog import BUS, DBC

    from pyrhonn import buslogstream
    from pyrhonn.cli import bus_input

    bus_input_read = bus_input.read
    (tmp_path / "plant.dbc").write_text(DBC)
    (tmp_path / "cfg.toml").write_text(shipped_text("example1") + BUS)
    assert can is not None
    log = _write(_frames(), tmp_path / "run.log")
    args = ["--can-log", str(log), "--dbc", str(tmp_path / "plant.dbc"), "--config", str(tmp_path / "cfg.toml"),
            "--free-run-from", "60", "--steps-ahead", "5", "--warmup", "5"]
    whole = _identify(monkeypatch, args, tmp_path / "whole", whole=True)
    assert json.loads(whole[1]["metrics.json"])["gaps"]["gaps"] == 3
    for chunk in (1, 5, None):
        with monkeypatch.context() as m:
            def read_whole(*_: object) -> None:
                raise AssertionError("the log was read whole")
            m.setattr(bus_input, "read", read_whole)
            if chunk is not None:
                m.setattr(buslogstream, "CHUNK_FRAMES", chunk)
            got = _identify(monkeypatch, args, tmp_path / f"s{chunk}", piece=3)
        _same(got, whole)
    # a frame logged too late to stream: the log is read whole (BusStream's Reread), to the same result
    frames = _frames()
    frames.insert(240, frames.pop(40))
    late = _write(frames, tmp_path / "late.log")
    late_args = [str(late) if a == str(log) else a for a in args]
    reference = _identify(monkeypatch, late_args, tmp_path / "late-whole", whole=True)
    reads: list[object] = []
    with monkeypatch.context() as m:
        m.setattr(buslogstream, "CHUNK_FRAMES", 8)
        m.setattr(bus_input, "read", lambda *a: reads.append(a) or bus_input_read(*a))
        reread = _identify(monkeypatch, late_args, tmp_path / "late-s", piece=5)
    assert len(reads) == 1  # streamed until the late frame, then read whole
    _same(reread, reference)


def test_a_signal_mdf4_streams_a_free_run_and_k_step_predictions_to_the_whole_files_outputs(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    asammdf = pytest.importorskip("asammdf")
    import functools

    from pyrhonn.mdfsignals import SignalMdfStream

    path = tmp_path / "run.mf4"
    mdf = asammdf.MDF(version="4.10")
    t = 0.01 * np.arange(150)
    slow = t[::2]  # x2 every other grid sample: valid at every other one
    for name, times in (("x1", t), ("x2", slow), ("x3", t), ("x4", t), ("u", t)):
        mdf.append([asammdf.Signal(np.sin((2 + len(name)) * times + len(name)), times, name=name)], comment=name)
    mdf.save(str(path), overwrite=True)
    mdf.close()
    args = [str(path), "--config", "example1", "--free-run-from", "30", "--steps-ahead", "4", "--warmup", "3"]
    whole = _identify(monkeypatch, args, tmp_path / "whole", whole=True)
    for block, rows in ((1, 1), (7, 5), (64, 29)):
        with monkeypatch.context() as m:
            m.setattr(identify_cli, "SignalMdfStream", functools.partial(SignalMdfStream, block=block, hold=5))
            m.setattr(identify_cli, "CHUNK_ROWS", rows)
            _same(_identify(monkeypatch, args, tmp_path / f"s{block}"), whole)
