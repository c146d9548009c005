"""Record a stream of CAN FD frames for the firmware application on the
Cortex-M4 image (app_main.c), and the frames the host's firmware sends back.

    python firmware_sim/cortex_m4/make_frames.py OUT_DIR [--frames N] [--start SECONDS]
                                                 [--diag-period P]
    python firmware_sim/cortex_m4/make_frames.py OUT_DIR --identifier CFG.toml --dbc ID.dbc
                                                 --trajectory DATA.csv [--frames N]

With ``--identifier`` the stream is another identifier's (a config file and
the DBC ``pyrhonn export --dbc`` wrote for it): the recording's first N rows
as that DBC's Measurement frames, with a hold of the first state, a
DiagRequest, a gap of three lost frames and a repeated frame; the host side
is the twin built for that DBC (firmware_sim/tools/build_twin.py).

The stream is the LIM at the rig's period (0.3 ms, ``pyrhonn.plants.lim`` as
``pyrhonn hil`` simulates it, the voltages switching on at 2.0 s), sent as
Measurement frames with consecutive ``Seq``, and in it, at fixed fractions of
the stream, every other path of the application: a position hold (ValidQm
cleared), an authenticated DiagRequest, LearningOff and LearningOn, a repeated
frame, a gap of three lost frames, an out-of-range measurement, a frame with
an unknown identifier and an authenticated weight transfer (WeightsBegin, one
WeightLoad per neuron, WeightsCommit). Each frame is stamped with its
reception time (0.3 ms apart).

The host side is ``pyrhonn.firmware.FirmwareApp`` (``pyrhonn._fwapp``: the same
fw_app, fw_protocol, generated pack/unpack, fw_hal_mem and float32 core) on
the identifier the firmware is built with (the shipped config
``firmware-lim``, exported to firmware_sim/config/lim_identifier.h), on the
memory HAL's simulated clock: reading it advances it by ``TICK_NS``, so the
time fields of the Diagnostics frames are deterministic and compared too.

Writes into OUT_DIR:

frames.h
    the stream as C arrays, with the application's settings (app_main.c);
frames_expected.txt
    what the host's firmware did, in app_main.c's output format: one line
    ``F k STATUS`` per frame, then one ``T id len flags data`` per frame sent;
frames.json
    the kind of every frame (``measurement``, ``control``, ...) and the
    settings, for the cycle report.
"""
from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass
from pathlib import Path

import can
import numpy as np

from pyrhonn import atomic
from pyrhonn.firmware import (TEST_KEY, FirmwareApp, SecOCSender, control_message, database, measurement_message,
                              weight_load_messages)
from pyrhonn.plants import lim

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tools"))
from export_config import lim_config  # noqa: E402 - the firmware's identifier, one definition

PERIOD_NS = 300_000       #: the rig's period, and the application's deadline
TICK_NS = 1_000           #: the simulated clock's advance per read
UNKNOWN_ID = 0x7FF        #: received by no node of the protocol
DIAG_PERIOD = 100         #: accepted measurements per Diagnostics frame


@dataclass(frozen=True)
class Frame:
    kind: str
    can_id: int
    data: bytes
    time_ns: int


def _can_id(msg: can.Message) -> int:
    return msg.arbitration_id | (0x80000000 if msg.is_extended_id else 0)


