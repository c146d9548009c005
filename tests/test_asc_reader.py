"""ASC logs are read a block of lines at a time with numpy (python-can's reader for the blocks it does not
parse): the same frames, record counts and refusals as python-can's ASCReader frame by frame."""
from __future__ import annotations

import random
from pathlib import Path
from typing import Any, Iterator

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

can = pytest.importorskip("can")

from pyrhonn import buslog  # noqa: E402
from pyrhonn.asc import AscBlocks  # noqa: E402
from test_buslog_readers import _read_both, _write  # noqa: E402

_HEADER = "date Sat Nov 28 04:30:00.000 am 2026\nbase hex  timestamps absolute\ninternal events logged\n"


def _classic(n: int, seed: int) -> list[Any]:
    """Frames: standard and extended ids, 0..8 bytes, CAN FD frames of 0..64 bytes, remote and error frames."""
    rng = random.Random(seed)
    t, out = 0.0, []
    for _ in range(n):
        t = round(t + rng.random() * 1e-3, 6)
        kind = rng.random()
        if kind < 0.05:
            out.append(can.Message(timestamp=t, is_error_frame=True, arbitration_id=rng.randrange(0x800)))
        elif kind < 0.1:
            out.append(can.Message(timestamp=t, arbitration_id=rng.randrange(0x800), is_remote_frame=True,
                                   dlc=rng.randrange(9)))
        elif kind < 0.3:
            out.append(can.Message(timestamp=t, arbitration_id=rng.randrange(1 << 29), is_extended_id=True,
                                   is_fd=True, bitrate_switch=rng.random() < 0.5,
                                   data=rng.randbytes(rng.choice([0, 1, 8, 12, 20, 64]))))
        else:
            ext = rng.random() < 0.3
            out.append(can.Message(timestamp=t, arbitration_id=rng.randrange(1 << 29 if ext else 0x800),
                                   is_extended_id=ext, data=rng.randbytes(rng.randrange(9))))
    return out


def _small_blocks(monkeypatch: pytest.MonkeyPatch) -> None:
    """Text logs read in blocks of about 200 bytes (so that a log spans many blocks, its header too)."""
    blocks = buslog._WholeLines.blocks

    def small(self: buslog._WholeLines, size: int = 1 << 20) -> Iterator[bytes]:
        return blocks(self, 200)

    monkeypatch.setattr(buslog._WholeLines, "blocks", small)


@pytest.mark.parametrize("small", [False, True])
def test_a_python_can_written_asc_log_gives_python_cans_frames_parsed_with_numpy(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, small: bool) -> None:
    path = _write(_classic(3000, 5), tmp_path / "x.asc")
    if small:
        _small_blocks(monkeypatch)
    fast, slow = _read_both(path)
    assert fast == slow
    assert slow[1] == 3000 and slow[2] > 0  # every record read, error and remote frames among them
    blocks = AscBlocks()
    body, records = blocks.parse(path.read_bytes())
    assert records is not None and records.records == 3000  # parsed by numpy, not handed to python-can


@pytest.mark.parametrize("cut", [0.5, 0.97])
@pytest.mark.parametrize("partial", [False, True])
def test_a_cut_asc_log_gives_python_cans_frames_and_refusal(tmp_path: Path, cut: float, partial: bool) -> None:
    text = _write(_classic(400, 9), tmp_path / "full.asc").read_bytes()
    path = tmp_path / "cut.asc"
    path.write_bytes(text[:int(len(text) * cut)])
    fast, slow = _read_both(path, partial)
    assert fast == slow
    assert slow[3] is not None  # the cut log is known incomplete


_HEXB = st.integers(0, 255).map(lambda b: f"{b:02X}")
_SEP = st.sampled_from([" ", " ", " ", "  ", "\t"])


@st.composite
def _frame_line(draw: st.DrawFn) -> str:
    t = f"{draw(st.integers(0, 10**7))}.{draw(st.integers(0, 999999)):06d}"
    ext = draw(st.booleans())
    ident = f"{draw(st.integers(0, (1 << 29) - 1 if ext else 0x7FF)):X}" + (draw(st.sampled_from(["x", "X"]))
                                                                            if ext else "")
    dlc = draw(st.integers(0, 15))
    n = draw(st.integers(0, 9))
    data = draw(_SEP).join(draw(st.lists(_HEXB, min_size=n, max_size=n)))
    tail = draw(st.sampled_from(["", "  Length = 227910 BitCount = 118 ID = 291x", " ", "\r"]))
    return f"{draw(st.sampled_from(['', '   ']))}{t} 1  {ident:<15} {draw(st.sampled_from(['Rx', 'Tx']))}   d {dlc:X} " \
           f"{data}{tail}"


