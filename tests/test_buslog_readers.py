"""Bus logs are read a block of frames at a time (candump lines, BLF containers, an MDF4's data frame columns
with numpy; python-can's readers for what those do not read) and decoded a message at a time: the same frames,
counts and refusals as python-can's readers frame by frame, and identify's outputs byte for byte the same as
with python-can's readers, cantools' decoding and the clock's samples counted a frame at a time."""
from __future__ import annotations

import io
import random
from pathlib import Path
from typing import Any, Iterator

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

can = pytest.importorskip("can")
pytest.importorskip("cantools")

from pyrhonn import buslog, buslogstream, framedecode  # noqa: E402
from pyrhonn.buslog import FrameBlock, _Log  # noqa: E402
from pyrhonn.candump import parse_block  # noqa: E402
from test_buslog_streaming import _same, identify, logs  # noqa: E402, F401


def _mixed(n: int, seed: int, errors: bool = True) -> list[Any]:
    """Frames of every kind: standard and extended ids, 0..8 bytes, CAN FD up to 64, remote and error frames."""
    rng = random.Random(seed)
    t = 1_700_000_000.0
    out = []
    for _ in range(n):
        t = round(t + rng.random() * 1e-3, 6)
        kind = rng.random()
        if errors and kind < 0.03:
            out.append(can.Message(timestamp=t, is_error_frame=True, arbitration_id=rng.randrange(0x800)))
        elif errors and kind < 0.06:
            out.append(can.Message(timestamp=t, arbitration_id=rng.randrange(0x800), is_remote_frame=True,
                                   dlc=rng.randrange(9)))
        elif kind < 0.3:
            size = rng.choice([0, 8, 12, 64])
            out.append(can.Message(timestamp=t, arbitration_id=rng.randrange(1 << 29), is_extended_id=True,
                                   is_fd=True, data=rng.randbytes(size)))
        else:
            out.append(can.Message(timestamp=t, arbitration_id=rng.randrange(0x800), data=rng.randbytes(rng.randrange(9))))
    return out


def _write(frames: list[Any], path: Path, container: int = 0) -> Path:
    writer = can.Logger(str(path))
    if container:
        writer.max_container_size = container
    with writer:
        for m in frames:
            writer.on_message_received(m)
    return path


def _read_both(path: Path, partial: bool = False) -> tuple[list[object], list[object]]:
    """(frames, records read, skipped, what is missing, the refusal) from the block readers and from python-can's
    reader frame by frame."""
    got = []
    for fast in (True, False):
        log = _Log(path, "--can-log", partial)
        try:
            parts = list(log._parts()) if fast else [FrameBlock.of(list(log.records()))]
            block = FrameBlock.join(parts) if parts else FrameBlock.of([])
            frames: object = (block.t.tolist(), block.ids.tolist(), block.extended.tolist(),
                              [block.data.row(i) for i in range(len(block))])
            refusal = None
        except ValueError as exc:
            frames, refusal = None, str(exc)
        got.append([frames, log.count, log.skipped, log.incomplete, refusal])
    return got[0], got[1]


@pytest.mark.parametrize("suffix", ["log", "blf", "asc", "mf4"])
def test_block_readers_give_python_cans_frames_in_every_format(tmp_path: Path, suffix: str) -> None:
    path = _write(_mixed(700, 1, errors=suffix != "mf4"), tmp_path / f"mixed.{suffix}", container=2048)
    fast, slow = _read_both(path)
    assert fast == slow
    assert fast[1] == 700 and fast[4] is None


def test_an_mdf4_with_error_frames_is_read_by_python_cans_reader_to_the_same_frames(tmp_path: Path) -> None:
    fast, slow = _read_both(_write(_mixed(300, 2), tmp_path / "errors.mf4"))
    assert fast == slow and fast[2] > 0


