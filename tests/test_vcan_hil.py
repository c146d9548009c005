"""hil/ over SocketCAN (vcan0, in the VM tier) against firmware_sim's Linux
runner: the same scenario as on the host transports, only the channel
changes. Skipped where there is no vcan0 (see conftest.vcan0)."""
from __future__ import annotations

import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

can = pytest.importorskip("can")

from pyrhonn.cli import main as pyrhonn_main  # noqa: E402

from hil.scenario import Scenario  # noqa: E402
from hil.score import score  # noqa: E402
from hil.transport import lim_config, run_replay  # noqa: E402

pytestmark = pytest.mark.vcan


def test_replay_over_vcan0_against_the_runner_is_bit_exact_and_accounted(vcan0: str, runner: Path) -> None:
    sc = Scenario(duration=0.3, start=1.95, frame_loss=0.02, seed=21)  # the hold ends, the motor starts
    plan = sc.build()
    # the VM is emulated (slow): a generous reply timeout and drain
    rec = run_replay(sc, "socketcan", vcan0, runner=str(runner), reply_timeout=10.0, drain=3.0)
    r = score(rec, reference=lim_config())
    f = r["frames"]
    assert f["lost_injected"] == int(plan.lost.sum()) > 0
    assert f["rejected_seq_jump"] == int(np.sum(plan.lost[:-1] & ~plan.lost[1:]))
    assert f["missing"] == 0 and f["accounted"], f
    assert r["firmware"]["rejected"] == f["rejected_seq_jump"] and r["firmware"]["measurements"] == f["answered"]
    assert r["bit_exact"]["equal"] and r["bit_exact"]["checked"] == f["answered"]
    side = rec.meta["firmware_side"]
    assert side["returncode"] == 0
    assert side["stats"]["rejected"] == f["rejected_seq_jump"] and side["stats"]["step_errors"] == 0


def test_cli_replay_over_vcan0(vcan0: str, runner: Path, tmp_path: Path, capsys) -> None:
    out = Path(os.environ.get("PYRHONN_VM_OUT", tmp_path)) / "hil-vcan0"
    code = pyrhonn_main(["hil", "replay", "--transport", "socketcan", "--channel", vcan0, "--runner", str(runner),
                         "--duration", "0.3", "--start", "0.9", "--timeout", "10", "--drain", "3", "--out", str(out),
                         "--log", str(out / "run.blf")])
    text = capsys.readouterr().out
    print(text)
    assert code == 0, text
    assert "all accounted for" in text and "Identifier.run: equal" in text and "not meaningful" in text.lower()
    assert pyrhonn_main(["hil", "score", str(out / "run.blf")]) == 0


def test_a_full_replay_of_the_paper_scenario_over_vcan0_is_bit_exact_and_accounted(vcan0: str, runner: Path) -> None:
    # the whole default scenario (4 s, 13,333 cycles), with injected losses, against the C runner over vcan0
    sc = Scenario(frame_loss=0.005, seed=31)
    plan = sc.build()
    rec = run_replay(sc, "socketcan", vcan0, runner=str(runner), reply_timeout=10.0, drain=5.0)
    r = score(rec, reference=lim_config())
    f = r["frames"]
    assert f["lost_injected"] == int(plan.lost.sum()) > 20 and f["lost_unaccounted"] == 0
    assert f["rejected_seq_jump"] == int(np.sum(plan.lost[:-1] & ~plan.lost[1:]))
    assert f["missing"] == 0 and f["accounted"], f
    assert r["bit_exact"]["equal"] and r["bit_exact"]["checked"] == f["answered"] == f["sent"] - f["rejected_seq_jump"]


def _set_link(vcan0: str, state: str) -> None:
    subprocess.run(["ip", "link", "set", vcan0, state], check=True)


def test_interface_going_down_mid_run_is_a_clear_error_on_the_rig_side(vcan0: str, runner: Path) -> None:
    from hil.rig import BusLost

    sc = Scenario(duration=0.3, start=0.9, frame_loss=0.0, seed=5)
    # right after measurement frame 200 is sent, the interface goes down
    take_down = lambda k: (_set_link(vcan0, "down") or []) if k == 200 else []  # noqa: E731
    try:
        with pytest.raises(BusLost, match=r"went away while (sending|receiving)") as info:
            run_replay(sc, "socketcan", vcan0, runner=str(runner), reply_timeout=10.0, drain=1.0,
                       extra_frames=take_down)
    finally:
        _set_link(vcan0, "up")
    rec = info.value.recording
    sent = [m for _, d, m in rec.events if d == "tx" and m.arbitration_id == 0x100]
    assert len(sent) == 201 and "bus_lost" in rec.meta  # every frame up to the loss is kept


def test_interface_going_down_stops_the_runner_with_a_clear_message(vcan0: str, runner: Path) -> None:
    import time

    proc = subprocess.Popen([str(runner), "--interface", vcan0, "--duration", "600"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        time.sleep(1.0)
        _set_link(vcan0, "down")
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
        _set_link(vcan0, "up")
    assert proc.returncode == 1
    assert f"the CAN interface {vcan0} failed" in err
    assert "wake-up" in out  # the statistics are still printed
