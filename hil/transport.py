"""The three transports, all through python-can's ``Bus``; the scenario is
the same on each, only the channel changes.

- ``virtual``: python-can's in-process bus; the firmware is
  :class:`pyrhonn.firmware.FirmwareApp` serving from a thread.
- ``udp_multicast``: between processes on one host; the firmware is a
  ``python -m hil.firmware_node`` process. Each run gets its own UDP port, so
  parallel runs do not cross.
- ``socketcan``: vcan0 or a real can0; the firmware is firmware_sim's Linux
  runner (``rhonn_runner --interface IF``), started here when ``runner`` is
  given, else expected to be running already.
"""
from __future__ import annotations

import functools
import json
import os
import random
import signal
import subprocess
import sys
import threading
import time
import uuid
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Callable, Iterator

import can

from .rig import FirmwareTimeout, Recording, Rig
from .scenario import Scenario

__all__ = ["TRANSPORTS", "free_port", "lim_config", "run_replay"]

TRANSPORTS = ("virtual", "udp_multicast", "socketcan")
ROOT = Path(__file__).resolve().parents[1]
UDP_GROUP = "239.74.163.2"  # python-can's default IPv4 group


@functools.cache
def lim_config():
    """The network the firmware runs: the shipped config ``firmware-lim`` (float32)."""
    from pyrhonn.configfile import load_shipped

    return load_shipped("firmware-lim").config


def free_port() -> int:
    """A per-run UDP port (random in a range python-can does not use by default)."""
    return random.SystemRandom().randrange(20000, 40000)


@contextmanager
def _virtual(channel: str | None, firmware: bool) -> Iterator[tuple[can.BusABC, str, Callable[[], dict]]]:
    from pyrhonn.firmware import FirmwareApp

    channel = channel or f"hil-{uuid.uuid4().hex}"
    rig = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
    info: dict[str, Any] = {}
    stop = threading.Event()
    thread = None
    if firmware:
        fw_bus = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
        app = FirmwareApp(fw_bus, lim_config())
        info["app"] = app

        def serve() -> None:
            try:
                app.serve(until=stop.is_set, timeout=0.01)
            finally:
                fw_bus.shutdown()

        thread = threading.Thread(target=serve, name="hil-firmware", daemon=True)
        thread.start()
    try:
        yield rig, channel, lambda: {"counters": info["app"].counters} if "app" in info else {}
    finally:
        stop.set()
        if thread is not None:
            thread.join(5)
        rig.shutdown()


def _stop(proc: subprocess.Popen | None) -> None:
    """End a firmware process still running after the replay: SIGTERM (it
    prints its statistics), then kill if it does not exit within 30 s."""
    if proc is not None and proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()


@contextmanager
def _udp(channel: str | None, port: int | None, firmware: bool) -> Iterator[tuple[can.BusABC, str, Callable[[], dict]]]:
    channel = channel or UDP_GROUP
    port = port or free_port()
    proc = None
    side: dict[str, Any] = {}
    if firmware:
        env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
        proc = subprocess.Popen([sys.executable, "-m", "hil.firmware_node", "--channel", channel, "--port", str(port)],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, cwd=str(ROOT))
        line = proc.stdout.readline() if proc.stdout else ""
        if line.strip() != "ready":
            err = proc.stderr.read() if proc.stderr else ""
            proc.kill()
            raise FirmwareTimeout(f"the firmware node did not start: {err.strip().splitlines()[-1:] or line!r}")
    rig = can.Bus(interface="udp_multicast", channel=channel, port=port, fd=True)

    def firmware_side() -> dict:
        if proc is None:
            return {}
        if "report" not in side:
            proc.send_signal(signal.SIGTERM)
            out, _ = proc.communicate(timeout=30)
            lines = [ln for ln in out.splitlines() if ln.startswith("{")]
            side["report"] = json.loads(lines[-1]) if lines else {}
        return side["report"]

    try:
        yield rig, f"{channel}:{port}", firmware_side
    finally:
        rig.shutdown()
        _stop(proc)


