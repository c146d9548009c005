"""hil writes its logs as MDF4 (python-can's MF4 writer): the same frames as the
BLF log of the run, at the same times to about a microsecond, read back by
``hil`` itself (with the sidecar's frame count and checksum) and by asammdf as
a bus logging file; a cut-short MDF4 log is refused like the other formats."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

can = pytest.importorskip("can")
asammdf = pytest.importorskip("asammdf")

from hil.rig import read_log, write_log  # noqa: E402
from pyrhonn.cli import main as pyrhonn_main  # noqa: E402


@pytest.fixture(scope="module")
def run_logs(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """A 0.3 s virtual run recorded as BLF, and the same Recording written as MDF4."""
    folder = tmp_path_factory.mktemp("run")
    blf = folder / "run.blf"
    assert pyrhonn_main(["hil", "replay", "--transport", "virtual", "--duration", "0.3", "--log", str(blf)]) == 0
    mf4 = write_log(read_log(blf), folder / "run.mf4")
    return blf, mf4


def test_an_mdf4_log_holds_the_runs_frames_at_their_times(run_logs) -> None:
    blf, mf4 = run_logs
    a, b = read_log(blf), read_log(mf4)
    assert len(b.events) == len(a.events) > 1000
    assert [(d, m.arbitration_id, bytes(m.data)) for _, d, m in b.events] == \
        [(d, m.arbitration_id, bytes(m.data)) for _, d, m in a.events]
    ta = np.array([t for t, _, _ in a.events])
    tb = np.array([t for t, _, _ in b.events])
    assert np.max(np.abs(tb - ta)) < 2e-6


def test_asammdf_reads_the_log_as_a_bus_logging_file(run_logs) -> None:
    blf, mf4 = run_logs
    with asammdf.MDF(mf4) as mdf:
        ids = mdf.get("CAN_DataFrame.ID").samples
    frames = read_log(blf).events
    assert len(ids) == len(frames)
    assert sorted(int(i) & 0x1FFFFFFF for i in ids) == sorted(m.arbitration_id for _, _, m in frames)


def test_a_cut_short_mdf4_log_is_refused(run_logs, tmp_path, cli_error) -> None:
    _, mf4 = run_logs
    cut = tmp_path / "cut.mf4"
    data = mf4.read_bytes()
    cut.write_bytes(data[: len(data) // 2])
    Path(str(cut) + ".json").write_bytes(Path(str(mf4) + ".json").read_bytes())
    err = cli_error(["hil", "score", str(cut)])
    assert "cut.mf4: not a whole MDF4 file" in err


def test_a_log_of_another_format_is_refused_by_name(tmp_path, cli_error) -> None:
    err = cli_error(["hil", "replay", "--transport", "virtual", "--duration", "0.1", "--log", str(tmp_path / "r.mdf")])
    assert "expected a .blf, .asc or .mf4 file name" in err