@settings(max_examples=25, deadline=None)
@given(cut=st.floats(0.02, 0.999), partial=st.booleans(), compressed=st.booleans())
def test_a_cut_blf_gives_python_cans_frames_count_and_refusal(tmp_path_factory: pytest.TempPathFactory,
                                                             cut: float, partial: bool, compressed: bool) -> None:
    d = tmp_path_factory.mktemp("blf")
    data = _blf(d / "whole.blf", compressed).read_bytes()
    (d / "cut.blf").write_bytes(data[:int(cut * len(data))])
    fast, slow = _read_both(d / "cut.blf", partial)
    assert fast == slow


def _blf(path: Path, compressed: bool) -> Path:
    writer = can.BLFWriter(str(path), compression_level=6 if compressed else 0)
    writer.max_container_size = 1024
    for m in _mixed(400, 3):
        writer.on_message_received(m)
    writer.stop()
    return path


@pytest.mark.parametrize("compressed", [False, True])
def test_a_damaged_blf_is_refused_after_python_cans_frames(tmp_path: Path, compressed: bool) -> None:
    data = _blf(tmp_path / "whole.blf", compressed).read_bytes()
    at = len(data) // 2
    (tmp_path / "damaged.blf").write_bytes(data[:at] + bytes(40) + data[at + 40:])
    fast, slow = _read_both(tmp_path / "damaged.blf")
    assert fast == slow and fast[4] is not None and "cannot read it as a BLF log" in fast[4]


LINES = st.one_of(
    st.tuples(st.integers(0, 10**6), st.integers(0, 999999), st.sampled_from(["vcan0", "can1", "x"]),
              st.one_of(st.integers(0, 0x7FF).map(lambda i: f"{i:03X}"),
                        st.integers(0, 0xFFFFFFFF).map(lambda i: f"{i:08x}")),
              st.sampled_from(["#", "##0", "##5"]), st.binary(max_size=12).map(lambda b: b.hex().upper()),
              st.sampled_from(["", " R", " T"]))
    .map(lambda p: f"({p[0]}.{p[1]:06d}) {p[2]} {p[3]}{p[4]}{p[5]}{p[6]}\n"),
    st.sampled_from(["\n", "  \n", "(1.5) can0 123#R\n", "(1.5) can0 123#ABC\n", "(2.0)\tcan0 123#00\n",
                     "(3.0) can0 123#0G\n"]))


@settings(max_examples=80, deadline=None)
@given(lines=st.lists(LINES, max_size=30))
def test_candump_blocks_parse_as_python_can_parses_them(lines: list[str]) -> None:
    text = "".join(lines)
    got = parse_block(text.encode())
    try:
        want = list(can.CanutilsLogReader(io.StringIO(text)))
    except Exception:  # noqa: BLE001 - python-can refuses a line: the block is left to it
        assert got is None
        return
    if got is None:  # a line it leaves to python-can (a remote frame, half a byte, a tab)
        assert any(x in text for x in ("#R", "#ABC", "\t", "#0G"))
        return
    data = [m for m in want if not m.is_error_frame]
    assert got.records == len(want) and got.errors == len(want) - len(data)
    assert got.t.tolist() == [m.timestamp for m in data]
    assert got.ids.tolist() == [m.arbitration_id for m in data]
    assert got.extended.tolist() == [m.is_extended_id for m in data]
    assert [got.data.row(i) for i in range(len(data))] == [bytes(m.data) for m in data]


@settings(max_examples=40, deadline=None)
@given(n=st.integers(1, 40), seconds=st.sampled_from([0, 7, 1_700_000_000, 9_007_199_254]),
       places=st.sampled_from([1, 6, 9]), ext=st.booleans(), size=st.sampled_from([0, 1, 8, 64]),
       fd=st.booleans(), odd=st.integers(0, 60), seed=st.integers(0, 1000))
