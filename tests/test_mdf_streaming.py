"""A signal MDF4 read a block of records at a time gives what the whole read gives, bit for bit: the
grid, the resampled values and validity flags, the channels' report (the median intervals, found with
a bounded number of intervals held, and the default period) and, through ``pyrhonn identify``,
predictions.csv, samples.csv and metrics.json byte for byte, whatever the block and chunk sizes, with
channels on different rates, a slow one, one that starts late and one that ends early."""
from __future__ import annotations

import functools
from pathlib import Path
from typing import Any, Iterator, Sequence

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

asammdf = pytest.importorskip("asammdf")

from pyrhonn.cli import identify, main  # noqa: E402
from pyrhonn import mdfsignals  # noqa: E402
from pyrhonn.configfile import load_named  # noqa: E402
from pyrhonn.datafile import Data, write_data  # noqa: E402
from pyrhonn.mdfsignals import BLOCK_RECORDS, MEDIAN_HOLD, MdfSignals, SignalMdfStream, read_signal_mdf  # noqa: E402

STATES, INPUTS = ("x1", "x2", "x3", "x4"), ("u",)
CHANNELS = {"x3": "pos3"}


def _times(rng: np.random.Generator, start: float, interval: float, end: float, jitter: float) -> np.ndarray:
    steps = interval * (1 + jitter * rng.uniform(-1, 1, int((end - start) / interval) + 2))
    t = start + np.r_[0.0, np.cumsum(steps)]
    return t[t <= end]


@pytest.fixture(scope="module")
def mf4(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """x1 every 10 ms with jitter, x2 every 7 ms, pos3 slower than the period (25 ms), x4 starting late,
    u every 5 ms ending early: one channel group per time base."""
    rng = np.random.default_rng(7)
    bases = {"x1": (0.0, 0.01, 0.8, 0.3), "x2": (0.001, 0.007, 0.8, 0.0), "pos3": (0.0, 0.025, 0.8, 0.1),
             "x4": (0.043, 0.01, 0.8, 0.2), "u": (0.0, 0.005, 0.71, 0.05)}
    path = tmp_path_factory.mktemp("mdfs") / "run.mf4"
    mdf = asammdf.MDF(version="4.10")
    for name, (start, interval, end, jitter) in bases.items():
        t = _times(rng, start, interval, end, jitter)
        values = np.sin((1 + len(name)) * t) + 0.1 * rng.standard_normal(t.size)
        mdf.append([asammdf.Signal(values.astype(np.float32 if name == "x2" else np.float64), t, name=name,
                                   unit="m" if name != "u" else "V")], comment=name)
    mdf.save(str(path), overwrite=True)
    mdf.close()
    return path


def _joined(parts: Iterator[tuple[np.ndarray, ...]]) -> tuple[np.ndarray, ...]:
    pieces = list(parts)
    return tuple(np.concatenate([p[i] for p in pieces]) for i in range(4))


@pytest.mark.parametrize("block,rows,hold", [(1, 1, 3), (2, 5, 40), (7, 3, 1), (BLOCK_RECORDS, 1 << 16, MEDIAN_HOLD)])
def test_the_streamed_grid_is_the_whole_reads_bit_for_bit(mf4: Path, block: int, rows: int, hold: int) -> None:
    whole = read_signal_mdf(mf4, STATES, INPUTS, channels=CHANNELS)
    stream = SignalMdfStream(mf4, STATES, INPUTS, channels=CHANNELS, block=block, hold=hold)
    assert stream.period == whole.period and stream.samples == whole.t.shape[0]
    t, X, valid, U = _joined(stream.chunks(rows))
    assert t.tobytes() == whole.t.tobytes() and X.tobytes() == whole.X.tobytes()
    assert valid.tobytes() == whole.valid.tobytes() and U.tobytes() == whole.U.tobytes()
    assert stream.report() == whole.report() and stream.units == whole.units
    # the fixture has what it claims: a slow channel not valid at some points, a late start, an early end
    assert whole.channels["x3"]["not_valid"] > 0 and whole.t[0] >= 0.043 and whole.t[-1] <= 0.71


def test_a_given_period_and_a_held_input_stream_as_read_whole(mf4: Path) -> None:
    whole = read_signal_mdf(mf4, STATES, INPUTS, channels=CHANNELS, period=0.003)
    stream = SignalMdfStream(mf4, STATES, INPUTS, channels=CHANNELS, period=0.003, block=7)
    t, X, valid, U = _joined(stream.chunks(11))
    assert X.tobytes() == whole.X.tobytes() and U.tobytes() == whole.U.tobytes()
    assert stream.report() == whole.report() and whole.channels["u"]["held"] > 0


def test_a_non_finite_value_is_refused_naming_the_channel_and_time(tmp_path: Path) -> None:
    path = tmp_path / "nan.mf4"
    mdf = asammdf.MDF(version="4.10")
    t = np.arange(50) * 0.01
    for name in (*STATES, *INPUTS):
        v = np.sin(t)
        if name == "x2":
            v[30] = np.nan
        mdf.append([asammdf.Signal(v, t, name=name)], comment=name)
    mdf.save(str(path), overwrite=True)
    mdf.close()
    with pytest.raises(ValueError) as whole:
        read_signal_mdf(path, STATES, INPUTS)
    stream = SignalMdfStream(path, STATES, INPUTS, block=4)
    with pytest.raises(ValueError) as streamed:
        list(stream.chunks(8))
    assert str(streamed.value) == str(whole.value) and "channel 'x2': value at 0.3 s is not finite" in str(whole.value)


def test_time_stamps_out_of_order_in_a_later_block_are_refused(tmp_path: Path) -> None:
    path = tmp_path / "back.mf4"
    mdf = asammdf.MDF(version="4.10")
    t = np.arange(40) * 0.01
    for name in (*STATES, *INPUTS):
        ts = t.copy()
        if name == "x4":
            ts[20] = ts[18]
        mdf.append([asammdf.Signal(np.cos(t), ts, name=name)], comment=name)
    mdf.save(str(path), overwrite=True)
    mdf.close()
    for block in (1, 3, 20):
        with pytest.raises(ValueError, match="channel 'x4': its time stamps must be finite and increasing"):
            SignalMdfStream(path, STATES, INPUTS, block=block)


def _data(m: MdfSignals) -> Data:
    return Data(X=m.X, U=m.U, valid=m.valid, t=m.t, lines=np.arange(2, m.t.shape[0] + 2, dtype=np.int64),
                ignored=(), units=m.units)


class _Whole:
    """The reference: the record read whole (:func:`read_signal_mdf`), then cut into chunks as identify fed
    it before it streamed."""

    def __init__(self, path: Path, states: Sequence[str], inputs: Sequence[str], **options: Any) -> None:
        self.whole = read_signal_mdf(path, states, inputs, **options)
        self.units, self.channels, self.report = self.whole.units, self.whole.channels, self.whole.report
        self.period, self.period_source, self.incomplete = (self.whole.period, self.whole.period_source,
                                                            self.whole.incomplete)


@pytest.fixture(scope="module")
def reference(mf4: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("whole") / "out"
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(identify, "SignalMdfStream", _Whole)
        mp.setattr(identify, "_mdf_chunks", lambda w: identify._pieces(_data(w.whole)))
        assert main(["identify", str(mf4), "--config", "example1", "--channel", "x3=pos3", "--out", str(out),
                     "--no-plots", "--warmup", "3"]) == 0
    return out


@pytest.mark.parametrize("block,rows", [(1, 1), (2, 2), (7, 7), (BLOCK_RECORDS, identify.CHUNK_ROWS)])
def test_identify_streams_a_signal_mdf4_to_the_whole_reads_outputs_byte_for_byte(
        mf4: Path, reference: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, block: int, rows: int) -> None:
    monkeypatch.setattr(identify, "SignalMdfStream", functools.partial(SignalMdfStream, block=block, hold=5))
    monkeypatch.setattr(identify, "CHUNK_ROWS", rows)
    out = tmp_path / "out"
    assert main(["identify", str(mf4), "--config", "example1", "--channel", "x3=pos3", "--out", str(out),
                 "--no-plots", "--warmup", "3"]) == 0
    for name in ("predictions.csv", "samples.csv", "metrics.json"):
        assert (out / name).read_bytes() == (reference / name).read_bytes(), name


def test_the_streamed_samples_csv_is_the_whole_records_data_file(mf4: Path, reference: Path, tmp_path: Path) -> None:
    write_data(tmp_path / "whole.csv", _data(read_signal_mdf(mf4, STATES, INPUTS, channels=CHANNELS)),
               load_named("example1"))
    assert (reference / "samples.csv").read_bytes() == (tmp_path / "whole.csv").read_bytes()


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(min_value=1e-9, max_value=1e3), min_size=1, max_size=60), st.integers(1, 70),
       st.integers(1, 9), st.data())
