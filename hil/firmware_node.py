"""The firmware as a process on a python-can bus (the udp_multicast transport).

    python -m hil.firmware_node --channel GROUP --port PORT [--interface udp_multicast] [--duration S]
                                [--receive-buffer BYTES] [--identifier CFG.toml --dbc ID.dbc]

Runs :class:`pyrhonn.firmware.FirmwareApp` (the exact firmware logic) with
firmware_sim's LIM identifier, or with ``--identifier`` and ``--dbc`` another
identifier (a config file, float32, and the DBC ``pyrhonn export --dbc`` wrote
for it: the firmware application compiled for that DBC, firmware_sim/tools/
build_twin.py, cached; exit 2 naming the option when either is refused), prints ``ready`` on stdout once its socket is
bound, serves until SIGTERM/SIGINT or ``--duration``, then prints one JSON
line: the firmware's counters and cyclictest-style statistics of its own side
(interval between Measurement arrivals, handling time per frame).
udp_multicast hands a sender its own frames back, so frames with the
firmware's own identifiers (Estimate, ControlAck, Diagnostics, Health) are skipped.
Its socket gets a deep receive queue (``--receive-buffer``, default 32 MiB
where the kernel allows it), so that a stall of this process on a busy host
delays frames instead of dropping them; what a full queue still drops, the
rig counts (hil.accounting).
"""
from __future__ import annotations

import argparse
import gc
import json
import signal
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np


def _stats(v: list[int]) -> dict:
    from .latency import stats_us

    return stats_us(np.asarray(v, dtype=np.int64))


def _firmware(identifier: Path | None, dbc: Path | None) -> tuple[Any, Any]:
    """(config, protocol) FirmwareApp runs: the LIM's, or those of ``identifier`` and ``dbc``; ValueError
    naming the option when one is missing or refused (FirmwareUnavailable when the twin cannot be built)."""
    from pyrhonn.configfile import load_config
    from pyrhonn.firmware import FirmwareApp

    from .transport import lim_config, twin_protocol

    if (identifier is None) != (dbc is None):
        raise ValueError("--identifier, --dbc: an identifier's config file and its DBC go together (give both, "
                         "or neither for the LIM)")
    if identifier is None or dbc is None:
        return lim_config(), None
    try:
        config = load_config(identifier).config
    except (OSError, ValueError) as exc:
        raise ValueError(f"--identifier: {identifier}: {exc}") from None
    if config.dtype != "float32":
        raise ValueError(f"--identifier: {identifier}: dtype is {config.dtype!r}; the firmware runs the float32 core")
    try:
        protocol = twin_protocol(dbc)
        FirmwareApp(None, config, protocol=protocol)   # the shapes agree
    except ValueError as exc:
        raise ValueError(f"--dbc: {dbc}: {exc}") from None
    return config, protocol


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m hil.firmware_node", description=__doc__.splitlines()[0])
    ap.add_argument("--interface", default="udp_multicast")
    ap.add_argument("--channel", required=True)
    ap.add_argument("--port", type=int, default=None)
    ap.add_argument("--duration", type=float, default=3600.0)
    ap.add_argument("--receive-buffer", type=int, default=None, metavar="BYTES",
                    help="the socket's receive buffer (default: hil.transport's deep one)")
    ap.add_argument("--identifier", type=Path, default=None, metavar="CFG.toml",
                    help="another identifier than the LIM: its config file (float32); needs --dbc")
    ap.add_argument("--dbc", type=Path, default=None, metavar="ID.dbc",
                    help="with --identifier: the protocol DBC pyrhonn export --dbc wrote for it")
    args = ap.parse_args(argv)
    import can

    from pyrhonn.firmware import FirmwareApp

    from .rig import ids
    from .transport import FirmwareUnavailable, _deep_receive_buffer

    try:
        config, protocol = _firmware(args.identifier, args.dbc)
    except (ValueError, FirmwareUnavailable) as exc:
        print(f"firmware_node: {exc}", file=sys.stderr)
        return 2

    kw: dict[str, Any] = {"fd": True}
    if args.port is not None:
        kw["port"] = args.port
    try:
        bus = can.Bus(interface=args.interface, channel=args.channel, **kw)
    except (OSError, can.CanError, ValueError) as exc:
        print(f"firmware_node: cannot open {args.interface} {args.channel}: {exc}", file=sys.stderr)
        return 2
    # a deep receive queue: a stall of this process on a busy host delays frames instead of dropping them
    sock = getattr(getattr(bus, "_multicast", None), "_socket", None)
    if args.receive_buffer is None:
        _deep_receive_buffer(sock)
    elif sock is not None:
        import socket

        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, args.receive_buffer)
    app = FirmwareApp(bus, config, protocol=protocol)
    own = {v for k, v in ids().items() if k in ("Estimate", "ControlAck", "Diagnostics", "Health")}
    meas_id = ids()["Measurement"]
    stop = False

    def _stop(*_):
        nonlocal stop
        stop = True

    signal.signal(signal.SIGTERM, _stop)
    signal.signal(signal.SIGINT, _stop)
    print("ready", flush=True)
    end = time.monotonic() + args.duration
    arrivals: list[int] = []
    handling: list[int] = []
    handled = 0
    clock = time.perf_counter_ns
    # no collector pauses while serving: what is allocated per frame is freed by refcount
    gc.freeze()
    gc.disable()
    try:
        while not stop and time.monotonic() < end:
            msg = bus.recv(timeout=0.05)
            if msg is None or (msg.arbitration_id in own and not msg.is_extended_id):
                continue
            t_in = clock()
            for reply in app.handle(msg):
                try:
                    bus.send(reply)
                except can.CanError:
                    app.tx_failures += 1
            if msg.arbitration_id == meas_id:
                arrivals.append(t_in)
                handling.append(clock() - t_in)
            handled += 1
    finally:
        bus.shutdown()
    gaps = np.diff(np.asarray(arrivals, dtype=np.int64)) if len(arrivals) > 1 else np.zeros(0, dtype=np.int64)
    report = {"handled": handled, "tx_failures": app.tx_failures, "counters": app.counters,
              "arrival_interval_us": _stats(gaps.tolist()), "handling_us": _stats(handling)}
    print(json.dumps(report), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