def test_candump_lines_laid_out_alike_parse_as_python_can_parses_them(n: int, seconds: int, places: int, ext: bool,
                                                                     size: int, fd: bool, odd: int,
                                                                     seed: int) -> None:
    rng = random.Random(seed)
    lines = []
    for k in range(n):
        ident = f"{rng.randrange(1 << 32):08X}" if ext else f"{rng.randrange(0x800):03x}"
        stamp = f"{seconds + k}.{rng.randrange(10 ** places):0{places}d}"
        lines.append(f"({stamp}) can0 {ident}#{'#1' if fd else ''}{rng.randbytes(size).hex()}\n")
    if odd < n:  # one line of the same length laid out otherwise (or not a record)
        lines[odd] = lines[odd][:-3] + "\tZ\n"
    text = "".join(lines)
    got = parse_block(text.encode())
    try:
        want = [m for m in can.CanutilsLogReader(io.StringIO(text)) if not m.is_error_frame]
    except Exception:  # noqa: BLE001 - python-can refuses a line: the block is left to it
        assert got is None
        return
    assert got is not None
    assert got.t.tolist() == [m.timestamp for m in want]
    assert got.ids.tolist() == [m.arbitration_id for m in want]
    assert [got.data.row(i) for i in range(len(want))] == [bytes(m.data) for m in want]


def test_a_bad_candump_line_is_refused_naming_the_same_line(tmp_path: Path) -> None:
    lines = [f"({1.0 + k * 1e-3:.6f}) vcan0 100#{k % 256:02X}00\n" for k in range(3000)]
    lines[2500] = "(3.5) vcan0 100#00 garbage here\n"
    path = tmp_path / "bad.log"
    path.write_text("".join(lines))
    fast, slow = _read_both(path)
    assert fast == slow
    assert fast[4] is not None and ": line 2501: cannot read it as a candump log" in fast[4]


def _tick_on_frame_by_frame(tc: np.ndarray, T: float, last: float) -> tuple[list[float], np.ndarray, int]:
    tau: list[float] = []
    sample = np.zeros(tc.size, dtype=np.int64)
    inserted = 0
    base = last
    for i, c in enumerate(tc.tolist()):
        gap = c - base
        n = int(round(gap / T))
        if n > 0:
            tau.extend(base + j * gap / n for j in range(1, n))
            inserted += n - 1
            tau.append(c)
            base = c
        sample[i] = len(tau)
    return tau, sample, inserted


@settings(max_examples=60, deadline=None)
@given(steps=st.lists(st.sampled_from([1.0, 1.0, 1.0, 2.0, 3.02, 0.2, 0.45, 0.55, 7.5, 0.0]), max_size=80),
       jitter=st.floats(0, 0.05), stretch=st.sampled_from([1, 3, 1 << 14]))
def test_the_clocks_samples_are_those_counted_frame_by_frame(steps: list[float], jitter: float, stretch: int
                                                            ) -> None:
    T = 3e-4
    tc = 1_700_000_000.0 + np.cumsum(np.array(steps) * T * (1 + jitter))
    with pytest.MonkeyPatch.context() as m:
        m.setattr(buslog, "_TICK_STRETCH", stretch)
        got = buslog._tick_on(tc, T, 1_700_000_000.0)
    want = _tick_on_frame_by_frame(tc, T, 1_700_000_000.0)
    assert got[0] == want[0] and got[1].tolist() == want[1].tolist() and got[2] == want[2]


def _python_can_parts(self: _Log) -> Iterator[FrameBlock]:
    yield FrameBlock.of(list(self.records()))


@pytest.mark.parametrize("fmt", ["log", "asc", "blf", "mf4"])
def test_identify_writes_what_python_can_and_cantools_frame_by_frame_give(logs: dict[str, Path],  # noqa: F811
                                                                         identify: Any,  # noqa: F811
                                                                         monkeypatch: pytest.MonkeyPatch,
                                                                         fmt: str) -> None:
    fast = identify(logs[fmt], streamed=None)
    with monkeypatch.context() as m:
        m.setattr(_Log, "_parts", _python_can_parts)
        m.setattr(buslog, "decode_frames", framedecode.decode_each)
        m.setattr(buslog, "_tick_on", _tick_on_frame_by_frame)
        m.setattr(buslogstream, "_tick_on", _tick_on_frame_by_frame)
        slow = identify(logs[fmt], streamed=None)
    _same(fast, slow)
