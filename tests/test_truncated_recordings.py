"""A recording cut short is refused naming what is missing, or read in part with --partial-log (the
report says what is missing); every reader checks the sizes a file declares before it allocates."""
from __future__ import annotations

import io
import json
import zipfile
from pathlib import Path

import numpy as np
import pytest

can = pytest.importorskip("can")
cantools = pytest.importorskip("cantools")

from pyrhonn import Identifier  # noqa: E402
from pyrhonn.buslog import read_frames  # noqa: E402
from pyrhonn.cli import main  # noqa: E402
from pyrhonn.configfile import load_shipped, shipped_text  # noqa: E402
from pyrhonn.statefile import load_state, save_state  # noqa: E402

DBC = """VERSION ""

NS_ :

BS_:

BU_: PLANT

BO_ 256 Sample: 8 PLANT
 SG_ X1 : 0|16@1- (0.001,0) [-30|30] "" PLANT
 SG_ X2 : 16|16@1- (0.001,0) [-30|30] "" PLANT
 SG_ X3 : 32|16@1- (0.001,0) [-30|30] "" PLANT
 SG_ X4 : 48|16@1- (0.001,0) [-30|30] "" PLANT

BO_ 257 Command: 2 PLANT
 SG_ U : 0|16@1- (0.001,0) [-30|30] "" PLANT
"""
BUS = """
[bus]
sample_period = 0.01

[bus.signals]
x1 = "Sample.X1"
x2 = "Sample.X2"
x3 = "Sample.X3"
x4 = "Sample.X4"
u = "Command.U"
"""
K = 300


def _frames() -> list[can.Message]:
    db = cantools.database.load_string(DBC, database_format="dbc")
    sample, command = db.get_message_by_name("Sample"), db.get_message_by_name("Command")
    k = np.arange(K)
    x = np.stack([np.sin(0.05 * k), np.cos(0.05 * k), np.sin(0.02 * k), np.cos(0.03 * k)], axis=1)
    u = np.sign(np.sin(0.013 * k))
    out = []
    for i in range(K):
        out.append(can.Message(timestamp=1000.0 + 0.01 * i, arbitration_id=256, is_extended_id=False,
                               data=sample.encode({f"X{j + 1}": x[i, j] for j in range(4)})))
        out.append(can.Message(timestamp=1000.0 + 0.01 * i + 0.001, arbitration_id=257, is_extended_id=False,
                               data=command.encode({"U": u[i]})))
    return out


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("cut")
    out = {"dbc": d / "s.dbc", "config": d / "cfg.toml"}
    out["dbc"].write_text(DBC)
    out["config"].write_text(shipped_text("example1") + BUS)
    for suffix in ("asc", "log"):
        out[suffix] = d / f"run.{suffix}"
        with can.Logger(str(out[suffix])) as logger:
            for m in _frames():
                logger.on_message_received(m)
    out["mf4"] = d / "run.mf4"
    with can.Logger(str(out["mf4"])) as logger:
        for m in _frames():
            logger.on_message_received(m)
    out["blf"] = d / "run.blf"
    with can.BLFWriter(str(out["blf"]), max_container_size=2048) as writer:  # several containers
        for m in _frames():
            writer.on_message_received(m)
    return out


def _cut(src: Path, dst: Path, fraction: float) -> Path:
    raw = src.read_bytes()
    n = int(len(raw) * fraction)
    dst.write_bytes(raw[:n - 3 if raw[n - 1:n] == b"\n" else n])  # inside a line or an object
    return dst


def _identify(files: dict[str, Path], log: Path, out: Path, *extra: str) -> list[str]:
    return ["identify", "--can-log", str(log), "--dbc", str(files["dbc"]), "--config", str(files["config"]),
            "--out", str(out), "--no-plots", *extra]


@pytest.mark.parametrize("suffix, says", [
    ("asc", "does not end with 'End TriggerBlock'"),
    ("log", "is cut short (no end of line)"),
    ("blf", "cut inside its object"),
])
def test_a_log_cut_to_37_percent_is_refused_naming_what_is_missing_or_read_in_part(
        files: dict[str, Path], tmp_path: Path, suffix: str, says: str, cli_error,
        capsys: pytest.CaptureFixture[str]) -> None:
    cut = _cut(files[suffix], tmp_path / f"cut.{suffix}", 0.37)
    err = cli_error(_identify(files, cut, tmp_path / "refused"))
    assert f"--can-log {cut}: truncated: " in err and says in err and "--partial-log" in err
    assert not (tmp_path / "refused").exists()
    assert main(_identify(files, cut, tmp_path / "part", "--partial-log")) == 0
    printed = capsys.readouterr().out
    assert f"warning: {cut} is incomplete, read partially (--partial-log): " in printed
    report = json.loads((tmp_path / "part" / "metrics.json").read_text())
    assert report["bus"]["complete"] is False and says in report["bus"]["missing"]
    assert 0.2 * K < report["samples"] < 0.45 * K  # what was there, and no more
    whole = read_frames(files[suffix])
    assert whole.incomplete is None and whole.t.size == 2 * K


