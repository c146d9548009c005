"""XCP on CAN FD in the Linux runner (``--xcp-can IFACE[,CMD_ID,RES_ID]``) and
its A2L (``make_a2l.py --can CMD_ID,RES_ID``).

On the host (fast): the runner refuses bad ``--xcp-can`` arguments with a
message naming the field, before it opens anything; the A2L's IF_DATA XCP
holds XCP_ON_CAN with its CAN_FD block, read back by pya2ldb; make_a2l
refuses bad identifiers.

In the VM tier (marked vcan, on vcan0): pyxcp's CAN transport over
python-can's socketcan bus connects to the runner, which shares vcan0 with
the replayed Measurements; GET_ID is the A2L's name, a wrong key is refused,
and a DAQ list on the step event delivers one sample per step of a short
replay.
"""
from __future__ import annotations

import json
import re
import shutil
import signal
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from a2l_read import read_a2l
from source_scripts import load_script  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
FW = ROOT / "firmware_sim"
CMD_ID, RES_ID = 0x7F0, 0x7F1  # the runner's defaults


@pytest.fixture(scope="module")
def runner_exe(tmp_path_factory: pytest.TempPathFactory) -> Path:
    if shutil.which("cc") is None and shutil.which("gcc") is None:
        pytest.skip("no C compiler to build rhonn_runner")
    build = load_script(FW / "linux" / "build_runner.py", "_build_runner_xcp_can")
    exe: Path = build.cached(tmp_path_factory.getbasetemp() / "runner-cache")
    return exe


@pytest.fixture(scope="module")
def make_a2l() -> Any:
    return load_script(FW / "tools" / "make_a2l.py", "_make_a2l_can")


# -- the runner's arguments (host) ---------------------------------------------------------------------


@pytest.mark.parametrize(("spec", "message"), [
    ("", "--xcp-can takes IFACE[,CMD_ID,RES_ID] with a CAN interface name of 1..15 characters"),
    (",0x7F0,0x7F1", "with a CAN interface name of 1..15 characters"),
    ("can_interface_name0", "with a CAN interface name of 1..15 characters"),
    ("vcan0,0x7F0", "takes IFACE or IFACE,CMD_ID,RES_ID (both identifiers)"),
    ("vcan0,1,2,3", "takes IFACE or IFACE,CMD_ID,RES_ID (both identifiers)"),
    ("vcan0,0x800,0x7F1", "CMD_ID must be an 11-bit identifier (0..0x7FF"),
    ("vcan0,-1,0x7F1", "CMD_ID must be an 11-bit identifier"),
    ("vcan0,0x7F0,12x", "RES_ID must be an 11-bit identifier"),
    ("vcan0,0x7F0,0x", "RES_ID must be an 11-bit identifier"),
    ("vcan0,0x7F0,2032", "CMD_ID and RES_ID must differ, both are 0x7F0"),
    ("vcan0,0x100,0x7F1", "CMD_ID 0x100 is one of the application's identifiers"),
    ("vcan0,0x7F0,0x131", "RES_ID 0x131 is one of the application's identifiers"),
])
def test_runner_refuses_a_bad_xcp_can_argument_before_it_starts(runner_exe: Path, tmp_path: Path, spec: str,
                                                                 message: str) -> None:
    report = tmp_path / "runner.json"
    proc = subprocess.run([str(runner_exe), "--bus-less", "--cycles", "1", "--xcp-can", spec, "--json", str(report)],
                          capture_output=True, text=True, timeout=30)
    assert proc.returncode == 2, proc.stderr
    assert message in proc.stderr
    assert not report.exists()  # refused while parsing: nothing opened, nothing written


def test_runner_serves_one_xcp_transport_and_names_a_missing_can_interface(runner_exe: Path) -> None:
    both = subprocess.run([str(runner_exe), "--bus-less", "--cycles", "1", "--xcp-udp", "0", "--xcp-can", "vcan0"],
                          capture_output=True, text=True, timeout=30)
    assert both.returncode == 2 and "give --xcp-udp or --xcp-can, not both" in both.stderr
    missing = subprocess.run([str(runner_exe), "--bus-less", "--cycles", "1", "--xcp-can", "nosuchcan7"],
                             capture_output=True, text=True, timeout=30)
    assert missing.returncode == 1
    # without SocketCAN (this kernel, maybe) or without the interface: either is named
    assert "no SocketCAN" in missing.stderr or "no CAN interface named 'nosuchcan7'" in missing.stderr


