"""firmware_sim's Linux runner: lost frames and who may talk to it.

- Frames the kernel drops are counted: the runner stops reading (SIGSTOP)
  while the rig sends more than its small receive queue holds; after SIGCONT
  the kernel's SO_RXQ_OVFL count reaches the firmware (RxDrops), the Seq
  gap is counted as lost frames, and every frame sent is accounted for:
  sent = accepted + lost + rejected Seq jumps, the lost ones being among
  the kernel's drops. On udp_multicast here; on SocketCAN (vcan0) in the VM
  tier.
- Only datagrams addressed to the multicast group reach the firmware: a
  valid LearningOff sent unicast to 127.0.0.1 and the port never arrives
  (learning stays on); the same frame sent to the group is executed.
- The runner's frames leave with a multicast TTL of 1, or 0 when asked.
"""
from __future__ import annotations

import functools
import json
import os
import signal
import socket
import struct
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest

can = pytest.importorskip("can")
pytest.importorskip("msgpack")

from can.interfaces.udp_multicast.bus import GeneralPurposeUdpMulticastBus  # noqa: E402
from can.interfaces.udp_multicast.utils import pack_message, unpack_message  # noqa: E402

from pyrhonn import firmware  # noqa: E402
from pyrhonn.plants import lim  # noqa: E402

from hil.transport import UDP_GROUP, free_port, udp_runner  # noqa: E402

DB = firmware.database()
ID = {m.name: m.frame_id for m in DB.messages}
WAIT = 30.0  # seconds for an answer that must come (a loaded machine is slow, never wrong)
IP_RECVTTL = getattr(socket, "IP_RECVTTL", 12)  # Linux's value; Python's socket module does not export it


@pytest.fixture(scope="session")
def runner_exe() -> Path:
    """rhonn_runner built from the current sources (cached per source content)."""
    try:
        return Path(udp_runner())
    except Exception as exc:  # noqa: BLE001 - no compiler: nothing to test here
        pytest.skip(f"no rhonn_runner: {exc}")


@functools.cache
def _samples() -> tuple[np.ndarray, np.ndarray]:
    traj = lim.simulate(dt=3e-4, horizon=2.4)
    k0 = int(round(2.0 / traj.dt))
    return traj.X[k0:k0 + 1000].copy(), traj.U[k0:k0 + 1000].copy()


def _measurement(seq: int) -> can.Message:
    X, U = _samples()
    return firmware.measurement_message(seq, X[seq % len(X)], U[seq % len(U)])


def _start(runner_exe: Path, port: int, report: Path, *extra: str) -> subprocess.Popen:
    cmd = [str(runner_exe), "--udp-multicast", f"{UDP_GROUP}:{port}", "--duration", "300", "--json", str(report),
           *extra]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    line = proc.stdout.readline()
    assert line.startswith("rhonn_runner: listening on udp_multicast"), (line, proc.stderr.read())
    return proc


def _stop(proc: subprocess.Popen, report: Path) -> tuple[dict, str]:
    proc.send_signal(signal.SIGCONT)  # in case a failed assertion left it stopped
    proc.send_signal(signal.SIGTERM)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 0, err
    return json.loads(report.read_text()), out


class _Rig:
    """The rig's side on python-can's own udp_multicast socket."""

    def __init__(self, port: int) -> None:
        self.bus = GeneralPurposeUdpMulticastBus(UDP_GROUP, port, 1)

    def send(self, msg: can.Message) -> None:
        self.bus.send(pack_message(msg))

    def wait_for(self, arbitration_id: int, match=lambda m: True, timeout: float = WAIT) -> can.Message | None:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            r = self.bus.recv(0.05)
            if r is None:
                continue
            try:
                m = unpack_message(r[0], check=True)
            except Exception:  # noqa: BLE001 - not a frame of ours
                continue
            if m.arbitration_id == arbitration_id and match(m):
                return m
        return None

    def estimate(self, seq: int, timeout: float = WAIT) -> firmware.Estimate | None:
        m = self.wait_for(ID["Estimate"], lambda m: firmware.decode_estimate(m).seq == seq, timeout)
        return None if m is None else firmware.decode_estimate(m)

    def close(self) -> None:
        self.bus.shutdown()


# -- frames the kernel dropped ----------------------------------------------------------------------


