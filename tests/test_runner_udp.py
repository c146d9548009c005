"""firmware_sim's Linux runner on python-can's udp_multicast bus (no CAN
needed): the C msgpack codec (firmware_sim/linux/udp_can.c) against
python-can's own pack_message / unpack_message, malformed datagrams, and the
runner serving the HIL rig.

- The C encoder writes exactly python-can's bytes, and python-can's strict
  unpack accepts them; every message python-can packs, and the same map
  written any other valid msgpack way, decodes in C to the same fields.
- Whatever the C decoder accepts, python-can accepts with the same fields;
  malformed datagrams are rejected with their reason, never crash, and the
  runner counts them and keeps answering with estimates byte-identical to
  the Python twin of the firmware.
- The runner's options and failures are clear (exit 2 / exit 1), hil's
  udp_multicast transport starts it by default, and --fifo reaches it.
"""
from __future__ import annotations

import json
import math
import os
import random
import shutil
import signal
import struct
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from source_scripts import load_script  # noqa: E402
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

can = pytest.importorskip("can")
msgpack = pytest.importorskip("msgpack")

from can.interfaces.udp_multicast.bus import GeneralPurposeUdpMulticastBus  # noqa: E402
from can.interfaces.udp_multicast.utils import pack_message, unpack_message  # noqa: E402

from pyrhonn import firmware  # noqa: E402
from pyrhonn.cli import main as pyrhonn_main  # noqa: E402
from pyrhonn.firmware import FirmwareApp  # noqa: E402

from hil.scenario import Scenario  # noqa: E402
from hil.score import score  # noqa: E402
from hil import transport  # noqa: E402
from hil.transport import FirmwareUnavailable, UDP_GROUP, free_port, lim_config, run_replay, udp_runner  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
LINUX = ROOT / "firmware_sim" / "linux"
DB = firmware.database()
ID = {m.name: m.frame_id for m in DB.messages}
OWN = {ID["Estimate"], ID["ControlAck"], ID["Diagnostics"]}
KEYS = ("timestamp", "arbitration_id", "is_extended_id", "is_remote_frame", "is_error_frame", "channel", "dlc",
        "data", "is_fd", "bitrate_switch", "error_state_indicator")



# -- fixtures ---------------------------------------------------------------------------------------


def _build_runner():
    """firmware_sim/linux/build_runner.py as a module (skips without a C compiler)."""
    if shutil.which("cc") is None and shutil.which("gcc") is None:
        pytest.skip("no C compiler to build rhonn_runner")
    return load_script(LINUX / "build_runner.py", "_build_runner_udp")


