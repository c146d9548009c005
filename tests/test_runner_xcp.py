"""The Linux runner's XCP slave (firmware_sim/app/fw_xcp.c, --xcp-udp) with
the A2L that firmware_sim/tools/make_a2l.py writes, read by pya2ldb and
driven by pyxcp as the master while the HIL rig's frames replay over
udp_multicast.

- The A2L is parsed by pya2ldb: its measurements and characteristic sit at
  the runner's symbols (nm) relative to __executable_start, and its
  IF_DATA XCP names XCP on UDP, the step event and the timestamps.
- pyxcp connects; GET_ID is the A2L's name; a wrong key is refused and
  disconnects; DAQ on the step event carries the weights and the health,
  and every step's sample arrives or is counted lost with its reason (the
  slave's transport refused it, or the master's receive queue dropped it);
  DOWNLOAD of learning off freezes the weights in the DAQ stream from the
  next step on.
"""
from __future__ import annotations

import json
import re
import shutil
import signal
import socket
import struct
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

can = pytest.importorskip("can")
pytest.importorskip("pyxcp")
pytest.importorskip("cryptography")

from pyxcp import Master  # noqa: E402
from pyxcp.config import create_application_from_config, set_application  # noqa: E402
from pyxcp.daq_stim import DaqList  # noqa: E402
from pyxcp.types import XcpResponseError  # noqa: E402

from a2l_read import read_a2l  # noqa: E402
from pyrhonn.firmware import database  # noqa: E402

from hil.scenario import Scenario  # noqa: E402
from hil.transport import UDP_GROUP, free_port  # noqa: E402
from source_scripts import load_script  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
FW = ROOT / "firmware_sim"
ESTIMATE = database().get_message_by_name("Estimate").frame_id
WEIGHTS = [(0, t) for t in range(2)] + [(i, t) for i in (1, 2, 3) for t in range(5)] + \
    [(i, t) for i in (4, 5) for t in range(6)]


xcp_master = load_script(FW / "tools" / "xcp_master.py", "_xcp_master")


@pytest.fixture(scope="module")
def runner_exe(tmp_path_factory: pytest.TempPathFactory) -> Path:
    if shutil.which("cc") is None and shutil.which("gcc") is None:
        pytest.skip("no C compiler to build rhonn_runner")
    build = load_script(FW / "linux" / "build_runner.py", "_build_runner_xcp")
    return build.cached(tmp_path_factory.getbasetemp() / "runner-cache")


@pytest.fixture(scope="module")
def make_a2l() -> Any:
    return load_script(FW / "tools" / "make_a2l.py", "_make_a2l")


