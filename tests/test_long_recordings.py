"""A recording of any length is read, identified and written a chunk at a time: the results do not depend
on where the chunks fall (a gap across a chunk boundary included) and are the whole-record ones, bit for
bit; the reader names a defect's line wherever it falls; the gaps, the metrics and the plots' envelope
are kept as running figures that equal the whole record's."""
from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
from figure_capture import capture_figures
from hypothesis import given, settings
from hypothesis import strategies as st

from pyrhonn import Identifier
from pyrhonn.cli import identify as identify_cli
from pyrhonn.cli import main
from pyrhonn.configfile import load_shipped, shipped_text
from pyrhonn.datafile import DataReader, concatenate, read_data
from pyrhonn.envelope import Envelope
from pyrhonn.gaps import SegmentTracker, segments_of, simulate_segments
from pyrhonn.metrics import absolute_deviation
from pyrhonn.simulation import scores
from pyrhonn.streamscores import RunningScores

STATES = ("q_m", "v", "lambda_a", "lambda_b", "i_a", "i_b")
N = 240
LOST = (30, 31, 32, 77, 79, 150)  # a run of three, two gaps one sample apart, a single one
DROPOUT = {(40, 1), (41, 1), (151, 0), (200, 5)}  # (sample, state): not valid, cell empty


def _record(path: Path, n: int = N) -> Path:
    """A record of the LIM config's states and inputs: a time column, validity columns, lost samples."""
    k = np.arange(n)[:, None]
    X = np.hstack([np.sin(k * w) * a for w, a in ((0.05, 1.0), (0.03, 2.0), (0.11, 1.0), (0.07, 1.0),
                                                  (0.13, 20.0), (0.17, 20.0))])
    U = np.hstack([np.sin(k * 0.2) * 150.0, np.cos(k * 0.2) * 150.0])
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["t", *STATES, "u_a", "u_b", *(f"{s}_valid" for s in STATES), "lost"])
        for i in range(n):
            if i in LOST:
                w.writerow([repr(i * 3e-4)] + [""] * 8 + ["0"] * 6 + ["1"])
                continue
            ok = [(i, j) not in DROPOUT for j in range(6)]
            w.writerow([repr(i * 3e-4)] + [repr(float(X[i, j])) if ok[j] else "" for j in range(6)]
                       + [repr(float(u)) for u in U[i]] + [str(int(f)) for f in ok] + ["0"])
    return path