@pytest.fixture(scope="session")
def runner_exe(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """rhonn_runner built from the current sources (never a stale build)."""
    return _build_runner().cached(tmp_path_factory.getbasetemp() / "runner-cache")


@pytest.fixture(scope="session")
def codec(tmp_path_factory: pytest.TempPathFactory):
    """udp_can.c compiled as a cffi module: (ffi, lib, status name)."""
    if shutil.which("cc") is None and shutil.which("gcc") is None:
        pytest.skip("no C compiler to build the codec")
    from cffi import FFI

    ffi = FFI()
    ffi.cdef("""
        typedef int... udp_can_status;
        typedef struct {
            double timestamp; uint32_t arbitration_id; uint8_t is_extended_id; uint8_t is_remote_frame;
            uint8_t is_error_frame; uint8_t is_fd; uint8_t bitrate_switch; uint8_t error_state_indicator;
            uint8_t dlc; uint8_t len; uint8_t data[64];
        } udp_can_msg;
        #define UDP_CAN_MAX_ENCODED ...
        udp_can_status udp_can_encode(const udp_can_msg *msg, uint8_t *out, size_t cap, size_t *written);
        udp_can_status udp_can_decode(const uint8_t *buf, size_t n, udp_can_msg *msg);
        const char *udp_can_status_name(udp_can_status status);
    """)
    ffi.set_source("_udp_can_under_test", '#include "udp_can.h"', sources=[str(LINUX / "udp_can.c")],
                   include_dirs=[str(LINUX)], extra_compile_args=["-std=c99"])
    out = tmp_path_factory.mktemp("codec")
    so = ffi.compile(tmpdir=str(out))
    module = load_script(Path(so), "_udp_can_under_test")

    def name(status: int) -> str:
        return module.ffi.string(module.lib.udp_can_status_name(status)).decode()

    return module.ffi, module.lib, name


def c_decode(codec, data: bytes) -> tuple[str, dict | None]:
    ffi, lib, name = codec
    m = ffi.new("udp_can_msg *")
    st_ = lib.udp_can_decode(data, len(data), m)
    if name(st_) != "ok":
        return name(st_), None
    return "ok", {"timestamp": m.timestamp, "arbitration_id": m.arbitration_id,
                  "is_extended_id": bool(m.is_extended_id), "is_remote_frame": bool(m.is_remote_frame),
                  "is_error_frame": bool(m.is_error_frame), "is_fd": bool(m.is_fd),
                  "bitrate_switch": bool(m.bitrate_switch), "error_state_indicator": bool(m.error_state_indicator),
                  "dlc": m.dlc, "data": bytes(ffi.buffer(m.data, m.len))}


def c_encode(codec, msg: can.Message) -> bytes:
    ffi, lib, name = codec
    m = ffi.new("udp_can_msg *")
    m.timestamp = msg.timestamp
    m.arbitration_id = msg.arbitration_id
    for k in ("is_extended_id", "is_remote_frame", "is_error_frame", "is_fd", "bitrate_switch",
              "error_state_indicator"):
        setattr(m, k, int(getattr(msg, k)))
    m.dlc = msg.dlc
    m.len = len(msg.data)
    ffi.memmove(m.data, bytes(msg.data), len(msg.data))
    out = ffi.new("uint8_t[]", lib.UDP_CAN_MAX_ENCODED)
    n = ffi.new("size_t *")
    status = name(lib.udp_can_encode(m, out, lib.UDP_CAN_MAX_ENCODED, n))
    assert status == "ok", status
    return bytes(ffi.buffer(out, n[0]))


def fields(msg: can.Message) -> dict:
    # A datagram may carry the timestamp as an integer: python-can keeps the int, the codec holds the
    # double it converts it to (rounded to nearest, as float() rounds; udp_can.h), the same seconds.
    return {"timestamp": float(msg.timestamp), "arbitration_id": msg.arbitration_id, "is_extended_id": msg.is_extended_id,
            "is_remote_frame": msg.is_remote_frame, "is_error_frame": msg.is_error_frame, "is_fd": msg.is_fd,
            "bitrate_switch": msg.bitrate_switch, "error_state_indicator": msg.error_state_indicator,
            "dlc": msg.dlc, "data": bytes(msg.data)}


# -- strategies ---------------------------------------------------------------------------------------


@st.composite
def can_messages(draw, channels: bool = True) -> can.Message:
    """Any message python-can's Message(check=True) accepts."""
    is_fd = draw(st.booleans())
    is_ext = draw(st.booleans())
    is_remote = False if is_fd else draw(st.booleans())
    is_error = False if is_remote else draw(st.booleans())
    if is_remote:
        data, dlc = b"", draw(st.integers(0, 8))
    else:
        data = draw(st.binary(max_size=64 if is_fd else 8))
        dlc = len(data)
    channel = None
    if channels:
        channel = draw(st.none() | st.text(max_size=40) | st.integers(-2 ** 63, 2 ** 64 - 1))
    return can.Message(timestamp=draw(st.floats(min_value=0.0, allow_nan=False, allow_infinity=False)),
                       arbitration_id=draw(st.integers(0, 0x1FFFFFFF if is_ext else 0x7FF)), is_extended_id=is_ext,
                       is_remote_frame=is_remote, is_error_frame=is_error, channel=channel, dlc=dlc, data=data,
                       is_fd=is_fd, bitrate_switch=is_fd and draw(st.booleans()),
                       error_state_indicator=is_fd and draw(st.booleans()), check=True)


def _be(v: int, n: int) -> bytes:
    return v.to_bytes(n, "big", signed=v < 0)


def alt_int(v: int, rnd: random.Random) -> bytes:
    """Any msgpack form that holds v (the test's own encoder, checked against msgpack)."""
    forms = []
    if 0 <= v < 0x80:
        forms.append(bytes([v]))
    if -32 <= v < 0:
        forms.append(bytes([v & 0xFF]))
    for code, n in ((0xCC, 1), (0xCD, 2), (0xCE, 4), (0xCF, 8)):
        if 0 <= v < 1 << (8 * n):
            forms.append(bytes([code]) + _be(v, n))
    for code, n in ((0xD0, 1), (0xD1, 2), (0xD2, 4), (0xD3, 8)):
        if -(1 << (8 * n - 1)) <= v < 1 << (8 * n - 1):
            forms.append(bytes([code]) + v.to_bytes(n, "big", signed=True))
    return rnd.choice(forms)


def alt_str(s: str, rnd: random.Random) -> bytes:
    b = s.encode()
    forms = [b"\xd9" + _be(len(b), 1), b"\xda" + _be(len(b), 2), b"\xdb" + _be(len(b), 4)]
    if len(b) < 32:
        forms.append(bytes([0xA0 | len(b)]))
    if len(b) > 255:
        forms = forms[1:]
    return rnd.choice(forms) + b


def alt_value(v, rnd: random.Random) -> bytes:
    if v is None:
        return b"\xc0"
    if isinstance(v, bool):
        return b"\xc3" if v else b"\xc2"
    if isinstance(v, int):
        return alt_int(v, rnd)
    if isinstance(v, float):
        f32 = struct.pack(">f", v) if abs(v) < 3e38 else None
        if f32 is not None and struct.unpack(">f", f32)[0] == v and rnd.random() < 0.5:
            return b"\xca" + f32
        return b"\xcb" + struct.pack(">d", v)
    if isinstance(v, str):
        return alt_str(v, rnd)
    if isinstance(v, (bytes, bytearray)):
        return rnd.choice([b"\xc4" + _be(len(v), 1), b"\xc5" + _be(len(v), 2), b"\xc6" + _be(len(v), 4)]) + bytes(v)
    raise TypeError(type(v))


def alt_pack(d: dict, rnd: random.Random) -> bytes:
    items = list(d.items())
    rnd.shuffle(items)
    n = len(items)
    out = rnd.choice([bytes([0x80 | n]), b"\xde" + _be(n, 2), b"\xdf" + _be(n, 4)])
    for k, v in items:
        out += alt_str(k, rnd) + alt_value(v, rnd)
    return out


def as_dict(msg: can.Message) -> dict:
    return msgpack.unpackb(pack_message(msg), raw=False)


# -- the codec against python-can ---------------------------------------------------------------------


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(msg=can_messages(channels=False))
def test_c_encoder_writes_python_cans_bytes_and_strict_unpack_accepts_them(codec, msg) -> None:
    blob = c_encode(codec, msg)
    assert blob == pack_message(msg)
    back = unpack_message(blob, check=True)
    assert fields(back) == fields(msg)


@settings(max_examples=300, deadline=None)
@given(msg=can_messages())
def test_every_message_python_can_packs_decodes_in_c_to_the_same_fields(codec, msg) -> None:
    status, got = c_decode(codec, pack_message(msg))
    assert status == "ok"
    assert got == fields(msg)


def test_an_integer_timestamp_past_2_53_decodes_to_the_seconds_python_can_reads(codec) -> None:
    d = as_dict(can.Message(timestamp=0.0, arbitration_id=0x101, data=b"\x01"))
    d["timestamp"] = 4800837202776949248  # not a double: python-can keeps the int
    blob = msgpack.packb(d)
    status, got = c_decode(codec, blob)
    assert status == "ok"
    assert got == fields(unpack_message(blob, check=True))
    assert got["timestamp"] == float(d["timestamp"]) and float(d["timestamp"]) != d["timestamp"]


@settings(max_examples=300, deadline=None)
@given(msg=can_messages(), rnd=st.randoms(use_true_random=False), int_timestamp=st.booleans())
def test_any_other_valid_msgpack_encoding_decodes_in_c_to_the_same_fields(codec, msg, rnd, int_timestamp) -> None:
    d = as_dict(msg)
    if int_timestamp and d["timestamp"] < 2 ** 53:  # an integer timestamp python-can takes as it is
        d["timestamp"] = int(d["timestamp"])
    blob = alt_pack(d, rnd)
    assert msgpack.unpackb(blob, raw=False) == d  # the test's encoder writes valid msgpack
    status, got = c_decode(codec, blob)
    assert status == "ok"
    assert got == fields(can.Message(**d, check=True))


def _mutations(draw, blob: bytes) -> bytes:
    b = bytearray(blob)
    for _ in range(draw(st.integers(1, 4))):
        op = draw(st.sampled_from(["set", "insert", "delete", "cut", "append"]))
        pos = draw(st.integers(0, max(len(b) - 1, 0)))
        if op == "set" and b:
            b[pos] = draw(st.integers(0, 255))
        elif op == "insert":
            b[pos:pos] = draw(st.binary(min_size=1, max_size=4))
        elif op == "delete" and b:
            del b[pos]
        elif op == "cut":
            del b[pos:]
        else:
            b += draw(st.binary(min_size=1, max_size=8))
    return bytes(b)


@settings(max_examples=1500, deadline=None)
@given(data=st.data(), msg=can_messages())
def test_whatever_c_accepts_python_can_accepts_with_the_same_fields(codec, data, msg) -> None:
    if data.draw(st.booleans()):
        blob = data.draw(st.binary(max_size=300))
    else:  # a valid datagram, damaged
        blob = _mutations(data.draw, pack_message(msg))
    status, got = c_decode(codec, blob)  # never crashes, whatever the bytes
    try:
        theirs = fields(unpack_message(blob, check=True))
    except Exception:  # noqa: BLE001 - python-can rejects it, any way
        theirs = None
    if status == "ok":
        assert theirs is not None and got == theirs
    elif theirs is not None:
        # python-can is laxer in a few documented ways: a missing key (its default), a duplicate
        # key (the last wins), a value of another type (an int for a bool...), an is_rx key
        assert status in ("missing", "duplicate", "type", "key"), status


def test_malformed_datagrams_are_rejected_with_their_reason(codec) -> None:
    msg = can.Message(timestamp=2.5, arbitration_id=0x100, is_extended_id=False, is_fd=True, bitrate_switch=True,
                      data=bytes(range(20)))
    good = pack_message(msg)
    d = as_dict(msg)
    rnd = random.Random(3)

    def packed(**change) -> bytes:
        return msgpack.packb({**d, **change}, use_bin_type=True)

    cases = [(good[:cut], "truncated") for cut in range(len(good))]
    cases += [
        (good + b"\xc0", "trailing"), (good + good, "trailing"),
        (b"\x93\x01\x02\x03", "not_map"), (b"\xc4\x01\x00", "not_map"),
        (packed(data=bytes(65)), "data_length"), (packed(data=bytes(300), dlc=20), "data_length"),
        (packed(dlc=19), "dlc"), (packed(dlc=65), "dlc"), (packed(dlc=-1), "dlc"),
        (packed(is_fd=False, bitrate_switch=False), "dlc"),
        (msgpack.packb({**d, 7: 1}), "key"), (msgpack.packb({**d, "is_rx": True}), "key"),
        (msgpack.packb({**d, b"dlc": 20}, use_bin_type=True), "key"),
        (msgpack.packb({k: v for k, v in d.items() if k != "is_fd"}, use_bin_type=True), "missing"),
        (b"\x8c" + good[1:] + b"\xa3dlc\x14", "duplicate"),
        (packed(arbitration_id=0x800), "id"), (packed(arbitration_id=-5), "id"),
        (packed(arbitration_id=1 << 40, is_extended_id=True), "id"),
        (packed(arbitration_id=256.0), "type"), (packed(is_fd=1), "type"), (packed(data="x" * 20), "type"),
        (packed(timestamp=None), "type"), (packed(channel=1.5), "type"), (packed(channel=[1]), "type"),
        (packed(timestamp=-1.0), "timestamp"), (packed(timestamp=math.nan), "timestamp"),
        (packed(timestamp=math.inf), "timestamp"),
        (packed(is_remote_frame=True), "flags"),
        (packed(is_remote_frame=True, is_fd=False, bitrate_switch=False, data=b"", dlc=0, is_error_frame=True), "flags"),
        (packed(is_fd=False, data=bytes(8), dlc=8), "flags"),
        (b"", "truncated"), (alt_pack(d, rnd)[:-1], "truncated"),
    ]
    for blob, reason in cases:
        assert c_decode(codec, blob)[0] == reason, (reason, blob)
        if reason not in ("missing", "duplicate", "key", "type"):  # python-can rejects all of these too
            with pytest.raises(Exception):  # noqa: B017 - whatever python-can raises
                unpack_message(blob, check=True)


# -- the runner ---------------------------------------------------------------------------------------


def _start(runner_exe: Path, port: int, *extra: str, report: Path | None = None) -> subprocess.Popen:
    cmd = [str(runner_exe), "--udp-multicast", f"{UDP_GROUP}:{port}", "--duration", "120", *extra]
    if report is not None:
        cmd += ["--json", str(report)]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    line = proc.stdout.readline()
    assert line.startswith("rhonn_runner: listening on udp_multicast"), (line, proc.stderr.read())
    return proc


def _measurements(n: int) -> list[can.Message]:
    plan = Scenario(duration=n * 3e-4, start=0.95, frame_loss=0.0, seed=1).build()
    return plan.frames()[:n]


def test_runner_counts_malformed_datagrams_by_reason_and_keeps_answering(runner_exe, tmp_path) -> None:
    port = free_port()
    report = tmp_path / "runner.json"
    frames = _measurements(60)
    twin = FirmwareApp(None, lim_config())
    expected = [bytes(m.data) for f in frames for m in twin.handle(f) if m.arbitration_id == ID["Estimate"]]
    good = pack_message(frames[0])
    d = as_dict(frames[0])
    bad = {
        "truncated": [good[:10], good[:-1], b""],
        "trailing": [good + b"\x00"],
        "data_length": [msgpack.packb({**d, "data": bytes(65)}, use_bin_type=True)],
        "dlc": [msgpack.packb({**d, "dlc": 3}, use_bin_type=True)],
        "key": [msgpack.packb({**d, "bogus": 1}, use_bin_type=True), msgpack.packb({1: 2})],
        "not_map": [b"\x01", b"hello"],
        "type": [msgpack.packb({**d, "is_fd": "yes"}, use_bin_type=True)],
        "oversized": [b"\x8b" + bytes(5000)],
    }
    proc = _start(runner_exe, port, report=report)
    got: list[bytes] = []
    bus = GeneralPurposeUdpMulticastBus(UDP_GROUP, port, 1)  # python-can's own socket, raw datagrams
    try:
        def collect(until: float) -> None:
            while time.monotonic() < until:
                r = bus.recv(0.01)
                if r is None:
                    continue
                try:
                    m = unpack_message(r[0], check=True)
                except Exception:  # noqa: BLE001 - our own malformed datagrams, handed back
                    continue
                if m.arbitration_id == ID["Estimate"]:
                    got.append(bytes(m.data))

        for k, frame in enumerate(frames):
            if k in (0, 30, 59):  # before, amid and at the end of the stream
                for blobs in bad.values():
                    for blob in blobs:
                        bus.send(blob)
            bus.send(pack_message(frame))
            collect(time.monotonic() + 0.003)
        collect(time.monotonic() + 1.0)
    finally:
        bus.shutdown()
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=30)
    assert proc.returncode == 0, err
    assert got == expected, f"{len(got)} estimates for {len(expected)}"
    stats = json.loads(report.read_text())
    udp = stats["udp"]
    want = {k: 3 * len(v) for k, v in bad.items() if k != "oversized"}
    assert {k: v for k, v in udp["malformed_by"].items() if v} == want
    assert udp["oversized"] == 3 * len(bad["oversized"])
    assert udp["malformed"] == 3 * sum(len(v) for v in bad.values())
    assert stats["frames_in"] == len(frames) and stats["rejected"] == 0 and stats["step_errors"] == 0
    assert udp["own_skipped"] == stats["frames_out"] == len(expected)
    assert stats["mode"] == "udp_multicast" and stats["rx"] == "arrival"
    assert "malformed 36" in out and "truncated=9" in out