@contextmanager
def _socketcan(channel: str | None, runner: str | None) -> Iterator[tuple[can.BusABC, str, Callable[[], dict]]]:
    from .rig import ids

    channel = channel or "vcan0"
    proc = None
    report = None
    side: dict[str, Any] = {}
    if runner:
        report = Path(os.environ.get("TMPDIR", "/tmp")) / f"hil-runner-{uuid.uuid4().hex}.json"
        proc = subprocess.Popen([str(runner), "--interface", channel, "--duration", "3600", "--json", str(report)],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        time.sleep(1.0)  # the runner binds its socket
        if proc.poll() is not None:
            _, err = proc.communicate()
            raise FirmwareTimeout(f"rhonn_runner exited at start: {err.strip()}")
    wanted = [{"can_id": ids()[n], "can_mask": 0x7FF} for n in ("Estimate", "ControlAck", "Diagnostics")]
    try:
        rig = can.Bus(interface="socketcan", channel=channel, fd=True, can_filters=wanted)
    except (OSError, can.CanError) as exc:
        if proc is not None:
            proc.kill()
        raise OSError(f"socketcan {channel}: cannot open it ({exc})") from exc

    import socket

    for opt in (33, socket.SO_RCVBUF):  # SO_RCVBUFFORCE (root), else SO_RCVBUF up to rmem_max
        try:
            rig.socket.setsockopt(socket.SOL_SOCKET, opt, 8 << 20)
            break
        except (OSError, AttributeError):
            continue

    def firmware_side() -> dict:
        if proc is None:
            return {}
        if "report" not in side:
            proc.send_signal(signal.SIGTERM)
            out, err = proc.communicate(timeout=60)
            side["report"] = {"stdout": out.strip().splitlines()[-8:], "returncode": proc.returncode}
            if report is not None and report.is_file():
                side["report"]["stats"] = json.loads(report.read_text())
                report.unlink()
        return side["report"]

    try:
        yield rig, channel, firmware_side
    finally:
        rig.shutdown()
        _stop(proc)


@contextmanager
def open_transport(transport: str, channel: str | None = None, *, port: int | None = None, firmware: bool = True,
                   runner: str | None = None):
    """(rig bus, channel description, firmware-side report function)."""
    if transport == "virtual":
        with _virtual(channel, firmware) as t:
            yield t
    elif transport == "udp_multicast":
        with _udp(channel, port, firmware) as t:
            yield t
    elif transport == "socketcan":
        with _socketcan(channel, runner if firmware else None) as t:
            yield t
    else:
        raise ValueError(f"transport: expected one of {', '.join(TRANSPORTS)}, got {transport!r}")


def run_replay(scenario: Scenario, transport: str = "virtual", channel: str | None = None, *,
               port: int | None = None, firmware: bool = True, runner: str | None = None,
               spin_ns: int | None = None, reply_timeout: float = 1.0, drain: float = 0.3,
               extra_frames: Callable[[int], list[can.Message]] | None = None) -> Recording:
    """Replay ``scenario`` over ``transport`` against the firmware; the Recording
    (its meta holds the firmware side's own report)."""
    if not isinstance(scenario, Scenario):
        raise ValueError(f"scenario: expected a Scenario, got {type(scenario).__name__}")
    plan = scenario.build()
    if spin_ns is None:
        spin_ns = 0 if transport == "virtual" else 150_000
    with open_transport(transport, channel, port=port, firmware=firmware, runner=runner) as (bus, where, side):
        rig = Rig(bus, plan, transport=transport, channel=where, spin_ns=spin_ns, reply_timeout=reply_timeout,
                  drain=drain, extra_frames=extra_frames)
        rec = rig.run()
        try:
            rec.meta["firmware_side"] = side()
        except Exception as exc:  # noqa: BLE001 - the side report is informative only
            rec.meta["firmware_side"] = {"error": f"{type(exc).__name__}: {exc}"}
    rec.meta["firmware_side"].pop("app", None)
    return rec