# -- the A2L (host) ------------------------------------------------------------------------------------


def test_the_a2l_describes_xcp_on_can_fd_and_pya2ldb_reads_it(runner_exe: Path, make_a2l: Any,
                                                               tmp_path: Path) -> None:
    out = tmp_path / "rhonn_lim_can.a2l"
    assert make_a2l.main([str(runner_exe), str(out), "--can", "0x7F0,2033", "--can-data-bitrate", "5000000"]) == 0
    read = read_a2l(out)
    xcp = read["if_data"]["XCP"][0]
    learning = read["characteristics"]["learning"]
    assert "XCP_ON_UDP_IP" not in xcp
    version, params = xcp["XCP_ON_CAN"]
    assert version == 0x0104
    assert params["CAN_ID_MASTER"] == CMD_ID and params["CAN_ID_SLAVE"] == RES_ID
    assert params["BAUDRATE"] == 500_000
    assert params["CAN_FD"] == [{"MAX_DLC": 64, "CAN_FD_DATA_TRANSFER_BAUDRATE": 5_000_000}]
    assert xcp["PROTOCOL_LAYER"][8:10] == [64, 64]  # MAX_CTO, MAX_DTO: one CAN FD frame each
    # the rest of the A2L is the same as for UDP
    syms = make_a2l.symbol_addresses(runner_exe)
    assert learning == syms["rhonn_xcp_calibration"]


@pytest.mark.parametrize(("argv", "message"), [
    (["--can", "0x7F0"], "takes CMD_ID,RES_ID"),
    (["--can", "0x7F0,x1"], "RES_ID 'x1' is not a number"),
    (["--can", "0x800,0x7F1"], "cmd_id: 2048 is not an 11-bit CAN identifier"),
    (["--can", "0x7F1,0x7F1"], "they must differ"),
    (["--can", "0x7F0,0x101"], "res_id: 0x101 is the application's Estimate frame"),
    (["--can", "0x7F0,0x7F1", "--can-bitrate", "0"], "bitrate: 0 is not a bit rate"),
    (["--can", "0x7F0,0x7F1", "--port", "5555"], "XCP on CAN has no --host or --port"),
])
def test_make_a2l_refuses_bad_can_identifiers_and_writes_nothing(runner_exe: Path, make_a2l: Any, tmp_path: Path,
                                                                 capsys: pytest.CaptureFixture[str],
                                                                 argv: list[str], message: str) -> None:
    out = tmp_path / "x.a2l"
    assert make_a2l.main([str(runner_exe), str(out), *argv]) == 1
    assert message in capsys.readouterr().err
    assert not out.exists()


# -- pyxcp over vcan0 (VM tier) ------------------------------------------------------------------------