@pytest.mark.parametrize("argv, message", [
    (["--udp-multicast", "10.0.0.1:5000"], "not an IPv4 multicast address"),
    (["--udp-multicast", "239.1.2.3"], "GROUP:PORT"),
    (["--udp-multicast", "239.1.2.3:0"], "port must be 1..65535"),
    (["--udp-multicast", "239.1.2.3:12x"], "port must be 1..65535"),
    (["--udp-multicast", "[ff15::1]"], "GROUP:PORT"),
    (["--udp-multicast", "[fe80::1]:5000"], "not an IPv6 multicast address"),
    (["--udp-multicast", "239.1.2.3:5000", "--bus-less"], "exactly one of"),
    (["--udp-multicast", "239.1.2.3:5000", "--rx", "sometimes"], "--rx takes tick or arrival"),
    (["--bus-less", "--rx", "arrival"], "needs a bus"),
    (["--bus-less", "--diag-period", "70000"], "--diag-period takes 0..65535"),
    (["--bus-less", "--spin-us", "20"], "--spin-us needs --rx arrival on a bus"),
    (["--udp-multicast", "239.1.2.3:5000", "--spin-us", "150"], "less than half the period"),
    (["--udp-multicast", "239.1.2.3:5000", "--spin-us", "-1"], "--spin-us takes"),
])
def test_runner_rejects_bad_udp_options_with_exit_2_and_a_reason(runner_exe, argv, message) -> None:
    out = subprocess.run([str(runner_exe), *argv, "--cycles", "10"], capture_output=True, text=True, timeout=30)
    assert out.returncode == 2 and message in out.stderr, out.stderr