@pytest.fixture(scope="module")
def a2l(runner_exe: Path, make_a2l: Any, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """The A2L of the runner, parsed by pya2ldb: name, addresses, IF_DATA."""
    out = tmp_path_factory.mktemp("a2l") / "rhonn_lim.a2l"
    assert make_a2l.main([str(runner_exe), str(out), "--port", "5555"]) == 0
    return {"path": out, **read_a2l(out)}


def _nm(exe: Path) -> dict[str, int]:
    out = subprocess.run(["nm", "--defined-only", str(exe)], check=True, capture_output=True, text=True).stdout
    return {p[2]: int(p[0], 16) for p in (ln.split() for ln in out.splitlines()) if len(p) == 3}


def test_the_a2l_places_every_signal_at_the_runners_symbols_and_pya2ldb_reads_it(a2l, runner_exe) -> None:
    syms = _nm(runner_exe)
    sig = syms["rhonn_xcp_signals"] - syms["__executable_start"]
    cal = syms["rhonn_xcp_calibration"] - syms["__executable_start"]
    m = a2l["measurements"]
    assert a2l["project"] == "RHONN_LIM"
    assert [k for k in m if k.startswith("w")] == [f"w{i}_{t}" for i, t in WEIGHTS]
    assert m["w0_0"] == (sig, "FLOAT32_IEEE") and m["w4_5"] == (sig + 4 * (4 * 12 + 5), "FLOAT32_IEEE")
    assert m["xhat_ia"][0] == sig + 288 + 16 and m["measurements"] == (sig + 504, "ULONG")
    assert {"nis_5", "trace_p_0", "innovation_qm", "updates_3", "gated_2", "daq_dto_lost"} <= set(m)
    assert a2l["characteristics"] == {"learning": cal, **{f"trace_ceiling_{i}": cal + 4 + 4 * i for i in range(6)},
                                      **{f"gate_{i}": cal + 28 + 4 * i for i in range(6)}}
    assert a2l["units"]["CM_IA"] == "A" and a2l["units"]["CM_QM"] == "m"
    xcp = a2l["if_data"]["XCP"][0]
    assert xcp["XCP_ON_UDP_IP"] == [0x0104, 5555, {"ADDRESS": "127.0.0.1"}]
    daq = xcp["DAQ"]
    assert daq[0] == "DYNAMIC" and daq[-1]["EVENT"] == [["step", "step", 0, "DAQ", 255, 0, 0, 0]]
    assert daq[-1]["TIMESTAMP_SUPPORTED"][:3] == [1, "SIZE_DWORD", "UNIT_1US"]


def test_make_a2l_refuses_an_image_without_the_slave_and_bad_arguments(make_a2l, tmp_path, capsys) -> None:
    out = tmp_path / "x.a2l"
    assert make_a2l.main([shutil.which("true") or "/bin/true", str(out)]) == 1
    assert "defines no" in capsys.readouterr().err and not out.exists()
    assert make_a2l.main([str(tmp_path / "missing"), str(out)]) == 1
    assert "runner: no such file" in capsys.readouterr().err
    layout = make_a2l.read_layout()
    with pytest.raises(ValueError, match="port"):
        make_a2l.a2l_text(layout, {"rhonn_xcp_signals": 0, "rhonn_xcp_calibration": 600}, "127.0.0.1", 70000)
    with pytest.raises(ValueError, match="host"):
        make_a2l.a2l_text(layout, {"rhonn_xcp_signals": 0, "rhonn_xcp_calibration": 600}, "localhost", 5555)


# -- pyxcp against the runner during a replay ----------------------------------------------------------


def _wrong_key(resource: int, seed: bytes) -> bytes:
    key = bytearray(xcp_master.key(resource, seed))
    key[0] ^= 1
    return bytes(key)


@pytest.fixture()
def runner(runner_exe: Path, tmp_path: Path) -> Iterator[tuple[subprocess.Popen, int, int, Path]]:
    """The runner on udp_multicast with --xcp-udp on a free port: (process, group port, XCP port, the
    --json report it writes when stopped)."""
    port = free_port()
    report = tmp_path / "runner.json"
    proc = subprocess.Popen([str(runner_exe), "--udp-multicast", f"{UDP_GROUP}:{port}", "--duration", "120",
                             "--diag-period", "0", "--xcp-udp", "0", "--json", str(report)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        first = proc.stdout.readline()
        match = re.match(r"xcp: udp 127\.0\.0\.1:(\d+), A2L RHONN_LIM", first)
        assert match, (first, proc.stderr.read() if proc.poll() is not None else "")
        assert proc.stdout.readline().startswith("rhonn_runner: listening on udp_multicast")
        yield proc, port, int(match.group(1)), report
    finally:
        if proc.poll() is None:
            proc.terminate()
        out, err = proc.communicate(timeout=10)
        print(out, err)  # the runner's statistics, shown when the test fails


def _replay(bus: can.BusABC, frames: list[can.Message]) -> int:
    """Send the rig's Measurements one by one, each once its Estimate came back; the number answered."""
    return int(xcp_master.replay(bus, frames, ESTIMATE))


def test_pyxcp_watches_and_tunes_the_runner_during_a_replay(runner, a2l) -> None:
    proc, group_port, xcp_port, report = runner
    m = a2l["measurements"]
    app = create_application_from_config({"Transport": {"Eth": {"host": "127.0.0.1", "port": xcp_port,
                                                                "protocol": "UDP"}}})
    app.general.seed_n_key_function = _wrong_key
    app.general.disable_error_handling = True  # an error response raises, instead of pyxcp's retry policy
    app.transport.timeout = 10.0                # a loaded CI machine may answer late; never a lost answer
    set_application(app)
    weights = [(f"w{i}_{t}", m[f"w{i}_{t}"][0], 0, "F32") for i, t in WEIGHTS]
    health = [(f"{k}_{i}", m[f"{k}_{i}"][0], 0, "F32") for k in ("nis", "trace_p") for i in range(6)]
    meas = ("measurements", m["measurements"][0], 0, "U32")
    policy = xcp_master.Samples([DaqList(name="weights", event_num=0, stim=False, enable_timestamps=True,
                               measurements=[meas, *weights], priority=0, prescaler=1),
                       DaqList(name="health", event_num=0, stim=False, enable_timestamps=True,
                               measurements=[meas, *health], priority=0, prescaler=1)])
    frames = Scenario(duration=1600 * 3e-4, start=2.0, frame_loss=0.0, seed=5).build().frames()[:1600]
    bus = can.Bus(interface="udp_multicast", channel=UDP_GROUP, port=group_port, receive_own_messages=False)
    try:
        with Master("eth", config=app, policy=policy) as x:
            x.connect()
            assert x.identifier(1) == a2l["project"]
            # a wrong key: refused, and the slave disconnects (CONNECT again)
            with pytest.raises(XcpResponseError, match="ACCESS_LOCKED"):
                x.cond_unlock("calpag")
            x.connect()
            x.setMta(a2l["characteristics"]["learning"])
            with pytest.raises(XcpResponseError, match="ACCESS_LOCKED"):
                x.download(b"\x00")
            x.seed_n_key_function = xcp_master.key
            x.cond_unlock()
            assert not any(x.getCurrentProtectionStatus().values())
            local_port = x.transport.sock.getsockname()[1]
            # room for the DAQ stream while a loaded machine starves pyxcp's reader (capped by rmem_max)
            x.transport.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
            drops0 = xcp_master.udp_drops(local_port)

            policy.setup()
            policy.start()
            cal = a2l["characteristics"]
            answered = _replay(bus, frames[:600])
            gated_on = int.from_bytes(x.shortUpload(4, m["measurements"][0]), "little")
            x.setMta(cal["gate_0"])
            x.download(struct.pack("<6f", *[1e-30] * 6))  # every update gated: taken before the next step
            answered += _replay(bus, frames[600:1000])
            gated_off = int.from_bytes(x.shortUpload(4, m["measurements"][0]), "little")
            x.setMta(cal["gate_0"])
            x.download(bytes(24))                          # gates off again
            x.setMta(cal["trace_ceiling_3"])
            with pytest.raises(XcpResponseError, match="OUT_OF_RANGE"):
                x.download(struct.pack("<f", 1e-30))      # below trace P(0): the core refuses it
            x.download(struct.pack("<f", 1e30))
            answered += _replay(bus, frames[1000:1200])
            stepped_on = int.from_bytes(x.shortUpload(4, m["measurements"][0]), "little")
            x.setMta(cal["learning"])
            x.download(b"\x00")                            # learning off: taken before the next step
            answered += _replay(bus, frames[1200:])
            time.sleep(0.3)
            policy.stop()
            counters = {k: int.from_bytes(x.shortUpload(4, m[k][0]), "little")
                        for k in ("measurements", "events", "daq_dto_sent", "daq_dto_lost", "learning_state",
                                  "gated_0", "gated_5", "updates_0")}
            x.setMta(cal["trace_ceiling_3"])
            assert struct.unpack("<f", x.upload(4))[0] == np.float32(1e30)  # the page reads back what was taken
            x.setMta(a2l["characteristics"]["learning"])
            assert x.upload(1) == b"\x00"
            drops = xcp_master.udp_drops(local_port) - drops0
            x.disconnect()
    finally:
        bus.shutdown()
    # two more masters: while one is connected the other is not answered (counted), but its
    # CONNECT takes the session over, so a vanished master cannot lock everyone out
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as a, socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as b:
        def ask(sock: socket.socket, cmd: bytes) -> bytes | None:
            sock.settimeout(0.5)
            sock.sendto(struct.pack("<HH", len(cmd), 0) + cmd, ("127.0.0.1", xcp_port))
            try:
                return sock.recvfrom(64)[0][4:]
            except TimeoutError:
                return None

        assert ask(a, b"\xff\x00")[:1] == b"\xff"
        assert ask(b, b"\xfd") is None
        assert ask(b, b"\xff\x00")[:1] == b"\xff"
        assert ask(a, b"\xfd") is None
        assert ask(b, b"\xfd")[:3] == b"\xff\x00\x05"   # b's session: locked again

    proc.send_signal(signal.SIGINT)
    assert proc.wait(timeout=10) == 0
    side = json.loads(report.read_text())["xcp"]
    assert side["other_masters"] == 2 and side["takeovers"] == 1
    assert side["step_events"] == len(frames) and side["malformed"] == 0
    assert side["daq_dto_sent"] == counters["daq_dto_sent"]
    assert answered == len(frames) == counters["measurements"] == counters["events"]
    assert counters["learning_state"] == 0
    w_names = [w[0] for w in weights]
    h_names = [h[0] for h in health]
    by_list: dict[int, list[tuple[int, int, list[float]]]] = {0: [], 1: []}
    for daq_list, ts, values in policy.rows:
        names = w_names if daq_list == 0 else h_names
        by_list[daq_list].append((int(values["measurements"]), ts, [values[k] for k in names]))
    lost_reasons = counters["daq_dto_lost"] + drops
    for rows in by_list.values():
        steps = [r[0] for r in rows]
        assert steps == sorted(set(steps))                    # once each, in order
        # every step's sample arrived, or a packet of it was lost and counted (by the slave or the
        # master's receive queue; each missing sample lost at least one)
        missing = len(frames) - len(steps)
        assert missing <= lost_reasons
        if lost_reasons == 0:
            assert steps == list(range(1, len(frames) + 1))  # DAQ ran from the first step to the last
        stamps = [r[1] for r in rows]
        assert all(b > a for a, b in zip(stamps, stamps[1:]))  # the slave's 1 us step timestamps
    # learning on: the weights move; every update gated from step gated_on + 1 to gated_off: frozen,
    # each step's update counted as gated; gates off: they move again; learning off from
    # stepped_on + 1: frozen
    before = [r[2] for r in by_list[0] if r[0] <= gated_on]
    gated = [r[2] for r in by_list[0] if gated_on <= r[0] <= gated_off]
    moving = [r[2] for r in by_list[0] if gated_off < r[0] <= stepped_on]
    after = [r[2] for r in by_list[0] if r[0] >= stepped_on]
    assert len({tuple(w) for w in before}) > 100
    assert len(gated) > 300 and all(w == gated[0] for w in gated)
    assert min(counters["gated_0"], counters["gated_5"]) > (gated_off - gated_on) // 2
    assert len({tuple(w) for w in moving}) > 50
    assert len(after) > 300 and all(w == after[0] for w in after)
    # the health list: trace P of every neuron positive
    assert all(all(v > 0 for v in r[2][6:]) for r in by_list[1])