def test_a_blf_shorter_than_its_header_records_says_how_much_is_missing(files: dict[str, Path],
                                                                      tmp_path: Path) -> None:
    raw = files["blf"].read_bytes()
    # whole containers kept, the last ones gone: only the header's own size tells
    ends, pos = [], int.from_bytes(raw[4:8], "little")
    while pos < len(raw):
        size = int.from_bytes(raw[pos + 8:pos + 12], "little")
        pos += size + size % 4
        ends.append(pos)
    (tmp_path / "short.blf").write_bytes(raw[:ends[len(ends) // 2]])
    with pytest.raises(ValueError, match=r"truncated: its BLF header records [\d,]+ bytes, the file has [\d,]+ "
                                         r"\([\d.]+ % missing\)"):
        read_frames(tmp_path / "short.blf")
    part = read_frames(tmp_path / "short.blf", partial=True)
    assert 0 < part.t.size < 2 * K and "% missing" in (part.incomplete or "")


def test_a_blf_whose_header_was_never_completed_is_refused(files: dict[str, Path], tmp_path: Path) -> None:
    raw = bytearray(files["blf"].read_bytes())
    raw[16:24] = (144).to_bytes(8, "little")  # the size and object count the writer puts there at start
    raw[32:36] = (0).to_bytes(4, "little")
    (tmp_path / "open.blf").write_bytes(bytes(raw))
    with pytest.raises(ValueError, match="its header was never completed"):
        read_frames(tmp_path / "open.blf")
    assert read_frames(tmp_path / "open.blf", partial=True).t.size == 2 * K


def test_a_blf_container_declaring_a_huge_size_is_refused_before_decompressing(files: dict[str, Path],
                                                                              tmp_path: Path) -> None:
    raw = bytearray(files["blf"].read_bytes())
    first = int.from_bytes(raw[4:8], "little")  # the first object: a container
    raw[first + 16 + 8:first + 16 + 12] = (3_000_000_000).to_bytes(4, "little")
    (tmp_path / "big.blf").write_bytes(bytes(raw))
    for partial in (False, True):
        with pytest.raises(ValueError, match=r"object 1 \(a container, at byte 144\) declares 3,000,000,000 bytes "
                                             "uncompressed"):
            read_frames(tmp_path / "big.blf", partial=partial)


def test_an_mdf4_bus_log_cut_short_is_refused_naming_how_much_is_missing(files: dict[str, Path], tmp_path: Path,
                                                                        cli_error) -> None:
    assert read_frames(files["mf4"]).t.size == 2 * K
    cut = _cut(files["mf4"], tmp_path / "cut.mf4", 0.6)  # among the channel blocks, after the data frames' group
    err = cli_error(_identify(files, cut, tmp_path / "o"))
    assert f"--can-log {cut}: truncated: cut short: its blocks reach byte" in err
    assert "bytes missing); read what is there with --partial-log (it would read " in err
    assert "channel group 3 lost (its channel blocks are past the cut)" in err
    assert "Traceback" not in err and "Exception ignored" not in err
    assert read_frames(cut, partial=True).t.size == 2 * K
    early = _cut(files["mf4"], tmp_path / "early.mf4", 0.1)  # in the data, before every channel block
    for extra in ([], ["--partial-log"]):
        err = cli_error(_identify(files, early, tmp_path / "o", *extra))
        assert "nothing in it can be read, not even with --partial-log: no channel group" in err
        assert "Traceback" not in err and "Exception ignored" not in err


def test_a_binary_log_named_as_text_and_a_missing_log_are_named(files: dict[str, Path], tmp_path: Path) -> None:
    (tmp_path / "run.log").write_bytes(files["blf"].read_bytes())
    with pytest.raises(ValueError, match="binary data, not a candump log"):
        read_frames(tmp_path / "run.log")
    with pytest.raises(ValueError, match=r"no such file; did you mean '.*run\.asc'"):
        read_frames(files["asc"].with_name("rn.asc"))


def _npy_header(shape: tuple[int, ...], descr: str) -> bytes:
    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(buf, {"descr": descr, "fortran_order": False, "shape": shape})
    return buf.getvalue()


def _replace_member(src: Path, dst: Path, name: str, payload: bytes) -> None:
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w") as zout:
        for info in zin.infolist():
            zout.writestr(info.filename, payload if info.filename == f"{name}.npy" else zin.read(info))


@pytest.mark.parametrize("member, shape, descr, says", [
    ("w_0", (100_000_000_000,), "<f8", "declares shape (100000000000,) of float64"),
    ("p_1", (10**6, 10**6), "<f8", "declares shape (1000000, 1000000)"),
    ("header", (), "<U100000000", "declares shape () of <U100000000 (400,000,000 bytes), but the member holds"),
    ("header", (2,), "<i8", "expected a JSON object"),
])
def test_a_state_file_declaring_a_huge_member_is_refused_before_anything_is_allocated(
        tmp_path: Path, member: str, shape: tuple[int, ...], descr: str, says: str) -> None:
    save_state(Identifier(load_shipped("example1").config), tmp_path / "ok.npz")
    _replace_member(tmp_path / "ok.npz", tmp_path / "bad.npz", member, _npy_header(shape, descr) + b"\0" * 64)
    with pytest.raises(ValueError, match=f"{member}: ") as info:
        load_state(tmp_path / "bad.npz", Identifier)
    assert says in str(info.value)
