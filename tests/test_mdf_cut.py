"""An MDF4 cut short (its blocks reach past its end) is refused, saying whether ``--partial-log`` reads part
of it; with ``--partial-log`` a signal MDF4 or an MDF4 bus log is read up to the last complete record of
each channel group whose channel blocks are before the cut: exactly the whole file's first samples or
frames, wherever the cut falls, compressed or not, the missing part named. A cut that leaves no channel
group (asammdf and python-can write the channel blocks after the data) is refused saying so."""
from __future__ import annotations

import json
import struct
from pathlib import Path
from typing import Callable

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

asammdf = pytest.importorskip("asammdf")
can = pytest.importorskip("can")

from pyrhonn import mdfrepair  # noqa: E402
from pyrhonn.buslog import read_frames  # noqa: E402
from pyrhonn.cli import main  # noqa: E402
from pyrhonn.configfile import shipped_text  # noqa: E402
from pyrhonn.mdfsignals import SignalMdfStream, read_signal_mdf  # noqa: E402
from test_cli_identify_canlog import BUS, DBC, _recording  # noqa: E402

_HEAD = struct.Struct("<4s4xQQ")
_LEAF = {b"DT", b"DZ", b"SD"}
STATES, INPUTS, CHANNELS = ["x1", "x2"], ["u"], {"x2": "pos2"}
NOTHING = "nothing in it can be read, not even with --partial-log"


def _blocks(raw: bytes) -> dict[int, tuple[bytes, int, tuple[int, ...]]]:
    found: dict[int, tuple[bytes, int, tuple[int, ...]]] = {}
    todo = [64]
    while todo:
        at = todo.pop()
        if at not in found:
            ident, length, n = _HEAD.unpack_from(raw, at)
            found[at] = (ident[2:], length, struct.unpack_from(f"<{n}Q", raw, at + _HEAD.size))
            todo += [link for link in found[at][2] if link]
    return found


def _group_leaves(blocks: dict[int, tuple[bytes, int, tuple[int, ...]]], link: int) -> list[int]:
    """The data blocks of a data group's data link, in order (through its header list and data lists)."""
    kind, _, links = blocks[link]
    if kind == b"HL":
        return _group_leaves(blocks, links[0])
    if kind != b"DL":
        return [link]
    leaves: list[int] = []
    while link:
        leaves += [leaf for leaf in blocks[link][2][1:] if leaf]
        link = blocks[link][2][0]
    return leaves


def streamed_layout(raw: bytes, lists_after: bool = False) -> bytes:
    """The same MDF4 laid out as a streaming recorder writes it: the header and channel metadata first, then
    the data blocks of the channel groups interleaved as they would arrive; the data lists with the
    metadata (written ahead), or each right after its last block (``lists_after``: written once full)."""
    blocks = _blocks(raw)
    queues = [_group_leaves(blocks, links[2]) for _, (kind, _, links) in sorted(blocks.items())
              if kind == b"DG" and links[2]]
    last_of = {links[-1]: at for at, (kind, _, links) in blocks.items() if kind == b"DL" and lists_after}
    order = [at for at in sorted(blocks) if blocks[at][0] not in _LEAF and at not in last_of.values()]
    while any(queues):
        for queue in queues:
            if queue:
                order.append(queue.pop(0))
                order += [last_of[order[-1]]] if order[-1] in last_of else []
    order += [at for at in sorted(blocks) if at not in set(order)]  # any other data (signal data blocks)
    moved, pos = {}, 64
    for at in order:
        moved[at], pos = pos, pos + (blocks[at][1] + 7) // 8 * 8
    out = bytearray(raw[:64]) + bytearray(pos - 64)
    for at in order:
        _, length, links = blocks[at]
        block = bytearray(raw[at:at + length])
        struct.pack_into(f"<{len(links)}Q", block, _HEAD.size, *[moved[link] if link else 0 for link in links])
        out[moved[at]:moved[at] + length] = block
    return bytes(out)