@pytest.mark.parametrize("argv, message", [
    (["--fifo", "4294967297"], "--fifo takes a priority in 1..99"),      # was truncated to priority 1
    (["--fifo", "-4294967295"], "--fifo takes a priority in 1..99"),
    (["--cycles", " -1"], "--cycles must be a whole number"),               # was ULLONG_MAX cycles
    (["--cycles", "18446744073709551616"], "--cycles must be a whole number"),
    (["--cycles", "+5"], "--cycles must be a whole number"),
    (["--diag-period", "+5"], "--diag-period takes 0..65535"),
    (["--json", "/nonexistent-dir/x.json"], "--json: cannot write /nonexistent-dir/x.json"),
    (["--period-us", "300", "--period-us", "200"], "--period-us is given twice"),  # was: the last one wins
    (["--bus-less"], "--bus-less is given twice"),
    (["--cycles", "5"], "give --cycles or --duration, not both"),
])
def test_runner_refuses_counts_it_would_wrap_and_a_json_path_before_running(runner_exe, argv, message) -> None:
    out = subprocess.run([str(runner_exe), "--bus-less", "--duration", "2", *argv], capture_output=True, text=True,
                         timeout=30)
    assert out.returncode == 2 and message in out.stderr, out.stderr
    assert "cycles, SCHED" not in out.stdout  # refused before the run, not after it