@pytest.fixture(scope="module")
def record(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    d = tmp_path_factory.mktemp("long")
    (d / "lim.toml").write_text(shipped_text("firmware-lim"))
    return _record(d / "rec.csv"), d / "lim.toml"


@pytest.mark.parametrize("block", [1, 97, 1000])
def test_chunks_of_any_size_read_as_the_whole_file(record: tuple[Path, Path], block: int) -> None:
    data, _ = record
    cf = load_shipped("firmware-lim")
    whole = read_data(data, cf, allow_lost=True)
    reader = DataReader(data, cf, allow_lost=True, block_bytes=block)
    chunks = list(reader.chunks())
    assert len(chunks) > (1 if block < 1000 else 0) and reader.samples == N
    got = concatenate(chunks)
    for field in ("X", "U", "valid", "t", "lines", "lost"):
        assert np.array_equal(getattr(got, field), getattr(whole, field), equal_nan=True), field
    assert whole.lost is not None and list(np.flatnonzero(whole.lost)) == list(LOST)


def _edit(text: str, line: int, change) -> str:
    lines = text.split("\n")
    lines[line - 1] = change(lines[line - 1])
    return "\n".join(lines)


@pytest.mark.parametrize("block", [1, 50, 4000])
@pytest.mark.parametrize("line, change, message", [
    (150, lambda s: s + ",x", ": line 150: expected 16 fields as in the header, got 17"),
    (121, lambda s: s[:-1] + "2", ": line 121, column 'lost': expected 0 or 1, got '2'"),
    (201, lambda s: ",".join("abc" if i == 1 else p for i, p in enumerate(s.split(","))),
     ": line 201, column 'q_m': not a number: 'abc'"),
])
def test_a_defect_is_named_by_its_line_wherever_the_chunks_fall(record: tuple[Path, Path], tmp_path: Path,
                                                                block: int, line: int, change, message: str) -> None:
    data, _ = record
    bad = tmp_path / "bad.csv"
    bad.write_text(_edit(data.read_text(), line, change))
    cf = load_shipped("firmware-lim")
    with pytest.raises(ValueError) as whole:
        read_data(bad, cf, allow_lost=True)
    assert message in str(whole.value)
    with pytest.raises(ValueError) as chunked:
        list(DataReader(bad, cf, allow_lost=True, block_bytes=block).chunks())
    assert str(chunked.value) == str(whole.value)


def _identify(data: Path, config: Path, out: Path, *extra: str) -> tuple[bytes, dict]:
    assert main(["identify", str(data), "--config", str(config), "--out", str(out), "--no-plots", *extra]) == 0
    return (out / "predictions.csv").read_bytes(), json.loads((out / "metrics.json").read_text())


def test_identify_streams_to_the_whole_record_result_wherever_the_chunks_fall(
        record: tuple[Path, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Blocks of one line, of a few lines and the whole file: predictions.csv the same bytes, metrics.json the
    same; the predictions are those of the whole-record path (simulate_segments over read_data), bit for bit."""
    data, config = record
    runs = {}
    for block in (1, 333, 1 << 22):
        monkeypatch.setattr(identify_cli, "BLOCK_BYTES", block)
        runs[block] = _identify(data, config, tmp_path / f"o{block}")
    first = runs[1 << 22]
    assert all(r == first for r in runs.values())
    cf = load_shipped("firmware-lim")
    whole = read_data(data, cf, allow_lost=True)
    assert whole.lost is not None
    X, U = whole.in_dtype(cf.config.dtype, cf.state_names, cf.input_names, str(data))
    sim, _, _ = simulate_segments(Identifier(cf.config), X, U, whole.valid, segments_of(whole.lost))
    rows = list(csv.DictReader(first[0].decode().splitlines()))
    for j, name in enumerate(STATES):
        got = np.array([float(r[f"{name}_hat"]) if r[f"{name}_hat"] else np.nan for r in rows])
        assert np.array_equal(got, sim.one_step[:, j].astype(np.float64), equal_nan=True), name
    report = first[1]
    assert report["gaps"]["lost_samples"] == len(LOST) and report["gaps"]["gaps"] == 4
    assert report["samples"] == N


def test_the_gaps_found_chunk_by_chunk_are_the_whole_records() -> None:
    rng = np.random.default_rng(3)
    for _ in range(30):
        T = int(rng.integers(2, 80))
        lost = rng.random(T) < 0.3
        lost[0] = lost[-1] = False
        valid = rng.random((T, 2)) < 0.8
        lines = np.arange(2, T + 2)
        t = np.arange(T) * 0.5
        whole = segments_of(lost)
        tracker = SegmentTracker(("a", "b"))
        cuts = sorted({0, T, *(int(c) for c in rng.integers(0, T, 4))})
        stepped, starts = [], []
        for a, b in zip(cuts, cuts[1:]):
            s, f = tracker.feed(lost[a:b], valid[a:b], lines[a:b], t[a:b])
            stepped.append(s)
            starts.append(f)
        tracker.finish()
        assert np.array_equal(np.concatenate(stepped), whole.stepped)
        assert np.array_equal(np.concatenate(starts), whole.starts())
        assert tracker.report() == whole.report(t, lines, valid, ("a", "b"))


@settings(max_examples=25, deadline=None)
@given(st.integers(1, 300), st.lists(st.integers(1, 60), min_size=1, max_size=8), st.integers(1, 5))
def test_the_envelope_keeps_each_buckets_min_and_max_however_the_series_is_cut(T: int, cuts: list[int],
                                                                               buckets: int) -> None:
    rng = np.random.default_rng(T)
    x = np.cumsum(rng.random(T) + 0.1)
    v = rng.normal(size=(T, 2))
    v[rng.random((T, 2)) < 0.1] = np.nan
    flag = rng.random((T, 1)) < 0.2
    env = Envelope(2, flags=1, buckets=buckets)
    a = 0
    for c in cuts * (T // max(sum(cuts), 1) + 1):
        b = min(a + c, T)
        env.feed(x[a:b], v[a:b], flag[a:b])
        a = b
        if a == T:
            break
    env.feed(x[a:], v[a:], flag[a:])
    w = env.width
    assert env.samples == T and (T <= 2 * buckets) == (w == 1)
    xs, ys = env.line(0)
    heads = np.arange(0, T, w)
    with np.errstate(invalid="ignore"):
        lo = np.fmin.reduceat(v[:, 0], heads)
        hi = np.fmax.reduceat(v[:, 0], heads)
    if w == 1:
        assert np.array_equal(xs, x) and np.array_equal(ys, v[:, 0], equal_nan=True)
    else:
        assert np.array_equal(xs, np.repeat(x[heads], 2))
        assert np.array_equal(ys, np.column_stack([lo, hi]).ravel(), equal_nan=True)
    marked = np.logical_or.reduceat(flag[:, 0], heads)
    edges = np.flatnonzero(np.diff(np.r_[0, marked.astype(np.int8), 0]))
    ends = np.r_[x[heads], x[-1]]
    assert env.runs(0) == [(float(x[heads][p]), float(ends[q])) for p, q in zip(edges[::2], edges[1::2])]


def test_running_scores_equal_the_whole_records_and_do_not_depend_on_the_chunks() -> None:
    rng = np.random.default_rng(7)
    T, n = 5000, 3
    X = rng.normal(size=(T, n)) * 3 + 10
    est = X + rng.normal(size=(T, n)) * 0.1
    mask = rng.random((T, n)) < 0.9
    mask[:, 2] = False  # nothing scored
    want = scores(X, est, mask)
    results = []
    for cuts in ([T], [1, 7, 4000, 992], [2500, 2500]):
        with RunningScores(n, deviation=True) as run:
            a = 0
            for c in cuts:
                run.add(X[a:a + c], est[a:a + c], mask[a:a + c])
                a += c
            got = run.scores()
            dev = run.absolute_deviation()
        np.testing.assert_allclose(got.rmse[:2], want.rmse[:2], rtol=1e-12)
        np.testing.assert_allclose(got.rrse[:2], want.rrse[:2], rtol=1e-12)
        assert np.isnan(got.rmse[2]) and dev[2] is None
        assert list(got.scored) == list(want.scored)
        for j in range(2):
            rows = mask[:, j]
            assert dev[j] == pytest.approx(absolute_deviation(X[rows, j][:, None], est[rows, j][:, None])[0],
                                           rel=1e-12)
        results.append((list(got.rmse[:2]), list(got.rrse[:2]), dev))
    assert all(r == results[0] for r in results)


def test_a_long_record_is_plotted_as_its_envelope_and_says_so(record: tuple[Path, Path], tmp_path: Path,
                                                              monkeypatch: pytest.MonkeyPatch) -> None:
    data, config = record
    saved = capture_figures(monkeypatch, identify_cli)
    monkeypatch.setattr(identify_cli, "_envelope", lambda n: Envelope(5 * n, flags=n, buckets=16))
    assert main(["identify", str(data), "--config", str(config), "--out", str(tmp_path / "o")]) == 0
    top = saved["q_m"].axes[0]  # type: ignore[attr-defined]
    assert f"{N:,} samples: each stroke the min and max of 8" in top.get_title()
    assert len(top.lines[0].get_xdata()) == 2 * len(range(0, N, 8))


def test_select_on_a_long_record_fits_stated_windows_and_validates_on_every_row(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A record longer than --max-fit-rows fits on evenly spaced windows (printed, and in the JSON with why),
    read a chunk at a time; the structure found is then scored on every row, streamed."""
    from test_structure import DELAY, plant, write_csv

    X, U = plant(T=1200)
    data = tmp_path / "run.csv"
    write_csv(data, X, U)
    args = ["select", str(data), "--states", "x1,x2", "--inputs", "u1", "--search", "fixed", "--max-delay", "6",
            "--json", str(tmp_path / "sel.json")]
    assert main([*args, "--out", str(tmp_path / "sel.toml"), "--max-fit-rows", "400"]) == 0
    out = capsys.readouterr().out
    assert "1,200 rows, more than --max-fit-rows 400: fitted on 10 evenly spaced windows of 40 rows" in out
    report = json.loads((tmp_path / "sel.json").read_text())
    (long,) = report["long_records"]
    assert long["rows"] == 1200 and len(long["windows"]) == 10
    assert long["windows"][0] == [0, 39] and long["windows"][-1] == [1160, 1199]
    assert report["fit_rows"] == [f"{data} rows {a}..{b}" for a, b in long["windows"]]
    checked = long["validation"]
    assert checked["rows"] == 1200 and checked["from_sample"] == DELAY + 1
    for kind in ("one_step", "free_run"):  # noise-free data: the structure found reproduces the plant
        assert all(0 <= checked[kind][s]["rrse"] < 1e-6 for s in ("x1", "x2")), kind
    # the same file under the budget fits on every row, as before
    assert main([*args, "--out", str(tmp_path / "all.toml")]) == 0
    assert "long_records" not in json.loads((tmp_path / "sel.json").read_text())