def chained_lists(raw: bytes, per: int = 3) -> bytes:
    """The same MDF4 with each data list cut into a chain of data lists of ``per`` blocks (appended to it; what
    linked the list links the first of the chain)."""
    blocks = _blocks(raw)
    out = bytearray(raw)
    for at, (kind, _, links) in sorted(blocks.items()):
        if kind != b"DL" or links[0]:
            continue
        leaves = [leaf for leaf in links[1:] if leaf]
        sizes = [struct.unpack_from("<Q", raw, leaf + _HEAD.size + 8)[0] if blocks[leaf][0] == b"DZ"
                 else blocks[leaf][1] - _HEAD.size for leaf in leaves]
        offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(int).tolist()
        following = 0
        for start in reversed(range(0, len(leaves), per)):
            chunk = leaves[start:start + per]
            body = (struct.pack(f"<{len(chunk) + 1}Q", following, *chunk) + struct.pack("<B3xI", 0, len(chunk))
                    + struct.pack(f"<{len(chunk)}Q", *offsets[start:start + len(chunk)]))
            out += bytes(-len(out) % 8)
            following = len(out)
            out += _HEAD.pack(b"##DL", _HEAD.size + len(body), len(chunk) + 1) + body
        for holder, (_, _, holder_links) in blocks.items():
            for i, link in enumerate(holder_links):
                if link == at:
                    struct.pack_into("<Q", out, holder + _HEAD.size + 8 * i, following)
    return bytes(out)


def _signal_mdf(path: Path, compression: int) -> Path:
    """x1, x3, x4 and u every 10 ms, pos2 every 20 ms (float32), in small data blocks (several per channel
    group)."""
    mdf = asammdf.MDF(version="4.10")
    mdf.configure(write_fragment_size=2048)
    t = np.arange(400) * 0.01
    mdf.append([asammdf.Signal(w * np.sin(w * t), t, name=name) for w, name in ((1.0, "x1"), (0.7, "x3"), (2.1, "x4"))]
               + [asammdf.Signal(0.5 * np.cos(t), t, name="u", unit="V")], comment="fast")
    t2 = np.arange(200) * 0.02
    mdf.append([asammdf.Signal(np.cos(1.3 * t2).astype(np.float32), t2, name="pos2", unit="rad")], comment="slow")
    mdf.save(str(path), overwrite=True, compression=compression)
    mdf.close()
    return path


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("cut")
    out: dict[str, Path] = {}
    for compression in (0, 2):  # plain data blocks, and compressed (transposed, deflated) ones
        saved = _signal_mdf(d / f"saved{compression}.mf4", compression)
        out[f"saved{compression}"] = saved
        out[f"signal{compression}"] = d / f"signal{compression}.mf4"
        out[f"signal{compression}"].write_bytes(streamed_layout(saved.read_bytes()))
        out[f"signal{compression}-chained"] = d / f"signal{compression}-chained.mf4"
        out[f"signal{compression}-chained"].write_bytes(streamed_layout(chained_lists(saved.read_bytes()),
                                                                        lists_after=True))
        with can.io.MF4Writer(str(d / f"logged{compression}.mf4"), compression_level=compression) as writer:
            for m in _recording().frames:
                writer.on_message_received(m)
        out[f"logged{compression}"] = d / f"logged{compression}.mf4"
    for compression in (0, 2):  # the same frames in small data blocks, as a recorder streams them
        with asammdf.MDF(str(out["logged0"])) as mdf:
            mdf.configure(write_fragment_size=2048)
            mdf.save(str(d / f"blocks{compression}.mf4"), overwrite=True, compression=compression)
        out[f"bus{compression}"] = d / f"bus{compression}.mf4"
        out[f"bus{compression}"].write_bytes(streamed_layout((d / f"blocks{compression}.mf4").read_bytes()))
        out[f"bus{compression}-chained"] = d / f"bus{compression}-chained.mf4"
        out[f"bus{compression}-chained"].write_bytes(streamed_layout(chained_lists(
            (d / f"blocks{compression}.mf4").read_bytes()), lists_after=True))
    (d / "plant.dbc").write_text(DBC)
    (d / "cfg.toml").write_text(shipped_text("example1") + BUS)
    out["dbc"], out["config"] = d / "plant.dbc", d / "cfg.toml"
    return out


def _cut(src: Path, at: int, folder: Path) -> Path:
    cut = folder / f"cut-{src.stem}-{at}.mf4"
    cut.write_bytes(src.read_bytes()[:at])
    return cut