def test_runner_reports_statistics_it_could_not_write(runner_exe) -> None:
    if not Path("/dev/full").exists():
        pytest.skip("no /dev/full here")
    out = subprocess.run([str(runner_exe), "--bus-less", "--cycles", "3", "--json", "/dev/full"], capture_output=True,
                         text=True, timeout=30)
    assert out.returncode == 1 and "--json: writing /dev/full failed" in out.stderr, out.stderr


def test_runner_without_a_network_exits_1_with_a_clear_message(runner_exe) -> None:
    """In a network namespace of its own (no interface up) the group cannot be joined."""
    unshare = shutil.which("unshare")
    if unshare is None or subprocess.run([unshare, "-n", "true"], capture_output=True).returncode != 0:
        pytest.skip("cannot make a network namespace here (unshare -n)")
    out = subprocess.run([unshare, "-n", str(runner_exe), "--udp-multicast", f"{UDP_GROUP}:{free_port()}",
                          "--cycles", "10"], capture_output=True, text=True, timeout=30)
    assert out.returncode == 1
    assert f"cannot open the udp_multicast group {UDP_GROUP}" in out.stderr and "IP_ADD_MEMBERSHIP" in out.stderr


def test_runner_on_an_ipv6_group_answers_python_can(runner_exe) -> None:
    group, port = "ff15::7079:7468", free_port()
    try:
        bus = can.Bus(interface="udp_multicast", channel=group, port=port, fd=True)
    except (OSError, can.CanError) as exc:
        pytest.skip(f"no IPv6 multicast here: {exc}")
    proc = subprocess.Popen([str(runner_exe), "--udp-multicast", f"[{group}]:{port}", "--duration", "60"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().startswith("rhonn_runner: listening"), proc.stderr.read()
        got = []
        for frame in _measurements(5):
            bus.send(frame)
            end = time.monotonic() + 1.0
            while time.monotonic() < end:
                m = bus.recv(0.05)
                if m is not None and m.arbitration_id == ID["Estimate"]:
                    got.append(m)
                    break
        assert len(got) == 5
    finally:
        bus.shutdown()
        proc.send_signal(signal.SIGTERM)
        proc.communicate(timeout=30)
    assert proc.returncode == 0


# -- hil over the runner --------------------------------------------------------------------------------


def _answered_or_counted_lost(frames: dict) -> int:
    """Cycles answered, or lost on a full receive queue and counted (a busy host's kernel may drop datagrams;
    hil.accounting), when no frame loss is injected."""
    return (frames["answered"] + frames["lost_to_firmware"] + frames["rejected_after_loss"]
            + frames["lost_from_firmware"])


def test_a_replay_over_udp_multicast_defaults_to_the_c_runner_and_reports_its_side(runner_exe) -> None:
    sc = Scenario(duration=0.3, start=0.9, frame_loss=0.0, seed=2)  # 1000 cycles
    rec = run_replay(sc, "udp_multicast", runner=str(runner_exe))
    side = rec.meta["firmware_side"]
    assert side["returncode"] == 0
    stats = side["stats"]
    assert stats["mode"] == "udp_multicast" and stats["frames_in"] >= sc.cycles
    assert side["handling_us"]["n"] >= 1 and side["handling_us"]["max"] >= side["handling_us"]["min"] > 0
    r = score(rec)
    assert r["frames"]["accounted"] and _answered_or_counted_lost(r["frames"]) == sc.cycles
    # Diagnostics on request only, as the Python node: the final one's StepTimeMax spans the whole run
    # (with one every 1000 measurements it would span none of it)
    assert r["firmware"]["step_time_max_us"] > 0
    # it busy-polls around the frames due, and only there (at most 2 x 50 us of every 300 us)
    assert stats["spin_us"] == 50 and 0 < stats["spin_share"] < 0.4


def test_the_firmware_choice_is_validated() -> None:
    sc = Scenario(duration=0.03)
    with pytest.raises(ValueError, match="rhonn_runner cannot join it"):
        run_replay(sc, "virtual", firmware="runner")
    with pytest.raises(ValueError, match="firmware: expected one of runner, python"):
        run_replay(sc, "udp_multicast", firmware="c")
    with pytest.raises(FirmwareUnavailable, match="not an executable file"):
        run_replay(sc, "udp_multicast", firmware="runner", runner="/nonexistent/rhonn_runner")


def test_without_firmware_sources_the_default_falls_back_to_the_python_node_and_says_so(tmp_path, monkeypatch,
                                                                                         capsys) -> None:
    import hil.transport as transport

    monkeypatch.setattr(transport, "ROOT", tmp_path)  # an installed hil: no firmware_sim/ beside it,
    monkeypatch.chdir(tmp_path)                        # nor in the current directory
    sc = Scenario(duration=0.06, start=1.95, seed=3)
    rec = run_replay(sc, "udp_multicast")
    side = rec.meta["firmware_side"]
    assert side["firmware"] == "hil.firmware_node" and "rhonn_runner unavailable" in side["fallback"]
    f = score(rec)["frames"]
    assert f["accounted"] and _answered_or_counted_lost(f) == sc.cycles
    with pytest.raises(FirmwareUnavailable, match="no firmware_sim sources beside"):
        run_replay(sc, "udp_multicast", firmware="runner")  # asked for by name: no fallback
    assert pyrhonn_main(["hil", "replay", "--transport", "udp_multicast", "--duration", "0.06", "--start", "1.95"]) == 0
    captured = capsys.readouterr()
    assert "note: rhonn_runner unavailable" in captured.err and "firmware hil.firmware_node" in captured.out


def test_an_installed_hil_run_from_a_checkout_builds_the_runner_from_it(tmp_path, monkeypatch) -> None:
    import hil.transport as transport

    _build_runner()                                    # skips without a C compiler
    monkeypatch.setattr(transport, "ROOT", tmp_path)  # installed: nothing beside the package
    monkeypatch.chdir(LINUX.parents[1])               # but run from the source tree
    monkeypatch.setenv("PYRHONN_CACHE_DIR", str(tmp_path / "cache"))
    exe = Path(transport.udp_runner())
    assert exe.is_file() and tmp_path / "cache" in exe.parents


def test_cli_bench_and_replay_take_the_firmware_choice(runner_exe, capsys, cli_error) -> None:
    assert pyrhonn_main(["hil", "bench", "--transport", "udp_multicast", "--cycles", "400",
                         "--runner", str(runner_exe)]) == 0
    out = capsys.readouterr().out
    line = next(ln for ln in out.splitlines() if ln.startswith("firmware: handling per frame"))
    assert "not available" not in line
    assert pyrhonn_main(["hil", "replay", "--transport", "udp_multicast", "--firmware", "python", "--duration",
                         "0.06", "--start", "0.9"]) == 0
    assert "Identifier.run: equal" in capsys.readouterr().out
    for argv in (["hil", "bench", "--cycles", "10", "--firmware", "matlab"],
                 ["hil", "replay", "--transport", "virtual", "--firmware", "runner", "--duration", "0.03"],
                 ["hil", "replay", "--firmware", "runner", "--runner", "/nonexistent", "--duration", "0.03"]):
        cli_error(argv)


def test_bench_fifo_reaches_the_runner(runner_exe) -> None:
    # in a child process: SCHED_FIFO must not leak into the test session
    out = subprocess.run([sys.executable, "-m", "pyrhonn.cli", "hil", "bench", "--transport", "udp_multicast",
                          "--cycles", "300", "--fifo", "10", "--json", "--runner", str(runner_exe)],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    r = json.loads(out.stdout)
    runner_policy = r["firmware_side"]["stats"]["policy"]
    if r["policy"].startswith("SCHED_FIFO 10,"):
        assert runner_policy == "SCHED_FIFO"
    else:  # refused here (no CAP_SYS_NICE): the runner did not get it either
        assert runner_policy == "SCHED_OTHER"
    assert np.isfinite(r["latency_us"]["avg"])
    # on two CPUs or more the bench busy-polls (the runner never sleeps); on one it would take the rig's CPU
    spin = 149 if len(os.sched_getaffinity(0)) >= 2 else transport.RUNNER_SPIN_US
    assert r["firmware_side"]["stats"]["spin_us"] == spin
    assert f"runner busy-polls {spin:g} us" in r["policy"]
    assert r["host_steal"]["available"] in (True, False)


def test_the_runner_busy_poll_margin_is_passed_on_and_checked(runner_exe, cli_error) -> None:
    rec = run_replay(Scenario(duration=0.03, start=0.9), "udp_multicast", runner=str(runner_exe),
                     runner_spin_us=20)
    assert rec.meta["firmware_side"]["stats"]["spin_us"] == 20
    rec = run_replay(Scenario(duration=0.03, start=0.9), "udp_multicast", runner=str(runner_exe))
    assert rec.meta["firmware_side"]["stats"]["spin_us"] == transport.RUNNER_SPIN_US  # hil replay's default
    for bad in (-1, 150, float("nan"), True, "50"):
        with pytest.raises(ValueError, match="runner_spin_us"):
            run_replay(Scenario(duration=0.03), "udp_multicast", runner=str(runner_exe), runner_spin_us=bad)
    for argv in (["hil", "bench", "--cycles", "10", "--runner-spin-us", "150"],
                 ["hil", "replay", "--runner-spin-us", "x", "--duration", "0.03"]):
        assert "spin" in cli_error(argv), argv
    # no runner started here to take it (virtual, socketcan without --runner, the Python node): refused
    for bus in (["--transport", "virtual"], ["--transport", "socketcan"], ["--firmware", "python"]):
        for command in (["replay", "--duration", "0.03"], ["bench", "--cycles", "10"]):
            err = cli_error(["hil", *command, *bus, "--runner-spin-us", "20"])
            assert "--runner-spin-us: only for a rhonn_runner started here" in err, (bus, command)


def test_the_runner_build_is_cached_per_source_content(tmp_path) -> None:
    module = _build_runner()
    exe = module.cached(tmp_path)
    assert exe.is_file() and exe.parent.parent == tmp_path
    mtime = exe.stat().st_mtime_ns
    assert module.cached(tmp_path) == exe and exe.stat().st_mtime_ns == mtime  # reused, not rebuilt
    module.FLAGS = [*module.FLAGS, "-DPYRHONN_CACHE_TEST=1"]  # another build recipe: another build
    other = module.cached(tmp_path)
    assert other != exe and other.is_file()
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".building-")] == []
    assert udp_runner(exe) == str(exe)