@st.composite
def _fd_line(draw: st.DrawFn) -> str:
    t = f"{draw(st.integers(0, 10**7))}.{draw(st.integers(0, 999999)):06d}"
    ident = f"{draw(st.integers(0, (1 << 29) - 1)):X}" + draw(st.sampled_from(["", "x"]))
    length = draw(st.sampled_from([0, 1, 8, 12, 64]))
    n = draw(st.sampled_from([length, length, length + 1, max(length - 1, 0)]))
    data = " ".join(draw(st.lists(_HEXB, min_size=n, max_size=n)))
    tail = draw(st.sampled_from(["", "        0    0     3000        0", " 0"]))
    return f" {t} CANFD   1 {draw(st.sampled_from(['Rx', 'Tx']))}  {ident:>8}  {' ' * 32} {draw(st.integers(0, 1))} " \
           f"{draw(st.integers(0, 1))} {draw(st.integers(0, 15)):x} {length:>2} {data}{tail}"


_OTHER = st.sampled_from([
    "", "// a comment", "Begin TriggerBlock Sat Nov 28 04:30:00.000 am 2026", "End TriggerBlock",
    "   0.000000 Start of measurement", "   0.100000 1  123  Rx   r", "   0.100000 1  1234x  Tx   r 8",
    "   0.200000 1  ErrorFrame", "   0.200000 1  Statistic: D 0 R 0 XD 0 XR 0 E 0 O 0 B 0.00%",
    "   0.300000 CANFD   1 Rx      1ab                                   1 0 8  8 01 02 03 04 05 06 07 08"
    "        0        0   1000        0        0        0        0        0",
    "   0.300000 CANFD   1 Rx      1ab  Engine  1 0 8  8 01 02 03 04 05 06 07 08        0        0   1000",
    "   0.300000 CANFD   1 Tx      1abx   0 1 2  2 01 02", "   0.300000 CANFD   1 Tx      1abx   0 1 2  0",
    "   0.300000 CANFD   1 Tx      1abx   0 1 2  0        0        0   1000",
    "   0.300000 CANFD   1 Rx      ErrorFrame", "   0.300000 CANFD   x Rx      1ab   0 1 2  2 01 02  0",
    "   0.400000 1  12G  Rx   d 2 01 02", "   0.400000 1  123  Rx   d 2 01 1FF", "   0.5 1 7ff Rx d 8 01 02",
    "base dec", "\x0c   0.600000 1  123  Rx   d 1 05", "   0.700000 2  123  Rx   d 1 0x5",
])


@settings(max_examples=60, deadline=None)
@given(header=st.lists(st.sampled_from(["date Sat Nov 28 04:30:00 2026", "base hex  timestamps absolute",
                                        "base dec", "base HEX", "// note", "no internal events logged",
                                        "   1.000000 1  123  Rx   d 1 07"]), max_size=4),
       body=st.lists(st.one_of(_frame_line(), _fd_line(), _OTHER), max_size=40), small=st.booleans())
def test_random_asc_logs_give_python_cans_frames_counts_and_refusals(
        tmp_path_factory: pytest.TempPathFactory, header: list[str], body: list[str], small: bool) -> None:
    path = tmp_path_factory.mktemp("asc") / "r.asc"
    path.write_text("\n".join(header + body + ["End TriggerBlock"]) + "\n")
    with pytest.MonkeyPatch.context() as monkeypatch:
        if small:
            _small_blocks(monkeypatch)
        fast, slow = _read_both(path)
    assert fast == slow


def test_frame_lines_in_the_common_layout_are_parsed_without_python_can() -> None:
    lines = (_HEADER + "Begin TriggerBlock Sat Nov 28 04:30:00.000 am 2026\n   0.000000 Start of measurement\n"
             "   0.001000 1  123             Rx   d 8 01 02 03 04 05 06 07 08\n"
             "   0.002000 1  1ABCDEFx        Tx   d 2 0A FF  Length = 0\n   0.003000 1  ErrorFrame\n"
             "   0.004000 1  7FF             Rx   r\nEnd TriggerBlock\n").encode()
    body, records = AscBlocks().parse(lines)
    assert body.startswith(b"Begin TriggerBlock") and records is not None
    assert (records.records, records.errors) == (4, 2)
    assert records.t.tolist() == [0.001, 0.002] and records.ids.tolist() == [0x123, 0x1ABCDEF]
    assert records.extended.tolist() == [False, True]
    assert [records.data.row(i) for i in range(2)] == [bytes(range(1, 9)), b"\x0a\xff"]


def test_a_bad_asc_line_is_refused_after_the_same_frame(tmp_path: Path) -> None:
    path = tmp_path / "bad.asc"
    path.write_text(_HEADER + "".join(f"   {i / 1000:.6f} 1  123  Rx   d 1 {i % 256:02X}\n" for i in range(50))
                    + "   0.060000 1  12G  Rx   d 1 00\nEnd TriggerBlock\n")
    fast, slow = _read_both(path)
    assert fast == slow
    assert "after frame 50" in slow[4]