def _no_copies_left(folder: Path) -> None:
    assert not list(folder.glob("pyrhonn-cut-*")), "a repaired copy was left behind"


@pytest.fixture
def temp(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """The folder repaired copies are written to (checked empty after each read)."""
    folder = tmp_path / "tmp"
    folder.mkdir()
    monkeypatch.setattr(mdfrepair.tempfile, "tempdir", str(folder))
    return folder


def across_cuts(test: Callable[..., None]) -> Callable[..., None]:
    """``test`` at cuts across the file (a ``fraction`` of its length: 10 %, 37 %, 90 % and as many more as
    hypothesis picks), of plain and of compressed data blocks (``compression`` 0 and 2), their data lists
    written ahead or each after its blocks, in a chain (``layout`` "" and "-chained")."""
    for cut in (0.9, 0.37, 0.1):
        test = example(fraction=cut).via(f"a cut at {cut:.0%}")(test)
    test = settings(max_examples=40, deadline=None)(given(fraction=st.floats(0.0, 1.0))(test))
    return pytest.mark.parametrize("layout", ["", "-chained"])(pytest.mark.parametrize("compression", [0, 2])(test))


@across_cuts
def test_a_cut_signal_mdf4_reads_the_whole_files_first_samples_or_says_why_not(
        files: dict[str, Path], tmp_path_factory: pytest.TempPathFactory, compression: int, layout: str,
        fraction: float) -> None:
    src = files[f"signal{compression}{layout}"]
    size = src.stat().st_size
    cut = _cut(src, int(fraction * (size - 1)), tmp_path_factory.mktemp("c"))
    whole = read_signal_mdf(src, STATES, INPUTS, channels=CHANNELS, period=0.01)
    try:
        part = read_signal_mdf(cut, STATES, INPUTS, channels=CHANNELS, period=0.01, partial=True)
    except ValueError as exc:
        text = str(exc)
        assert text.startswith(f"{cut}: ")
        assert (NOTHING in text or "at least two" in text or "do not overlap" in text
                or ("no channel" in text and "truncated: cut short" in text)), text
        return
    K = part.t.size
    assert 2 <= K <= whole.t.size
    np.testing.assert_array_equal(part.t, whole.t[:K])
    np.testing.assert_array_equal(part.X, whole.X[:K])
    np.testing.assert_array_equal(part.valid, whole.valid[:K])
    np.testing.assert_array_equal(part.U, whole.U[:K])
    if part.incomplete is None:  # only padding after the last block was cut
        assert K == whole.t.size
        return
    assert part.incomplete.startswith("cut short: its blocks reach byte ")
    assert f"the file has {cut.stat().st_size:,}" in part.incomplete
    assert part.report()["complete"] is False and part.report()["missing"] == part.incomplete


@across_cuts
def test_a_cut_mdf4_bus_log_reads_the_whole_logs_first_frames_or_says_why_not(
        files: dict[str, Path], tmp_path_factory: pytest.TempPathFactory, compression: int, layout: str,
        fraction: float) -> None:
    src = files[f"bus{compression}{layout}"]
    cut = _cut(src, int(fraction * (src.stat().st_size - 1)), tmp_path_factory.mktemp("c"))
    whole = read_frames(src)
    try:
        part = read_frames(cut, partial=True)
    except ValueError as exc:
        text = str(exc)
        assert text.startswith(f"--can-log {cut}: ")
        assert NOTHING in text or "no data frames" in text or "empty file" in text, text
        return
    n = part.t.size
    assert 1 <= n <= whole.t.size
    np.testing.assert_array_equal(part.t, whole.t[:n])
    np.testing.assert_array_equal(part.ids, whole.ids[:n])
    assert part.data.rows() == whole.data.rows()[:n]
    if part.incomplete is None:  # only padding after the last block was cut
        assert n == whole.t.size
        return
    assert part.incomplete.startswith("cut short: its blocks reach byte ")
    assert f"; {n:,} frames read" in part.incomplete


def test_a_cut_inside_a_data_block_keeps_its_whole_records_and_names_the_rest(files: dict[str, Path],
                                                                              tmp_path: Path, temp: Path) -> None:
    src = files["signal0"]
    cut = _cut(src, src.stat().st_size // 2, tmp_path)
    part = read_signal_mdf(cut, STATES, INPUTS, channels=CHANNELS, period=0.01, partial=True)
    assert part.incomplete is not None
    assert "read the first " in part.incomplete and " of its 400 records of channel group 1 (x1, x3, x4 ...)" in \
        part.incomplete and "records of channel group 2 (pos2)" in part.incomplete
    stream = SignalMdfStream(cut, STATES, INPUTS, channels=CHANNELS, period=0.01, partial=True, block=7)
    rows = np.concatenate([X for _, X, _, _ in stream.chunks(rows=13)])
    np.testing.assert_array_equal(rows, part.X)
    assert stream.incomplete == part.incomplete
    _no_copies_left(temp)


def test_without_partial_log_a_cut_mdf4_is_refused_saying_what_partial_log_would_read(
        files: dict[str, Path], tmp_path: Path, cli_error) -> None:
    cut = _cut(files["signal2"], files["signal2"].stat().st_size // 2, tmp_path)
    err = cli_error(["identify", str(cut), "--config", "example1", "--channel", "x2=pos2", "--no-plots",
                     "--out", str(tmp_path / "o")])
    assert f"{cut}: truncated: cut short: its blocks reach byte " in err
    assert "read what is there with --partial-log (it would read the first " in err
    bus = _cut(files["bus0"], files["bus0"].stat().st_size // 2, tmp_path)
    with pytest.raises(ValueError, match=r"truncated: cut short: .*read what is there with --partial-log "
                                         r"\(it would read the first [\d,]+ of its [\d,]+ records of channel group 1"):
        read_frames(bus)
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("kind", ["saved0", "saved2", "logged0", "logged2"])
def test_a_cut_before_the_channel_blocks_of_asammdf_and_python_can_files_is_refused_saying_why(
        files: dict[str, Path], tmp_path: Path, kind: str, temp: Path) -> None:
    src = files[kind]
    first_group = struct.unpack_from("<Q", src.read_bytes(), 64 + _HEAD.size)[0]  # the header's first link
    for fraction in (0.1, 0.37, 0.9):  # of the way to the channel blocks, which follow the data
        cut = _cut(src, int(fraction * first_group), tmp_path)
        with pytest.raises(ValueError) as exc:
            if kind.startswith("saved"):
                read_signal_mdf(cut, STATES, INPUTS, channels=CHANNELS, partial=True)
            else:
                read_frames(cut, partial=True)
        assert f"{cut}: truncated: cut short: its blocks reach byte " in str(exc.value)
        assert f"{NOTHING}: no channel group's blocks are whole before the cut" in str(exc.value)
        assert "asammdf's MDF.save and python-can's MF4 logger" in str(exc.value)
    _no_copies_left(temp)


def test_a_cut_among_the_last_channel_blocks_reads_the_groups_before_it(files: dict[str, Path], tmp_path: Path,
                                                                         temp: Path) -> None:
    """python-can writes three channel groups (data, error and remote frames), the last at the file's end:
    a cut there loses only the (empty) remote frame group; every data frame is read."""
    src = files["logged2"]
    cut = _cut(src, src.stat().st_size - 40, tmp_path)
    whole, part = read_frames(src), read_frames(cut, partial=True)
    np.testing.assert_array_equal(part.t, whole.t)
    assert part.data.rows() == whole.data.rows()
    assert part.incomplete is not None and "channel group 3 lost (its channel blocks are past the cut)" in \
        part.incomplete and f"{whole.t.size:,} records of channel group 1 (CAN_DataFrame" in part.incomplete
    _no_copies_left(temp)


def test_a_damaged_link_is_refused_not_repaired(files: dict[str, Path], tmp_path: Path) -> None:
    raw = bytearray(files["signal0"].read_bytes())
    struct.pack_into("<Q", raw, 64 + 24, 200)  # the header's first data group link into the middle of a block
    bad = tmp_path / "bad.mf4"
    bad.write_bytes(bytes(raw))
    with pytest.raises(ValueError, match=r"bad.mf4: damaged MDF4: no valid block at byte 200 .*; not read"):
        read_signal_mdf(bad, STATES, INPUTS, channels=CHANNELS, partial=True)


def test_identify_partial_log_reads_a_cut_signal_mdf4_and_a_cut_mdf4_bus_log(
        files: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str], temp: Path) -> None:
    signal = _cut(files["signal2"], files["signal2"].stat().st_size * 3 // 5, tmp_path)
    assert main(["identify", str(signal), "--config", "example1", "--channel", "x2=pos2", "--no-plots", "--warmup", "5",
                 "--partial-log", "--out", str(tmp_path / "sig"), "--sample-period", "0.01"]) == 0
    printed = capsys.readouterr().out
    assert f"warning: {signal} is incomplete, read partially (--partial-log): cut short:" in printed
    mdf = json.loads((tmp_path / "sig" / "metrics.json").read_text())["mdf"]
    assert mdf["complete"] is False and "records of channel group 1 (x1, x3, x4 ...)" in mdf["missing"]
    bus = _cut(files["bus2"], files["bus2"].stat().st_size * 4 // 5, tmp_path)  # in its data blocks
    assert main(["identify", "--can-log", str(bus), "--dbc", str(files["dbc"]), "--config", str(files["config"]),
                 "--out", str(tmp_path / "bus"), "--warmup", "5", "--no-plots", "--partial-log"]) == 0
    printed = capsys.readouterr().out
    assert f"warning: {bus} is incomplete, read partially (--partial-log): cut short:" in printed
    report = json.loads((tmp_path / "bus" / "metrics.json").read_text())
    assert "records of channel group 1 (CAN_DataFrame" in json.dumps(report)
    _no_copies_left(temp)


def test_the_recordings_pages_cut_mdf4_command_prints_the_warning_the_page_shows(files: dict[str, Path],
                                                                                   tmp_path: Path) -> None:
    """docs/recordings.md's command on a recording cut in its data blocks: it runs, and prints the page's
    warning (its figures aside, which depend on asammdf's block sizes)."""
    import re

    from docs_blocks import ROOT, blocks_by, code_blocks, commands, run

    src = files["signal2"]
    (tmp_path / "run.mf4").write_bytes(src.read_bytes()[:src.stat().st_size // 2])
    label = "test_mdf_cut.py::test_the_recordings_pages_cut_mdf4_command_prints_the_warning_the_page_shows"
    printed = "".join(run(["bash", "-ec", line], tmp_path, f"docs/recordings.md: `{line}`")
                      for body in blocks_by("docs/recordings.md", label) for line in commands(body))
    page = (ROOT / "docs" / "recordings.md").read_text(encoding="utf-8")
    shown = [body.strip() for lang, body, _, _ in code_blocks(page) if lang == "text" and "run.mf4 is incomplete" in body]
    assert len(shown) == 1, "docs/recordings.md shows no (or more than one) warning of a cut MDF4"
    warning = next(line for line in printed.splitlines() if line.startswith("warning: run.mf4 is incomplete"))
    figures = r"[\d,]+"
    pattern = "".join(figures if part[:1].isdigit() else re.escape(part) for part in re.split(r"([\d,]*\d)", shown[0]))
    assert re.fullmatch(pattern, warning), (shown[0], warning)


def test_an_unfinalised_recording_cut_short_names_both_and_reads_its_first_frames_and_samples(
        files: dict[str, Path], tmp_path: Path, temp: Path) -> None:
    """A streaming recorder's file says 'UnFinMF' until it stops, and may not have counted its records yet:
    cut short, both are named and the records are counted from the data."""
    for kind in ("bus2", "signal0"):
        raw = bytearray(files[kind].read_bytes()[:files[kind].stat().st_size * 4 // 5])
        raw[:8] = b"UnFinMF "
        for at, (block, _, links) in _blocks(files[kind].read_bytes()).items():
            if block == b"CG" and kind.startswith("bus"):  # its cycle count, never written
                struct.pack_into("<Q", raw, at + _HEAD.size + 8 * len(links) + 8, 0)
        cut = tmp_path / f"open-{kind}.mf4"
        cut.write_bytes(bytes(raw))
        if kind.startswith("bus"):
            whole, part = read_frames(files[kind]), read_frames(cut, partial=True)
            n = part.t.size
            assert 0 < n < whole.t.size and part.data.rows() == whole.data.rows()[:n]
            with pytest.raises(ValueError, match="truncated: its identification block says 'UnFinMF'"):
                read_frames(cut)
        else:
            signals = read_signal_mdf(cut, STATES, INPUTS, channels=CHANNELS, period=0.01, partial=True)
            full = read_signal_mdf(files[kind], STATES, INPUTS, channels=CHANNELS, period=0.01)
            np.testing.assert_array_equal(signals.X, full.X[:signals.t.size])
            part = signals
        assert part.incomplete is not None and part.incomplete.startswith("its identification block says 'UnFinMF'")
        assert "; cut short: its blocks reach byte " in part.incomplete
        assert ("(its channel group declares 0)" if kind.startswith("bus") else "; read the first ") in part.incomplete
    _no_copies_left(temp)


def test_a_compressed_block_declaring_more_than_deflate_gives_is_refused_before_anything_is_read(
        files: dict[str, Path], tmp_path: Path, temp: Path) -> None:
    raw = bytearray(files["signal2"].read_bytes())
    first = min(at for at, (kind, _, _) in _blocks(bytes(raw)).items() if kind == b"DZ")
    struct.pack_into("<Q", raw, first + _HEAD.size + 8, 1 << 50)  # its original (uncompressed) length
    cut = tmp_path / "huge.mf4"
    cut.write_bytes(bytes(raw[:len(raw) * 4 // 5]))
    with pytest.raises(ValueError, match=rf"huge.mf4: truncated: cut short: .*{NOTHING}: the compressed block at "
                                         rf"byte {first:,} declares 1,125,899,906,842,624 bytes from "):
        read_signal_mdf(cut, STATES, INPUTS, channels=CHANNELS, partial=True)
    _no_copies_left(temp)


def test_a_header_list_linking_itself_is_refused_as_damaged(files: dict[str, Path], tmp_path: Path) -> None:
    raw = bytearray(files["signal2"].read_bytes())
    hl = min(at for at, (kind, _, _) in _blocks(bytes(raw)).items() if kind == b"HL")
    struct.pack_into("<Q", raw, hl + _HEAD.size, hl)  # its first data list link: itself
    last = max(at for at, (kind, _, _) in _blocks(bytes(raw)).items() if kind == b"DZ")  # the last one still linked
    cut = tmp_path / "loop.mf4"
    cut.write_bytes(bytes(raw[:last + 30]))  # inside it: the file is cut short
    with pytest.raises(ValueError, match=rf"{NOTHING}: a header list links a 'HL' block at byte {hl:,}, not a data list"):
        read_signal_mdf(cut, STATES, INPUTS, channels=CHANNELS, partial=True)


def test_an_unsorted_data_group_cut_short_is_named_lost_and_the_other_groups_read(files: dict[str, Path],
                                                                                 tmp_path: Path, temp: Path) -> None:
    """A data group whose records of several channel groups interleave cannot be cut at a record: it is lost
    (here the first group made to link a second channel group), the other group is read."""
    src = files["signal0"]
    raw = bytearray(src.read_bytes())
    blocks = _blocks(bytes(raw))
    first, second = (at for at, (kind, _, _) in sorted(blocks.items()) if kind == b"DG")
    struct.pack_into("<Q", raw, blocks[first][2][1] + _HEAD.size, blocks[second][2][1])  # its channel group's next
    cut = tmp_path / "unsorted.mf4"
    cut.write_bytes(bytes(raw[:len(raw) // 2]))
    lost = "channel group 1 (x1, x3, x4 ...) lost (its records of several channel groups interleave (unsorted)"
    with pytest.raises(ValueError, match=r"no channel 'x1' for 'x1'.*; truncated: cut short: ") as exc:
        read_signal_mdf(cut, STATES, INPUTS, channels=CHANNELS, partial=True)
    assert lost in str(exc.value)
    part = read_signal_mdf(cut, ["x2"], [], channels=CHANNELS, period=0.02, partial=True)
    whole = read_signal_mdf(src, ["x2"], [], channels=CHANNELS, period=0.02)
    assert part.incomplete is not None and lost in part.incomplete and 2 <= part.t.size <= whole.t.size
    np.testing.assert_array_equal(part.X, whole.X[:part.t.size])
    _no_copies_left(temp)