def test_an_order_statistic_found_holding_few_intervals_is_the_sorted_ones(
        values: list[float], hold: int, block: int, data: st.DataObject) -> None:
    d = np.array(values)
    k = data.draw(st.integers(0, d.size - 1))
    assert mdfsignals._kth(lambda: iter(np.array_split(d, block)), k, hold) == np.sort(d)[k]


def _peak_while_streamed(tmp_path: Path, samples: int) -> int:
    """The most memory (bytes, Python's allocations) the stream holds opening and reading ``samples`` samples
    (in data blocks of 16 KiB) a block of 1,024 records and a chunk of 1,024 grid points at a time, intervals held
    at most 8,192."""
    import tracemalloc

    path = tmp_path / f"n{samples}.mf4"
    t = 0.01 * np.arange(samples)
    mdf = asammdf.MDF(version="4.10")
    mdf.append([asammdf.Signal(np.sin(t * (j + 1)), t, name=name) for j, name in enumerate(STATES)], comment="x")
    mdf.append([asammdf.Signal(np.cos(t), t, name="u")], comment="u")
    mdf.configure(write_fragment_size=1 << 14)  # data blocks of 16 KiB, as a logger writes them: asammdf reads
    mdf.save(str(path), overwrite=True)         # the blocks a range of records is in
    mdf.close()
    tracemalloc.start()
    try:
        stream = SignalMdfStream(path, STATES, INPUTS, block=1024, hold=8192)
        rows = sum(c[0].shape[0] for c in stream.chunks(1024))
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert rows == samples
    return peak


def test_the_memory_a_streamed_signal_mdf4_holds_does_not_grow_with_its_length(tmp_path: Path) -> None:
    short, long = _peak_while_streamed(tmp_path, 4_000), _peak_while_streamed(tmp_path, 24_000)
    # read whole, the grid's arrays alone (t, X, valid, U) take 52 bytes a sample, a channel's samples 16
    assert long < short + 8 * 20_000, (short, long)