def stream(n_frames: int, start: float) -> list[Frame]:
    """The recorded frames (the measurements and everything in between)."""
    period = PERIOD_NS * 1e-9
    k0 = int(round(start / period))
    traj = lim.simulate(dt=period, horizon=(k0 + n_frames) * period, inputs=lim.LimInput(start=2.0), holds=())
    X, U = traj.X[k0:k0 + n_frames], traj.U[k0:k0 + n_frames]
    valid = np.ones(X.shape, dtype=bool)
    valid[n_frames // 8:n_frames // 8 + max(1, n_frames // 20), 0] = False    # a position hold
    sender = SecOCSender(TEST_KEY) if TEST_KEY is not None else None
    if sender is None:
        raise SystemExit("make_frames: pyrhonn._fwapp was built with a provisioned key; the test key is needed")
    db = database()
    frames: list[Frame] = []
    live = host_app()  # the firmware so far: the weight transfer sends what it holds
    seq = 0
    extra = 0  # frames already sent in this period before its Measurement

    def add(kind: str, can_id: int, data: bytes, k: int) -> None:
        """A frame received in period k: the Measurement at k * PERIOD_NS,
        anything else a third of a period before it, 1 us apart."""
        nonlocal extra
        if kind == "measurement":
            frames.append(Frame(kind, can_id, data, k * PERIOD_NS))
            extra = 0
        else:
            frames.append(Frame(kind, can_id, data, k * PERIOD_NS - PERIOD_NS // 3 + extra * 1000))
            extra += 1
        live.clock_ns = frames[-1].time_ns
        live.handle_frame(can_id, data, now_ns=frames[-1].time_ns)

    def msg(kind: str, m: can.Message, k: int) -> None:
        add(kind, _can_id(m), bytes(m.data), k)

    def at(fraction: float) -> int:
        return int(fraction * n_frames)

    events = {at(0.2): "diag", at(0.25): "repeat", at(0.3): "gap", at(0.4): "range", at(0.45): "unknown",
              at(0.5): "weights", at(0.6): "learning_off", at(0.7): "learning_on"}
    for k in range(n_frames):
        event = events.get(k) if k > 0 else None
        if event == "gap":
            seq += 3                                      # three frames lost on the way
        meas = measurement_message(seq & 0xFFFF, X[k], U[k], valid[k])
        if event == "diag":
            msg("control", control_message("DiagRequest", token=7, sender=sender), k)
        elif event == "repeat":
            msg("measurement_repeat", measurement_message((seq - 1) & 0xFFFF, X[k - 1], U[k - 1], valid[k - 1]), k)
        elif event == "range":
            raw = db.decode_message("Measurement", bytes(meas.data), scaling=False, decode_choices=False)
            raw["V"] = 2 ** 15 - 1                        # 3.2767 m/s, past the accepted 3 m/s
            add("measurement_range", meas.arbitration_id,
                bytes(db.encode_message("Measurement", raw, scaling=False, strict=False)), k)
        elif event == "unknown":
            add("unknown_id", UNKNOWN_ID, bytes(meas.data[:8]), k)
        elif event == "weights":                          # half the weights the firmware holds now
            weights = [np.float32(0.5) * live.get_weights(i).astype(np.float32) for i in range(X.shape[1])]
            msg("control", control_message("WeightsBegin", token=1, sender=sender), k)
            for m in weight_load_messages(weights, sender=sender):
                msg("weight_load", m, k)
            msg("control", control_message("WeightsCommit", token=2, sender=sender), k)
        elif event in ("learning_off", "learning_on"):
            msg("control", control_message("LearningOff" if event == "learning_off" else "LearningOn", token=k & 0xFF,
                                           sender=sender), k)
        msg("measurement", meas, k)
        seq += 1
    return frames


def identifier_stream(n_frames: int, config_file, protocol, trajectory: Path) -> list[Frame]:
    """Another identifier's stream (see the module docstring): the recording's first ``n_frames`` rows."""
    from pyrhonn.datafile import read_data

    data = read_data(trajectory, config_file, config_source="the identifier's trajectory")
    if data.X.shape[0] < n_frames + 4:
        raise SystemExit(f"make_frames: {trajectory} has {data.X.shape[0]} rows; --frames {n_frames} needs "
                         f"{n_frames + 4}")
    sender = SecOCSender(TEST_KEY) if TEST_KEY is not None else None
    if sender is None:
        raise SystemExit("make_frames: pyrhonn._fwapp was built with a provisioned key; the test key is needed")
    valid = np.ones(data.X.shape, dtype=bool)
    valid[n_frames // 8:n_frames // 8 + max(1, n_frames // 20), 0] = False    # a hold of the first state
    frames: list[Frame] = []
    seq = 0
    for k in range(n_frames):
        if k == n_frames // 5:
            m = control_message("DiagRequest", token=7, sender=sender)
            frames.append(Frame("control", _can_id(m), bytes(m.data), k * PERIOD_NS - PERIOD_NS // 3))
        if k == n_frames // 4:
            m = protocol.measurement_message((seq - 1) & 0xFFFF, data.X[k - 1], data.U[k - 1], valid[k - 1])
            frames.append(Frame("measurement_repeat", _can_id(m), bytes(m.data), k * PERIOD_NS - PERIOD_NS // 3))
        if k == int(0.3 * n_frames):
            seq += 3                                      # three frames lost on the way
        m = protocol.measurement_message(seq & 0xFFFF, data.X[k], data.U[k], valid[k])
        frames.append(Frame("measurement", _can_id(m), bytes(m.data), k * PERIOD_NS))
        seq += 1
    return frames


def host_app(config=None, protocol=None) -> FirmwareApp:
    """The host's firmware as the M4 image runs it: the firmware's
    identifier (or ``config`` on ``protocol``), deadline and diagnostics
    period, the simulated clock."""
    app = FirmwareApp(None, lim_config() if config is None else config, deadline_ns=PERIOD_NS,
                      diag_period=DIAG_PERIOD, host_clock=False, protocol=protocol)
    app.tick_ns = TICK_NS
    return app


def replay(frames: list[Frame], config=None, protocol=None) -> str:
    """The host's output for the stream, in app_main.c's format."""
    app = host_app(config, protocol)
    lines = []
    for k, f in enumerate(frames):
        app.clock_ns = f.time_ns
        replies = app.handle_frame(f.can_id, f.data, now_ns=f.time_ns)
        lines.append(f"F {k} {app.last_status}")
        for r in replies:
            flags = (1 if r.is_fd else 0) | (2 if r.bitrate_switch else 0)
            lines.append(f"T {_can_id(r):x} {len(r.data)} {flags} {bytes(r.data).hex()}")
    return "\n".join(lines) + "\n"


def header(frames: list[Frame]) -> str:
    def row(f: Frame) -> str:
        return "{" + ", ".join(f"0x{b:02x}" for b in f.data) + "}" if f.data else "{0}"

    return "\n".join([
        "/* Generated by firmware_sim/cortex_m4/make_frames.py: do not edit. */",
        "#ifndef FRAMES_H",
        "#define FRAMES_H",
        "#include <stdint.h>",
        f"#define FRAMES_N {len(frames)}u",
        f"#define FRAMES_DEADLINE_NS {PERIOD_NS}u",
        f"#define FRAMES_DIAG_PERIOD {DIAG_PERIOD}u",
        f"#define FRAMES_TICK_NS {TICK_NS}u",
        "static const uint32_t frame_id[FRAMES_N] = {" + ", ".join(f"0x{f.can_id:x}u" for f in frames) + "};",
        "static const uint8_t frame_len[FRAMES_N] = {" + ", ".join(str(len(f.data)) for f in frames) + "};",
        "static const uint64_t frame_time_ns[FRAMES_N] = {" + ", ".join(f"{f.time_ns}u" for f in frames) + "};",
        "static const uint8_t frame_data[FRAMES_N][64] = {\n    " + ",\n    ".join(row(f) for f in frames) + "\n};",
        "#endif",
        "",
    ])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path, help="folder to write frames.h, frames_expected.txt and frames.json into")
    ap.add_argument("--frames", type=int, default=1000, help="Measurements in the stream (default 1000, at least 20)")
    ap.add_argument("--start", type=float, default=2.0, help="time of the first measurement in s (default 2.0)")
    ap.add_argument("--identifier", type=Path, help="another identifier's config file (float32); with --dbc and "
                                                    "--trajectory")
    ap.add_argument("--dbc", type=Path, help="the DBC pyrhonn export --dbc wrote for it")
    ap.add_argument("--trajectory", type=Path, help="its recording (t, the config's states and inputs)")
    args = ap.parse_args(argv)
    if args.frames < 20:
        ap.error(f"--frames: at least 20, got {args.frames}")
    if not 0.0 <= args.start <= 100.0:
        ap.error(f"--start: expected 0..100 s, got {args.start}")
    given = [args.identifier, args.dbc, args.trajectory]
    if any(g is not None for g in given) and any(g is None for g in given):
        ap.error("--identifier, --dbc, --trajectory: give all three, or none for the LIM")
    config = protocol = None
    if args.identifier is not None:
        from build_twin import protocol as twin_protocol   # firmware_sim/tools, on the path above

        from pyrhonn.configfile import load_config

        try:
            config_file = load_config(args.identifier)
            protocol = twin_protocol(args.dbc)
        except (OSError, ValueError) as exc:
            ap.error(str(exc))
        config = config_file.config
        frames = identifier_stream(args.frames, config_file, protocol, args.trajectory)
    else:
        frames = stream(args.frames, args.start)
    args.out.mkdir(parents=True, exist_ok=True)
    atomic.write_text(args.out / "frames.h", header(frames))
    atomic.write_text(args.out / "frames_expected.txt", replay(frames, config, protocol))
    atomic.write_text(args.out / "frames.json", json.dumps({
        "kinds": [f.kind for f in frames], "period_ns": PERIOD_NS, "tick_ns": TICK_NS, "diag_period": DIAG_PERIOD,
        "start_s": args.start}, indent=1) + "\n")
    print(f"wrote {args.out}: {len(frames)} frames ({args.frames} measurements from t = {args.start} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
