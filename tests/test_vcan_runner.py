"""The firmware's Linux runner on a real SocketCAN interface (vcan0, in the
VM tier): measurement frames sent over the bus come back as estimate frames
byte-identical to what the same firmware logic gives in Python
(pyrhonn.firmware.FirmwareApp), and the runner reports and exits cleanly on
SIGTERM. Skipped where there is no vcan0 (see conftest.vcan0)."""
from __future__ import annotations

import json
import signal
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest

can = pytest.importorskip("can")

from pyrhonn import firmware  # noqa: E402
from pyrhonn.configfile import load_shipped  # noqa: E402
from pyrhonn.firmware import FirmwareApp  # noqa: E402
from pyrhonn.plants import lim  # noqa: E402

pytestmark = pytest.mark.vcan
ESTIMATE_ID = firmware.database().get_message_by_name("Estimate").frame_id


def lim_config():
    return load_shipped("firmware-lim").config


def measurement_frames(n: int) -> list:
    traj = lim.simulate(dt=3e-4, horizon=2.4)
    k0 = int(round(2.0 / traj.dt))
    X, U, valid = traj.X_meas[k0:k0 + n].copy(), traj.U[k0:k0 + n], traj.valid[k0:k0 + n]
    X[~np.isfinite(X)] = 0.0
    return [firmware.measurement_message(t, X[t], U[t], valid[t]) for t in range(n)]


def test_runner_estimates_over_vcan_equal_the_python_firmware_twin(vcan0: str, runner: Path,
                                                                   tmp_path: Path) -> None:
    n = 300
    frames = measurement_frames(n)
    twin = FirmwareApp(None, lim_config())
    expected = []
    for msg in frames:
        expected += [bytes(m.data) for m in twin.handle(msg) if m.arbitration_id == ESTIMATE_ID]
    report = tmp_path / "runner.json"
    proc = subprocess.Popen([str(runner), "--interface", vcan0, "--duration", "600", "--json", str(report)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        with can.Bus(interface="socketcan", channel=vcan0, fd=True,
                     can_filters=[{"can_id": ESTIMATE_ID, "can_mask": 0x7FF}]) as bus:
            time.sleep(1.0)  # the runner binds its socket
            got: list[bytes] = []
            for msg in frames:
                bus.send(msg)
                time.sleep(0.002)
                while (reply := bus.recv(0.0)) is not None:
                    got.append(bytes(reply.data))
            deadline = time.monotonic() + 60.0
            while len(got) < len(expected) and time.monotonic() < deadline:
                reply = bus.recv(1.0)
                if reply is not None:
                    got.append(bytes(reply.data))
    finally:
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=60)
    assert proc.returncode == 0, err
    assert len(got) == n, f"{len(got)} estimates for {n} measurements"
    assert got == expected, "the runner's estimate frames differ from the Python twin's"
    stats = json.loads(report.read_text())
    assert stats["frames_in"] == n and stats["rejected"] == 0 and stats["step_errors"] == 0
    assert "wake-up" in out and "step" in out


def test_runner_counts_and_rejects_a_repeated_sequence_counter(vcan0: str, runner: Path, tmp_path: Path) -> None:
    frames = measurement_frames(3)
    report = tmp_path / "runner.json"
    proc = subprocess.Popen([str(runner), "--interface", vcan0, "--duration", "600", "--json", str(report)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        with can.Bus(interface="socketcan", channel=vcan0, fd=True) as bus:
            time.sleep(1.0)
            for msg in (frames[0], frames[1], frames[1], frames[2]):
                bus.send(msg)
                time.sleep(0.05)
            time.sleep(1.0)
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.communicate(timeout=60)
    stats = json.loads(report.read_text())
    assert stats["frames_in"] == 4 and stats["rejected"] == 1