def test_frames_the_kernel_drops_while_the_runner_is_stopped_are_counted_and_every_frame_is_accounted(
        runner_exe, tmp_path) -> None:
    port = free_port()
    report = tmp_path / "runner.json"
    # the smallest receive queue the kernel allows: a handful of datagrams
    proc = _start(runner_exe, port, report, "--rcvbuf", "1024")
    rig = _Rig(port)
    sent = 0
    try:
        for seq in range(20):
            rig.send(_measurement(seq))
            sent += 1
            assert rig.estimate(seq) is not None, f"no estimate for {seq}"
        proc.send_signal(signal.SIGSTOP)
        burst = 600
        for seq in range(20, 20 + burst):
            rig.send(_measurement(seq))
            sent += 1
        proc.send_signal(signal.SIGCONT)
        # trickle on until three frames in a row are answered: every drop is then behind a frame that revealed it
        seq, answered_in_a_row = 20 + burst, 0
        while answered_in_a_row < 3:
            assert seq < 20 + burst + 200, "the runner never answered again"
            rig.send(_measurement(seq))
            sent += 1
            answered_in_a_row = answered_in_a_row + 1 if rig.estimate(seq, timeout=5.0) is not None else 0
            seq += 1
    finally:
        rig.close()
        stats, out = _stop(proc, report)
    assert stats["rx_drops"] > 0, stats
    # every lost Measurement here was a kernel drop (the runner's own frames handed back may be dropped too)
    assert 0 < stats["lost_frames"] <= stats["rx_drops"]
    assert sent == stats["measurements"] + stats["lost_frames"] + stats["rejected_seq_jump"] + \
        stats["rejected_seq_repeat"]
    # one rejection per gap; a restart per gap unless two gaps come back to back
    assert stats["rejected_seq_jump"] == stats["seq_gaps"] >= stats["restarts"] >= 1
    assert stats["measurements"] < sent - 500  # the queue held only a few of the burst
    assert f"kernel drops {stats['rx_drops']}" in out and f"lost {stats['lost_frames']} in" in out


# -- who may talk to the runner ---------------------------------------------------------------------


def test_a_unicast_datagram_never_reaches_the_firmware_and_the_group_one_does(runner_exe, tmp_path) -> None:
    port = free_port()
    report = tmp_path / "runner.json"
    proc = _start(runner_exe, port, report)
    rig = _Rig(port)
    uni = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    tx = firmware.SecOCSender(firmware.TEST_KEY)
    try:
        rig.send(_measurement(0))
        assert rig.estimate(0).learning
        # a valid LearningOff, to the host's address and the runner's port
        uni.sendto(pack_message(firmware.control_message("LearningOff", 0x51, sender=tx)), ("127.0.0.1", port))
        assert rig.wait_for(ID["ControlAck"], timeout=1.0) is None
        rig.send(_measurement(1))
        assert rig.estimate(1).learning, "a unicast LearningOff was executed"
        # the same command to the group (the next freshness value): executed
        rig.send(firmware.control_message("LearningOff", 0x52, sender=tx))
        ack = rig.wait_for(ID["ControlAck"])
        assert ack is not None and DB.decode_message("ControlAck", bytes(ack.data))["Token"] == 0x52
        rig.send(_measurement(2))
        assert not rig.estimate(2).learning
    finally:
        uni.close()
        rig.close()
        stats, _ = _stop(proc, report)
    assert stats["frames_in"] == 4 and stats["rejected"] == 0  # 3 measurements and the group's LearningOff
    assert stats["udp"]["datagrams"] == stats["frames_in"] + stats["udp"]["own_skipped"]  # the unicast never came


def _ttl_of_estimates(runner_exe: Path, tmp_path: Path, *extra: str) -> tuple[int, dict]:
    port = free_port()
    report = tmp_path / "ttl.json"
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEPORT, 1)
    sock.bind(("", port))
    sock.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP,
                    socket.inet_aton(UDP_GROUP) + socket.inet_aton("0.0.0.0"))
    sock.setsockopt(socket.IPPROTO_IP, IP_RECVTTL, 1)
    sock.settimeout(1.0)
    proc = _start(runner_exe, port, report, *extra)
    rig = _Rig(port)
    ttl = None
    try:
        rig.send(_measurement(0))
        end = time.monotonic() + WAIT
        while ttl is None and time.monotonic() < end:
            try:
                data, anc, _, _ = sock.recvmsg(4096, socket.CMSG_SPACE(4))
            except TimeoutError:
                continue
            if unpack_message(data).arbitration_id == ID["Estimate"]:
                ttl = next(struct.unpack("i", d[:4])[0] for lvl, typ, d in anc
                           if lvl == socket.IPPROTO_IP and typ == socket.IP_TTL)
    finally:
        sock.close()
        rig.close()
        stats, _ = _stop(proc, report)
    assert ttl is not None, "no estimate"
    return ttl, stats


@pytest.mark.parametrize("extra, want", [((), 1), (("--multicast-ttl", "0"), 0)])
def test_the_runners_frames_leave_with_a_multicast_ttl_of_one_or_zero_when_asked(runner_exe, tmp_path, extra,
                                                                                 want) -> None:
    ttl, stats = _ttl_of_estimates(runner_exe, tmp_path, *extra)
    assert ttl == want and stats["multicast_ttl"] == want