@pytest.fixture()
def can_runner(vcan0: str, runner: Path, tmp_path: Path) -> Iterator[tuple[subprocess.Popen[str], Path]]:
    """The runner (conftest's: the CMake build in the VM tier) on vcan0 with XCP on the same
    interface, default identifiers: (process, --json report)."""
    report = tmp_path / "runner.json"
    proc = subprocess.Popen([str(runner), "--interface", vcan0, "--xcp-can", vcan0, "--duration", "300",
                             "--diag-period", "0", "--json", str(report)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None
        first = proc.stdout.readline()
        assert re.match(rf"xcp: can {vcan0}, command 0x7F0, response 0x7F1, A2L RHONN_LIM", first), \
            (first, proc.stderr.read() if proc.poll() is not None and proc.stderr else "")
        assert proc.stdout.readline().startswith(f"rhonn_runner: listening on socketcan {vcan0}")
        yield proc, report
    finally:
        if proc.poll() is None:
            proc.terminate()
        out, err = proc.communicate(timeout=30)
        print(out, err)  # the runner's statistics, shown when the test fails


@pytest.mark.vcan
def test_pyxcp_over_can_fd_counts_one_daq_sample_per_replayed_step(can_runner: tuple[subprocess.Popen[str], Path],
                                                                   runner: Path, make_a2l: Any) -> None:
    can = pytest.importorskip("can")
    pytest.importorskip("pyxcp")
    from pyxcp import Master
    from pyxcp.config import create_application_from_config, set_application
    from pyxcp.daq_stim import DaqList
    from pyxcp.types import XcpResponseError

    from hil.scenario import Scenario
    from pyrhonn.firmware import database

    xcp_master = load_script(FW / "tools" / "xcp_master.py", "_xcp_master_can")
    proc, report = can_runner
    estimate = database().get_message_by_name("Estimate").frame_id
    at = make_a2l.symbol_addresses(runner)
    off = make_a2l.read_layout().signal_offsets
    sig = at["rhonn_xcp_signals"]
    steps_at, w_at = sig + off["measurements"], sig + off["weights"]

    def wrong_key(resource: int, seed: bytes) -> bytes:
        key = bytearray(xcp_master.key(resource, seed))
        key[0] ^= 1
        return bytes(key)

    app = create_application_from_config({"Transport": {"CAN": {
        "interface": "socketcan", "channel": "vcan0", "fd": True, "can_id_master": CMD_ID,
        "can_id_slave": RES_ID}}})
    assert (app.transport.can.interface, app.transport.can.fd) == ("socketcan", True)  # pyxcp took the keys
    app.general.seed_n_key_function = wrong_key
    app.general.disable_error_handling = True  # an error response raises, instead of pyxcp's retry policy
    app.transport.timeout = 10.0                # software emulation answers late; never a lost answer
    set_application(app)
    policy = xcp_master.Samples([DaqList(name="w", event_num=0, stim=False, enable_timestamps=True, priority=0,
                                         prescaler=1, measurements=[("measurements", steps_at, 0, "U32"),
                                                                    ("w0_0", w_at, 0, "F32")])])
    n = 120
    frames = Scenario(duration=n * 3e-4, start=0.0, frame_loss=0.0, seed=5).build().frames()[:n]
    bus = can.Bus(interface="socketcan", channel="vcan0", fd=True,
                  can_filters=[{"can_id": estimate, "can_mask": 0x7FF}])
    try:
        with Master("can", config=app, policy=policy) as x:
            x.connect()
            assert x.identifier(1) == "RHONN_LIM"
            with pytest.raises(XcpResponseError, match="ACCESS_LOCKED"):
                x.cond_unlock("daq")                   # a wrong key: refused, and the slave disconnects
            x.connect()
            x.seed_n_key_function = xcp_master.key
            x.cond_unlock()
            assert not any(x.getCurrentProtectionStatus().values())
            policy.setup()
            policy.start()
            answered = xcp_master.replay(bus, frames, estimate, timeout=10.0)  # one step a frame
            time.sleep(0.5)
            policy.stop()
            counters = {k: int.from_bytes(x.shortUpload(4, sig + off[k]), "little")
                        for k in ("measurements", "events", "daq_dto_sent", "daq_dto_lost")}
            x.disconnect()
    finally:
        bus.shutdown()
    proc.send_signal(signal.SIGTERM)
    assert proc.wait(timeout=30) == 0
    stats = json.loads(report.read_text())
    side = stats["xcp"]
    assert side["transport"] == "can" and side["interface"] == "vcan0"
    assert (side["cmd_id"], side["res_id"]) == (CMD_ID, RES_ID)
    assert side["malformed"] == 0 and side["send_errors"] == 0 and side["errors"] >= 1  # the wrong key
    assert side["bus_skipped"] > 0 and stats["rejected"] == 0  # XCP's frames never reached the application
    assert answered == n == counters["measurements"] == counters["events"] == side["step_events"]
    assert counters["daq_dto_lost"] == 0 and counters["daq_dto_sent"] == side["daq_dto_sent"] > 0
    steps = [int(values["measurements"]) for _, _, values in policy.rows]
    print(f"{len(steps)} DAQ samples for {n} steps, {counters['daq_dto_sent']} DTOs sent")
    assert steps == list(range(1, n + 1))  # one sample per step, from the first to the last, none lost
