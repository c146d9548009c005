"""The three transports, all through python-can's ``Bus``; the scenario is
the same on each, only the channel changes.

- ``virtual``: python-can's in-process bus; the firmware is
  :class:`pyrhonn.firmware.FirmwareApp` serving from a thread.
- ``udp_multicast``: between processes on one host. The firmware is
  firmware_sim's Linux runner on python-can's udp_multicast wire protocol
  (``rhonn_runner --udp-multicast GROUP:PORT``, the C firmware; ``runner``
  names the executable, else one built from the source tree with cc and
  cached, see firmware_sim/linux/build_runner.py), or with
  ``firmware="python"`` a ``python -m hil.firmware_node`` process (the same
  firmware logic through cffi: where there is no C compiler; another
  identifier's twin is compiled for its DBC, so it needs one). Each run gets
  its own UDP port, so parallel runs do not cross.
- ``socketcan``: vcan0 or a real can0; the firmware is firmware_sim's Linux
  runner (``rhonn_runner --interface IF``), started here when ``runner`` is
  given, else expected to be running already.

A runner started here runs under SCHED_FIFO (its own ``--fifo``, memory
locked) when this process does, at the same priority; its report (stdout,
exit code, its JSON statistics) is the Recording's ``firmware_side``.
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
import uuid
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Callable, Iterator

import can

from .rig import FirmwareTimeout, Recording, Rig
from .scenario import Scenario

__all__ = ["FIRMWARES", "TRANSPORTS", "FirmwareUnavailable", "free_port", "lim_config", "parse_cpu_pair", "run_replay",
           "twin_protocol", "udp_runner", "use_fifo"]

TRANSPORTS = ("virtual", "udp_multicast", "socketcan")
FIRMWARES = ("runner", "python")  # udp_multicast: the C runner (default) or the Python node
ROOT = Path(__file__).resolve().parents[1]
UDP_GROUP = "239.74.163.2"  # python-can's default IPv4 group
#: the udp_multicast runner busy-polls this long before (and after) each Measurement is due, so a frame
#: on schedule is taken without a wake-up latency (about 30 us on average on this VM, hundreds at p99)
RUNNER_SPIN_US = 50.0
#: the most the runner accepts (less than half the 0.3 ms period): it then sleeps 2 us a period, i.e.
#: busy-polls as a real-time task that owns its CPU (``hil bench``'s default)
RUNNER_SPIN_MAX_US = 149.0


def check_runner_spin(value: object) -> float:
    """The runner's busy-poll margin in us, 0 <= value <= RUNNER_SPIN_MAX_US
    (ValueError naming runner_spin_us otherwise)."""
    from pyrhonn.validation import check_real, fail

    v = check_real("runner_spin_us", value)
    if not 0.0 <= v <= RUNNER_SPIN_MAX_US:
        raise fail("runner_spin_us", f"expected microseconds in [0, {RUNNER_SPIN_MAX_US:g}] (less than half the "
                                     f"0.3 ms period), got {value!r}")
    return v


@functools.cache
def lim_config():
    """The network the firmware runs: the shipped config ``firmware-lim`` (float32)."""
    from pyrhonn.configfile import load_shipped

    return load_shipped("firmware-lim").config


def free_port() -> int:
    """A per-run UDP port (random in a range python-can does not use by default)."""
    return random.SystemRandom().randrange(20000, 40000)


def _source_module(relative: str, name: str, what: str) -> Any:
    """A script of the source tree (beside this package, else the current directory's), imported;
    FirmwareUnavailable naming ``what`` when there is none."""
    import importlib.util

    scripts = [base / relative for base in (ROOT, Path.cwd())]
    script = next((p for p in scripts if p.is_file()), None)
    if script is None:
        raise FirmwareUnavailable(f"no {what}: no firmware_sim sources beside this installation or in the current "
                                  f"directory ({relative})")
    spec = importlib.util.spec_from_file_location(name, script)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def identifier_twin(scenario: Scenario) -> tuple[Any, Any]:
    """(config, protocol) of the firmware twin FirmwareApp runs for ``scenario``: the LIM's, or for another
    identifier its config and the firmware application compiled for its DBC
    (firmware_sim/tools/build_twin.py, once per DBC, cached). FirmwareUnavailable when that cannot be built."""
    from pyrhonn.firmware import lim_protocol

    if not scenario.identifier:
        return lim_config(), lim_protocol()
    return scenario.reference_config(), twin_protocol(scenario.dbc)


def twin_protocol(dbc: str | os.PathLike) -> Any:
    """The protocol of ``dbc`` with the firmware application compiled for it (firmware_sim/tools/build_twin.py,
    once per DBC, cached): what FirmwareApp runs for another identifier. FirmwareUnavailable when that cannot
    be built, ValueError naming the DBC when it has not the protocol's shape."""
    module = _source_module("firmware_sim/tools/build_twin.py", "_pyrhonn_build_twin", f"firmware twin for {dbc}")
    try:
        return module.protocol(dbc)
    except (RuntimeError, OSError, subprocess.CalledProcessError) as exc:
        raise FirmwareUnavailable(f"cannot build the firmware twin for {dbc} ({exc})") from exc


@contextmanager
def _virtual(channel: str | None, firmware: bool, scenario: Scenario | None = None
             ) -> Iterator[tuple[can.BusABC, str, Callable[[], dict]]]:
    from pyrhonn.firmware import FirmwareApp

    channel = channel or f"hil-{uuid.uuid4().hex}"
    # the twin first: a build that fails leaves no bus open
    config, protocol = identifier_twin(scenario) if scenario is not None and firmware else (lim_config(), None)
    rig = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
    info: dict[str, Any] = {}
    stop = threading.Event()
    thread = None
    if firmware:
        fw_bus = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
        app = FirmwareApp(fw_bus, config, protocol=protocol)
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


class FirmwareUnavailable(OSError):
    """The firmware process cannot be had here (no runner and no way to build one)."""


#: receive buffer asked for the rig's and the Python node's sockets: a small datagram takes a few kB of
#: it, so 32 MiB queue some 10,000 frames, seconds of a stalled process at 0.3 ms (two frames a cycle)
RECEIVE_BUFFER = 32 << 20


def _deep_receive_buffer(sock: Any) -> None:
    """RECEIVE_BUFFER bytes of receive buffer for a socket, so that a stall
    of its process (tens of ms to seconds on a busy host) delays frames
    instead of dropping them: SO_RCVBUFFORCE (root), else SO_RCVBUF up to
    net.core.rmem_max. What a full queue still drops is counted
    (udp_socket_drops)."""
    import socket

    if sock is None:
        return
    for opt in (33, socket.SO_RCVBUF):
        try:
            sock.setsockopt(socket.SOL_SOCKET, opt, RECEIVE_BUFFER)
            return
        except (OSError, AttributeError):
            continue


def udp_socket_drops(port: int) -> dict[int, int]:
    """inode -> datagrams the kernel dropped, of every UDP socket on this host
    bound to ``port`` (/proc/net/udp and udp6: the socket's sk_drops, the
    counter SO_RXQ_OVFL reports, which python-can's udp_multicast cannot
    enable: it refuses an unexpected control message). A receive queue that
    overflows drops what arrives; {} where /proc has no such table."""
    drops: dict[int, int] = {}
    for table in ("/proc/net/udp", "/proc/net/udp6"):
        try:
            with open(table, encoding="ascii") as f:
                lines = f.read().splitlines()[1:]
        except OSError:
            continue
        for line in lines:
            cols = line.split()
            try:
                if len(cols) >= 13 and int(cols[1].rsplit(":", 1)[1], 16) == port:
                    drops[int(cols[9])] = int(cols[-1])
            except ValueError:
                continue
    return drops


def _drop_counter(sock: Any, port: int) -> Callable[[], dict[str, int]] | None:
    """{"rig": n, "firmware": n}: the kernel's drops on the rig's socket and
    on every other socket bound to the run's own port (the firmware's), or
    None where the rig's socket is not in /proc/net/udp."""
    try:
        inode = os.fstat(sock.fileno()).st_ino
    except (AttributeError, OSError, ValueError):
        return None
    if inode not in udp_socket_drops(port):
        return None

    def count() -> dict[str, int]:
        d = udp_socket_drops(port)
        return {"rig": d.get(inode, 0), "firmware": sum(v for k, v in d.items() if k != inode)}

    return count


def _check_cpu(name: str, cpu: object) -> int:
    """A CPU of this host (0 .. os.cpu_count() - 1), else ValueError naming ``name``."""
    n = os.cpu_count() or 1
    if isinstance(cpu, bool) or not isinstance(cpu, int) or not 0 <= cpu < n:
        raise ValueError(f"{name}: expected a CPU number 0..{n - 1}, got {cpu!r}")
    return cpu


def _pin(proc: subprocess.Popen, cpu: int | None) -> None:
    """Pin a firmware process just started to ``cpu`` (it starts on the rig's CPUs, which it inherits)."""
    if cpu is not None:
        try:
            os.sched_setaffinity(proc.pid, {cpu})
        except OSError as exc:
            proc.kill()
            raise OSError(f"cannot pin the firmware process to CPU {cpu}: {exc}") from exc


def _stop(proc: subprocess.Popen | None) -> None:
    """End a firmware process still running after the replay: SIGTERM (it
    prints its statistics), then kill if it does not exit within 30 s."""
    if proc is not None and proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()


def udp_runner(runner: str | os.PathLike | None = None, scenario: Scenario | None = None) -> str:
    """The rhonn_runner to start on udp_multicast: ``runner`` when given, else
    the one built from the source tree (beside the package, else the current
    directory's; once per source content, cached; see
    firmware_sim/linux/build_runner.py), for ``scenario``'s identifier when it
    names one. FirmwareUnavailable when neither."""
    if runner is not None:
        path = Path(runner)
        if not (path.is_file() and os.access(path, os.X_OK)):
            raise FirmwareUnavailable(f"rhonn_runner: {runner}: not an executable file")
        return str(path)
    # the sources beside this package (a checkout, an editable install), else a checkout this runs in
    try:
        module = _source_module("firmware_sim/linux/build_runner.py", "_pyrhonn_build_runner", "rhonn_runner to start")
    except FirmwareUnavailable as exc:
        raise FirmwareUnavailable(f"{exc}; give --runner PATH (CMake target rhonn_runner, or "
                                  "firmware_sim/linux/build_runner.py), or --firmware python") from None
    try:
        if scenario is not None and scenario.identifier:
            return str(module.cached_for(Path(scenario.identifier), Path(scenario.dbc)))
        return str(module.cached())
    except (RuntimeError, OSError, subprocess.CalledProcessError) as exc:
        raise FirmwareUnavailable(f"cannot build rhonn_runner ({exc}); give --runner PATH, or --firmware python "
                                  "(the same firmware logic in a Python process)") from exc


def use_fifo(priority: int | None) -> str:
    """Switch this process to SCHED_FIFO at ``priority`` (None: leave it);
    the policy in effect, as a line for a report. A firmware process started
    afterwards runs under SCHED_FIFO too (see _fifo_args)."""
    if priority is None:
        return "SCHED_OTHER"
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except (OSError, AttributeError) as exc:
        return f"SCHED_OTHER (SCHED_FIFO {priority} refused: {exc})"
    return f"SCHED_FIFO {priority}"


def parse_cpu_pair(text: str) -> tuple[int, int]:
    """"RIG,FIRMWARE" CPU numbers, e.g. "0,1" (ValueError otherwise)."""
    parts = text.split(",")
    if len(parts) != 2 or not all(p.strip().isdigit() for p in parts):
        raise ValueError(f"expected RIG,FIRMWARE CPU numbers (e.g. 0,1), got {text!r}")
    return int(parts[0]), int(parts[1])


def _fifo_args() -> list[str]:
    """``--fifo PRIO`` when this process runs under SCHED_FIFO (``hil bench
    --fifo``): the runner then asks for it itself, and locks its memory."""
    try:
        if os.sched_getscheduler(0) == os.SCHED_FIFO:
            return ["--fifo", str(os.sched_getparam(0).sched_priority)]
    except (OSError, AttributeError):
        pass
    return []


def _hist_us(h: dict | None) -> dict:
    """A runner histogram (count, min_us, ...) in hil.latency.stats_us's form."""
    if not h or not h.get("count"):
        return {"n": 0}
    return {"n": int(h["count"]), "min": h["min_us"], "avg": h["avg_us"], "p99": h["p99_us"], "p99.9": h["p999_us"],
            "max": h["max_us"]}


def _runner_side(proc: subprocess.Popen, report: Path, side: dict[str, Any]) -> dict:
    """Stop the runner (SIGTERM: it prints and writes its statistics) and
    read its report, once."""
    if "report" not in side:
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=60)
        side["report"] = {"stdout": out.strip().splitlines()[-12:], "returncode": proc.returncode}
        if err.strip():
            side["report"]["stderr"] = err.strip().splitlines()[-5:]
        if report.is_file():
            stats = json.loads(report.read_text())
            side["report"]["stats"] = stats
            side["report"]["handling_us"] = _hist_us(stats.get("step"))
            side["report"]["arrival_interval_us"] = _hist_us(stats.get("interval"))
            report.unlink()
    return side["report"]


