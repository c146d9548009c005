"""The Linux runner (firmware_sim/linux/rhonn_runner.c), built with the
command authentication on, over python-can's udp_multicast bus (no CAN
needed): a forged and a replayed Control are rejected, not answered and
reported in its statistics; an authenticated one is answered.
"""
from __future__ import annotations

import json
import shutil
import signal
import subprocess
import time
from pathlib import Path

import pytest
from source_scripts import load_script  # noqa: E402

can = pytest.importorskip("can")

from pyrhonn import firmware  # noqa: E402
from pyrhonn.firmware import SecOCSender  # noqa: E402

from hil.transport import UDP_GROUP, free_port  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
DB = firmware.database()
ACK = DB.get_message_by_name("ControlAck").frame_id


@pytest.fixture(scope="module")
def runner_exe(tmp_path_factory: pytest.TempPathFactory) -> Path:
    if shutil.which("cc") is None and shutil.which("gcc") is None:
        pytest.skip("no C compiler to build rhonn_runner")
    module = load_script(ROOT / "firmware_sim" / "linux" / "build_runner.py", "_build_runner_secoc")
    return module.cached(tmp_path_factory.getbasetemp() / "runner-cache")


def test_the_runner_rejects_forged_and_replayed_commands_and_reports_them(runner_exe, tmp_path) -> None:
    port = free_port()
    report = tmp_path / "runner.json"
    proc = subprocess.Popen([str(runner_exe), "--udp-multicast", f"{UDP_GROUP}:{port}", "--duration", "120",
                             "--json", str(report)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    line = proc.stdout.readline()
    assert line.startswith("rhonn_runner: listening on udp_multicast"), (line, proc.stderr.read())
    bus = can.Bus(interface="udp_multicast", channel=UDP_GROUP, port=port, receive_own_messages=False)
    tx = SecOCSender(firmware.TEST_KEY)
    acks: list[dict] = []

    def send_and_collect(msg: can.Message, wait: float, until_acks: int | None = None) -> None:
        bus.send(msg)
        end = time.monotonic() + wait
        while time.monotonic() < end and (until_acks is None or len(acks) < until_acks):
            r = bus.recv(0.05)
            if r is not None and r.arbitration_id == ACK:
                acks.append(DB.decode_message("ControlAck", bytes(r.data), decode_choices=False))

    try:
        forged = bytearray(firmware.control_message("Reset", 12, sender=tx).data)
        forged[-1] ^= 0x01
        send_and_collect(can.Message(arbitration_id=0x110, is_extended_id=False, data=bytes(forged), is_fd=True,
                                     bitrate_switch=True), 0.5)
        good = firmware.control_message("LearningOff", 11, sender=tx)
        send_and_collect(good, 20.0, until_acks=1)       # answered (on a busy machine, late)
        send_and_collect(good, 0.5)                      # replayed: not answered
    finally:
        bus.shutdown()
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=30)
    assert proc.returncode == 0, err
    assert [(a["Command"], a["Token"], a["Result"]) for a in acks] == [(2, 11, 0)]
    stats = json.loads(report.read_text())
    assert stats["rejected_auth"] == 1 and stats["rejected_freshness"] == 1
    assert stats["rejected"] == stats["rejected_auth"] + stats["rejected_freshness"]
    assert f"replayed or stale {stats['rejected_freshness']}" in out
