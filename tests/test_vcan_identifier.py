"""hil replay of another identifier than the LIM over SocketCAN (vcan0, in the VM
tier): the small plant of the any-identifier tests (conftest.exported: selected,
exported with its DBC), replayed from its recording as that DBC's Measurement
frames against the Linux runner built for that config and DBC. Every estimate
bit-exact with the offline Identifier.run and frame for frame with the firmware
twin built for the DBC, every frame accounted for, injected losses included.
Skipped where there is no vcan0 (see conftest.vcan0).

The emulated VM compiles slowly (minutes for the runner and the twin), so `make test-vm` prepares
the identifier on the host first, as `make test-c` builds the LIM's runner there:

    python tests/test_vcan_identifier.py DIR

selects and exports it into DIR and builds its runner and twin into DIR/cache, a link to the cache
`hil replay` uses (where the host's any-identifier tests have built them already); the test inside the
VM then takes DIR from $PYRHONN_VM_IDENTIFIER. Without it, the test makes its own (slowly)."""
from __future__ import annotations

import os
import shlex
from pathlib import Path

import numpy as np
import pytest

can = pytest.importorskip("can")

from pyrhonn.cli import main as pyrhonn_main  # noqa: E402
from pyrhonn.firmware import FirmwareApp  # noqa: E402

from hil.rig import read_log  # noqa: E402
from hil.score import score  # noqa: E402

from docs_blocks import blocks_by, commands  # noqa: E402
from source_scripts import load_script  # noqa: E402

pytestmark = pytest.mark.vcan
FW = Path(__file__).resolve().parent.parent / "firmware_sim"


def prepare(folder: Path) -> dict[str, Path]:
    """The identifier in ``folder`` (conftest.exported's files), its runner and its twin built into
    ``folder/cache`` (reused when there)."""
    from conftest import write_two_state_plant

    folder.mkdir(parents=True, exist_ok=True)
    files = {"dir": folder, "config": folder / "cfg.toml", "dbc": folder / "id.dbc", "data": folder / "data.csv"}
    if not all(files[k].is_file() for k in ("config", "dbc", "data")):
        write_two_state_plant(files["data"])
        assert pyrhonn_main(["select", str(files["data"]), "--states", "y1,y2", "--inputs", "u",
                             "--input-max-delay", "3", "--dtype", "float32", "--out", str(files["config"])]) == 0
        assert pyrhonn_main(["export", "--config", str(files["config"]), "--data", str(files["data"]),
                             "--dbc", str(files["dbc"]), "--out", str(folder / "id.h")]) == 0
    files["runner"] = load_script(FW / "linux" / "build_runner.py", "_vcan_build_runner").cached_for(
        files["config"], files["dbc"], folder / "cache")
    files["twin"] = load_script(FW / "tools" / "build_twin.py", "_vcan_build_twin").protocol(files["dbc"],
                                                                                         folder / "cache")
    return files


@pytest.fixture(scope="module")
def identifier(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The prepared identifier of $PYRHONN_VM_IDENTIFIER, else one prepared here."""
    given = os.environ.get("PYRHONN_VM_IDENTIFIER")
    return prepare(Path(given) if given else tmp_path_factory.mktemp("identifier"))


def test_replay_of_another_identifier_over_vcan0_is_bit_exact_with_the_twin_and_accounted(
        vcan0: str, identifier: dict, tmp_path: Path) -> None:
    exported, twin = identifier, identifier["twin"]
    runner = identifier["runner"]
    log = tmp_path / "run.blf"
    # docs/hil-any-identifier.md's commands: the runner built by build_runner.py (as prepare() did, with the
    # page's very command run by test_hil_identifier), then the page's replay, 300 cycles (90 ms) with 2 % of
    # the frames lost, its files and runner where prepare() put them; the VM is emulated: a generous timeout
    # and drain
    [body] = blocks_by("docs/hil-any-identifier.md",
                       "test_vcan_identifier.py::test_replay_of_another_identifier_over_vcan0_is_bit_exact_with_the_twin_and_accounted")
    build, replay = commands(body)
    assert build.startswith("python firmware_sim/linux/build_runner.py --config cfg.toml --dbc id.dbc "), build
    given = {"cfg.toml": str(exported["config"]), "id.dbc": str(exported["dbc"]), "data.csv": str(exported["data"]),
             "vcan0": vcan0, "build/id-runner/rhonn_runner": str(runner)}
    argv = [given.get(word, word) for word in shlex.split(replay)]
    assert argv[:3] == ["pyrhonn", "hil", "replay"] and str(runner) in argv and vcan0 in argv, argv
    assert pyrhonn_main([*argv[1:], "--timeout", "10", "--drain", "3", "--quiet", "--log", str(log)]) == 0

    rec = read_log(log)
    assert rec.scenario.identifier == str(exported["config"]) and rec.scenario.state_names == ("y1", "y2")
    plan = rec.scenario.build()
    r = score(rec, reference=rec.scenario.reference_config())
    f = r["frames"]
    assert f["sent"] + f["lost_injected"] == 300 and f["lost_injected"] == int(plan.lost.sum()) > 0
    assert f["rejected_seq_jump"] == int(np.sum(plan.lost[:-1] & ~plan.lost[1:])) > 0
    assert f["missing"] == 0 and f["accounted"], f
    assert r["firmware"]["measurements"] == f["answered"] and r["firmware"]["rejected"] == f["rejected_seq_jump"]
    assert r["bit_exact"]["equal"] and r["bit_exact"]["checked"] == f["answered"]
    side = rec.meta["firmware_side"]
    assert side["returncode"] == 0 and side["stats"]["step_errors"] == 0

    # frame for frame: the twin built for the DBC, fed the Measurements that reached the bus, answers with
    # the very Estimates the runner sent
    app = FirmwareApp(None, rec.scenario.reference_config(), protocol=twin)
    meas_id, est_id = (twin.database.get_message_by_name(n).frame_id for n in ("Measurement", "Estimate"))
    sent = [m for _t, d, m in rec.events if d == "tx" and m.arbitration_id == meas_id]
    got = [bytes(m.data) for _t, d, m in rec.events if d == "rx" and m.arbitration_id == est_id]
    expected = [bytes(m.data) for msg in sent for m in app.handle(msg) if m.arbitration_id == est_id]
    assert len(got) == f["answered"] and got == expected


if __name__ == "__main__":
    import sys

    if len(sys.argv) != 2:
        raise SystemExit(f"usage: {sys.argv[0]} DIR (prepare the identifier of this test into DIR)")
    sys.path.insert(0, str(Path(__file__).resolve().parent))   # conftest's plant
    folder = Path(sys.argv[1])
    cache = load_script(FW / "linux" / "build_runner.py", "_vcan_build_runner").default_cache_dir().resolve()
    cache.mkdir(parents=True, exist_ok=True)
    folder.mkdir(parents=True, exist_ok=True)
    if not (folder / "cache").exists():
        (folder / "cache").symlink_to(cache, target_is_directory=True)
    print(prepare(folder)["runner"])