def _start_runner(exe: str, bus_args: list[str], where: str, cpu: int | None,
                  spin_us: float) -> tuple[subprocess.Popen, Path]:
    """Start rhonn_runner on a bus, taking each frame as it arrives (--rx arrival) and busy-polling
    ``spin_us`` either side of each expected one; (the process, the path of the JSON statistics it
    writes on exit) once its socket is ready (it prints "listening"), FirmwareTimeout with its message
    when it exits instead."""
    report = Path(os.environ.get("TMPDIR", "/tmp")) / f"hil-runner-{uuid.uuid4().hex}.json"
    proc = subprocess.Popen([exe, *bus_args, "--rx", "arrival", "--spin-us", f"{spin_us:g}", "--duration", "3600",
                             "--json", str(report), *_fifo_args()],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    _pin(proc, cpu)
    line = proc.stdout.readline() if proc.stdout else ""  # printed once the socket is ready
    if not line.startswith("rhonn_runner: listening"):
        proc.kill()
        _, err = proc.communicate()
        raise FirmwareTimeout(f"rhonn_runner did not start on {where}: {err.strip() or line.strip() or 'no output'}")
    return proc, report


def _stop_runner(proc: subprocess.Popen | None, report: Path | None) -> None:
    """_stop, and the runner's statistics file removed if nobody read it."""
    _stop(proc)
    if report is not None and report.is_file():
        report.unlink()


@contextmanager
def _udp(channel: str | None, port: int | None, firmware: str | None, runner: str | None = None,
         cpu: int | None = None, spin_us: float = RUNNER_SPIN_US,
         scenario: Scenario | None = None) -> Iterator[tuple[can.BusABC, str, Callable[[], dict]]]:
    """The udp_multicast bus; ``firmware`` "runner" starts ``runner`` (a path
    udp_runner resolved), "python" the Python node (for ``scenario``'s identifier
    when it names one), None nothing."""
    channel = channel or UDP_GROUP
    port = port or free_port()
    proc = None
    report = None
    side: dict[str, Any] = {}
    if firmware == "runner":
        assert runner is not None, "open_transport resolves the runner"
        group = f"[{channel}]" if ":" in channel else channel
        # Diagnostics on request only, as the Python node (FirmwareApp's default): both firmware choices
        # put the same frames on the bus, and the last Diagnostics' StepTimeMax covers the whole run
        proc, report = _start_runner(runner, ["--udp-multicast", f"{group}:{port}", "--diag-period", "0"],
                                     f"udp_multicast {group}:{port}", cpu, spin_us)
    elif firmware == "python":
        env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
        node = [sys.executable, "-m", "hil.firmware_node", "--channel", channel, "--port", str(port)]
        if scenario is not None and scenario.identifier:
            node += ["--identifier", str(Path(scenario.identifier).resolve()), "--dbc",
                     str(Path(scenario.dbc).resolve())]
        proc = subprocess.Popen(node, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, cwd=str(ROOT))
        _pin(proc, cpu)
        line = proc.stdout.readline() if proc.stdout else ""
        if line.strip() != "ready":
            err = proc.stderr.read() if proc.stderr else ""
            proc.kill()
            raise FirmwareTimeout(f"the firmware node did not start: {err.strip().splitlines()[-1:] or line!r}")
    try:
        rig = can.Bus(interface="udp_multicast", channel=channel, port=port, fd=True)
    except (OSError, can.CanError) as exc:
        _stop_runner(proc, report)
        raise OSError(f"udp_multicast {channel}:{port}: cannot open it ({exc})") from exc
    # the rig's socket also gets its own Measurements back (multicast loop): twice the traffic to buffer
    sock = getattr(getattr(rig, "_multicast", None), "_socket", None)
    _deep_receive_buffer(sock)
    rig.hil_kernel_drops = _drop_counter(sock, port)  # type: ignore[attr-defined]  # what a receive queue that overflowed dropped

    def firmware_side() -> dict:
        if proc is None:
            return {}
        if report is not None:
            return _runner_side(proc, report, side)
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
        _stop_runner(proc, report)


@contextmanager
def _socketcan(channel: str | None, runner: str | None, cpu: int | None = None,
               spin_us: float = RUNNER_SPIN_US) -> Iterator[tuple[can.BusABC, str, Callable[[], dict]]]:
    from .rig import ids

    channel = channel or "vcan0"
    proc = None
    report = None
    side: dict[str, Any] = {}
    if runner:
        # each frame as it arrives (the runner's SocketCAN default is once per tick: up to a period late)
        proc, report = _start_runner(str(runner), ["--interface", channel], f"socketcan {channel}", cpu, spin_us)
    wanted = [{"can_id": ids()[n], "can_mask": 0x7FF} for n in ("Estimate", "ControlAck", "Diagnostics", "Health")]
    try:
        rig = can.Bus(interface="socketcan", channel=channel, fd=True, can_filters=wanted)
    except (OSError, can.CanError) as exc:
        _stop_runner(proc, report)
        raise OSError(f"socketcan {channel}: cannot open it ({exc})") from exc
    _deep_receive_buffer(getattr(rig, "socket", None))

    def firmware_side() -> dict:
        if proc is None or report is None:
            return {}
        return _runner_side(proc, report, side)

    try:
        yield rig, channel, firmware_side
    finally:
        rig.shutdown()
        _stop_runner(proc, report)


def _firmware_kind(transport: str, firmware: bool | str) -> str | None:
    """What serves the rig: None (nothing started here), "python" or "runner"."""
    if firmware is False or firmware is None:
        return None
    if firmware is not True and firmware not in FIRMWARES:
        raise ValueError(f"firmware: expected one of {', '.join(FIRMWARES)} (or True/False), got {firmware!r}")
    if transport == "virtual":
        if firmware == "runner":
            raise ValueError("firmware: the virtual bus lives inside this process; rhonn_runner cannot join it "
                             "(use udp_multicast or socketcan)")
        return "python"
    if transport == "socketcan":
        if firmware == "python":
            raise ValueError("firmware: over socketcan the firmware is rhonn_runner (--runner), or one already "
                             "running")
        return "runner"
    return "runner" if firmware is True else str(firmware)


@contextmanager
def open_transport(transport: str, channel: str | None = None, *, port: int | None = None,
                   firmware: bool | str = True, runner: str | None = None, firmware_cpu: int | None = None,
                   runner_spin_us: float = RUNNER_SPIN_US, scenario: Scenario | None = None):
    """(rig bus, channel description, firmware-side report function).
    ``firmware``: True (the transport's default firmware), False (none: one
    must be running already), or "runner" / "python" (udp_multicast).
    ``firmware_cpu``: pin the firmware process started here to this CPU.
    ``runner_spin_us``: how long a runner started here (udp_multicast, or
    socketcan with ``runner``) busy-polls either side of each expected
    Measurement (``rhonn_runner --rx arrival --spin-us``). ``scenario``: the
    firmware started here runs its identifier (None: the LIM's)."""
    if transport not in TRANSPORTS:
        raise ValueError(f"transport: expected one of {', '.join(TRANSPORTS)}, got {transport!r}")
    runner_spin_us = check_runner_spin(runner_spin_us)
    kind = _firmware_kind(transport, firmware)
    if firmware_cpu is not None:
        if transport == "virtual" or kind is None or (transport == "socketcan" and runner is None):
            raise ValueError("firmware_cpu: only a firmware process started here can be pinned (udp_multicast, or "
                             "socketcan with a runner)")
        _check_cpu("firmware_cpu", firmware_cpu)
    if transport == "virtual":
        with _virtual(channel, kind is not None, scenario) as t:
            yield t
    elif transport == "udp_multicast":
        fallback = None
        other = scenario is not None and bool(scenario.identifier)
        if kind == "python" and other:
            assert scenario is not None
            twin_protocol(scenario.dbc)   # built here (cached), so the node only loads it; an error ends here
        if kind == "runner":
            try:
                runner = udp_runner(runner, scenario)
            except FirmwareUnavailable as exc:
                if firmware is not True or runner is not None or other:
                    raise                   # the runner was asked for by name, or none other runs the identifier
                kind, fallback = "python", f"rhonn_runner unavailable ({exc}): the firmware is the Python node"
        with _udp(channel, port, kind, runner, firmware_cpu, runner_spin_us, scenario) as (bus, where, side):
            def side_noted() -> dict:
                report = side()
                report["firmware"] = {"runner": "rhonn_runner", "python": "hil.firmware_node"}.get(kind or "", None)
                if fallback is not None:
                    report["fallback"] = fallback
                return report

            yield bus, where, side_noted
    else:
        with _socketcan(channel, runner if kind is not None else None, firmware_cpu, runner_spin_us) as t:
            yield t


def run_replay(scenario: Scenario, transport: str = "virtual", channel: str | None = None, *,
               port: int | None = None, firmware: bool | str = True, runner: str | None = None,
               firmware_cpu: int | None = None, runner_spin_us: float = RUNNER_SPIN_US,
               spin_ns: int | None = None, reply_timeout: float = 1.0, drain: float = 0.3,
               extra_frames: Callable[[int], list[can.Message]] | None = None,
               progress: Callable[[int, int, int, int], None] | None = None,
               sample_drops: bool = False) -> Recording:
    """Replay ``scenario`` over ``transport`` against the firmware; the Recording
    (its meta holds the firmware side's own report). ``firmware``, ``runner``,
    ``firmware_cpu``, ``runner_spin_us``: see :func:`open_transport`
    (udp_multicast: the C runner by default). ``progress``: the rig's progress
    hook (hil.progress.Progress). ``sample_drops``: read the kernel's drop
    counters during the run too (hil.rig.Rig; not for timing runs)."""
    if not isinstance(scenario, Scenario):
        raise ValueError(f"scenario: expected a Scenario, got {type(scenario).__name__}")
    plan = scenario.build()
    if spin_ns is None:
        spin_ns = 0 if transport == "virtual" else 150_000
    with open_transport(transport, channel, port=port, firmware=firmware, runner=runner,
                        firmware_cpu=firmware_cpu, runner_spin_us=runner_spin_us,
                        scenario=scenario) as (bus, where, side):
        rig = Rig(bus, plan, transport=transport, channel=where, spin_ns=spin_ns, reply_timeout=reply_timeout,
                  drain=drain, extra_frames=extra_frames, kernel_drops=getattr(bus, "hil_kernel_drops", None),
                  progress=progress, sample_drops=sample_drops)
        rec = rig.run()
        try:
            rec.meta["firmware_side"] = side()
        except Exception as exc:  # noqa: BLE001 - the side report is informative only
            rec.meta["firmware_side"] = {"error": f"{type(exc).__name__}: {exc}"}
    rec.meta["firmware_side"].pop("app", None)
    return rec