@pytest.mark.parametrize("argv, message", [
    (["--udp-multicast", "239.1.2.3:5000", "--multicast-ttl", "256"], "--multicast-ttl takes 0..255"),
    (["--udp-multicast", "239.1.2.3:5000", "--multicast-ttl", "-1"], "--multicast-ttl takes 0..255"),
    (["--bus-less", "--multicast-ttl", "0"], "--multicast-ttl is an option of --udp-multicast"),
    (["--udp-multicast", "239.1.2.3:5000", "--rcvbuf", "0"], "--rcvbuf takes a number of bytes"),
    (["--udp-multicast", "239.1.2.3:5000", "--rcvbuf", "1k"], "--rcvbuf takes a number of bytes"),
    (["--bus-less", "--rcvbuf", "4096"], "--rcvbuf needs a bus"),
])
def test_runner_refuses_bad_ttl_and_receive_buffer_options(runner_exe, argv, message) -> None:
    out = subprocess.run([str(runner_exe), *argv], capture_output=True, text=True, timeout=30)
    assert out.returncode == 2 and message in out.stderr, out.stderr


def test_the_runner_reports_filter_health_per_neuron(runner_exe, tmp_path) -> None:
    port = free_port()
    report = tmp_path / "runner.json"
    proc = _start(runner_exe, port, report)
    rig = _Rig(port)
    try:
        for seq in range(30):
            rig.send(_measurement(seq))
            assert rig.estimate(seq) is not None
        rig.send(firmware.control_message("DiagRequest", 3, sender=firmware.SecOCSender(firmware.TEST_KEY)))
        health = []
        while len(health) < 6:
            m = rig.wait_for(ID["Health"])
            assert m is not None, "no Health frames after the Diagnostics"
            health.append(firmware.decode_health(m))
    finally:
        rig.close()
        stats, out = _stop(proc, report)
    assert [h.neuron for h in health] == list(range(6)) and all(h.updates == 29 for h in health)
    assert [h["updates"] for h in stats["health"]] == [29] * 6
    assert all(h["trace_p"] > 0 and h["rejected"] == 0 for h in stats["health"])
    assert stats["udp"]["own_skipped"] == stats["frames_out"]  # its Health frames handed back are skipped
    assert "health:" in out and "trace P" in out


# -- SocketCAN (the VM tier) ------------------------------------------------------------------------


@pytest.mark.vcan
def test_frames_the_kernel_drops_on_socketcan_are_counted(vcan0: str, runner: Path, tmp_path: Path) -> None:
    report = tmp_path / "runner.json"
    proc = subprocess.Popen([str(runner), "--interface", vcan0, "--duration", "300", "--rcvbuf", "1024",
                             "--json", str(report)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    sent = 0
    try:
        line = proc.stdout.readline()
        assert line.startswith("rhonn_runner: listening on socketcan"), (line, proc.stderr.read())
        with can.Bus(interface="socketcan", channel=vcan0, fd=True,
                     can_filters=[{"can_id": ID["Estimate"], "can_mask": 0x7FF}]) as bus:
            def estimate(seq: int, timeout: float) -> bool:
                end = time.monotonic() + timeout
                while time.monotonic() < end:
                    m = bus.recv(0.05)
                    if m is not None and firmware.decode_estimate(m).seq == seq:
                        return True
                return False

            for seq in range(20):
                bus.send(_measurement(seq))
                sent += 1
                assert estimate(seq, WAIT)
            os.kill(proc.pid, signal.SIGSTOP)
            seq, tries = 20, 0
            while seq < 620:
                tries += 1
                assert tries < 100_000, "vcan refused the burst"
                try:
                    bus.send(_measurement(seq), timeout=1.0)
                except can.CanError:  # the sender's queue is full: not sent, send the same Seq again
                    time.sleep(0.001)
                    continue
                sent += 1
                seq += 1
            os.kill(proc.pid, signal.SIGCONT)
            seq, in_a_row = 620, 0
            while in_a_row < 3:
                assert seq < 820, "the runner never answered again"
                bus.send(_measurement(seq))
                sent += 1
                in_a_row = in_a_row + 1 if estimate(seq, 5.0) else 0
                seq += 1
    finally:
        proc.send_signal(signal.SIGCONT)
        proc.send_signal(signal.SIGTERM)
        proc.communicate(timeout=60)
    stats = json.loads(report.read_text())
    assert stats["rx_drops"] > 0 and stats["lost_frames"] >= stats["rx_drops"]
    assert sent == stats["measurements"] + stats["lost_frames"] + stats["rejected_seq_jump"] + \
        stats["rejected_seq_repeat"]
