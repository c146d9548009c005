"""The XCP slave's cost and its DAQ stream over a long run.

1. Cortex-M4F (QEMU mps2-an386, firmware_sim/cortex_m4/xcp_main.c): the
   estimated cycles (firmware_sim/cortex_m4/cycles.py) and instructions of
   a Measurement frame (fw_app_on_frame) without the slave and with it,
   connected, with one DAQ list on the step event (the measurement counter,
   the 29 weights, NIS and trace P of every neuron: 3 ODTs) sampled inside
   the frame, and deferred (fw_xcp_set_deferred: the frame only notes the
   sample, fw_xcp_poll sends it after the frame, its cost counted apart), of
   the DAQ event inside the frame, and of one command of each kind
   (fw_xcp_on_command); the flash and RAM the slave adds (the image's map
   file, its structures' sizes).
2. Linux (rhonn_runner --bus-less --xcp-udp, pyxcp as the master): the
   weights and health by DAQ on every step for --steps steps (default
   100,000, 30 s at 0.3 ms): every step's sample received, or lost and
   counted (by the slave's transport, or by the master's receive queue:
   the kernel's drop count of its socket).

    python bench/bench_xcp.py [--steps 100000] [--frames 200] [--skip-m4] [--skip-linux] [--results]

``--results`` also writes the figures to bench/results/xcp.json, which the docs quote.
"""
from __future__ import annotations

import argparse
import json
import re
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
M4 = ROOT / "firmware_sim" / "cortex_m4"
BUDGET = 50_400  # cycles in 0.3 ms at 168 MHz
TARGET_SHARE = 0.15  # a Measurement frame with the DAQ list running: at most 15 % of the budget


def _m4(frames: int) -> dict:
    sys.path.insert(0, str(M4))
    import cycles
    import run_m4

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        run_m4.run([sys.executable, str(M4 / "make_vector.py"), str(out / "vector"), "--samples", "10"])
        run_m4.run([sys.executable, str(M4 / "make_frames.py"), str(out / "frames"), "--frames", str(frames)])
        build = out / "build"
        run_m4.build_m4(out / "vector", build, True, out / "frames", target="xcp_m4.elf")
        elf = build / "xcp_m4.elf"
        objs = run_m4.app_objects(build)
        xcp_obj = next((build / "CMakeFiles" / "fw_xcp_m4.dir").rglob("fw_xcp.c.obj"))
        counted = [*objs.values(), xcp_obj]
        harness = ("main", "feed", "command")
        report: dict = {}
        for mode in ("plain", "connected", "daq", "deferred"):
            est = cycles.estimate(elf, counted, "fw_app_on_frame", harness=harness, args=[mode, str(frames)])
            report[mode] = {"frames": est["calls"], "cycles_mean": est["estimated_cycles_per_call"],
                            "cycles_max": est["estimated_cycles_max"],
                            "instructions_mean": est["instructions_per_call"],
                            "by_function": est["cycles_per_call_by_function"]}
        # the step event (the hooks, the signals' refresh, the DTOs): what the slave adds to the same frames
        plain, daq = report["plain"], report["daq"]
        report["daq_event"] = {
            "cycles_mean": daq["cycles_mean"] - plain["cycles_mean"],
            "instructions_mean": daq["instructions_mean"] - plain["instructions_mean"],
            "by_function": {k: round(v - plain["by_function"].get(k, 0.0), 1) for k, v in daq["by_function"].items()
                            if abs(v - plain["by_function"].get(k, 0.0)) >= 1.0}}
        # the deferred sample, sent by fw_xcp_poll after each frame (outside the frame's deadline)
        est = cycles.estimate(elf, counted, "fw_xcp_poll", harness=harness, args=["deferred", str(frames)])
        report["deferred_poll"] = {"calls": est["calls"], "cycles_mean": est["estimated_cycles_per_call"],
                                   "cycles_max": est["estimated_cycles_max"],
                                   "instructions_mean": est["instructions_per_call"],
                                   "by_function": est["cycles_per_call_by_function"]}
        for mode in ("daq", "deferred"):
            report[mode]["cycles_max_share_of_budget"] = report[mode]["cycles_max"] / BUDGET
            report[mode]["target_share"] = TARGET_SHARE
            report[mode]["target_met"] = report[mode]["cycles_max"] <= TARGET_SHARE * BUDGET
        n_cmd = 500
        est = cycles.estimate(elf, counted, "fw_xcp_on_command", harness=harness, args=["commands", str(n_cmd)])
        each = est["cycles_each"][-n_cmd:]  # the set-up's commands (CONNECT, seed & key, DAQ lists) come first
        ins = est["instructions_each"][-n_cmd:]
        kinds = ("SHORT_UPLOAD 4 B", "SHORT_UPLOAD 56 B", "SET_MTA", "DOWNLOAD 1 B (learning)", "GET_STATUS")
        report["commands"] = {k: {"calls": len(each[i::5]), "cycles_mean": sum(each[i::5]) / len(each[i::5]),
                                  "cycles_max": max(each[i::5]),
                                  "instructions_mean": sum(ins[i::5]) / len(ins[i::5])} for i, k in enumerate(kinds)}
        setup = est["cycles_each"][:-n_cmd]
        report["set_up_commands"] = {"calls": len(setup), "cycles_max": max(setup)}
        text = run_m4.run([*run_m4.QEMU, "-kernel", str(elf)], timeout=300).stdout
        report["sizeof"] = {name: int(v) for name, v in re.findall(r"sizeof\((\w+)\) (\d+)", text)}
        foot = run_m4.map_footprint(build / "xcp_m4.map", ("fw_xcp", "fw_app"))
        report["fw_xcp_object"] = foot["fw_xcp"]
        report["fw_app_object"] = foot["fw_app"]
        report["fw_xcp_object_file"] = run_m4.sizes(xcp_obj)
        report["fw_app_object_file"] = run_m4.sizes(objs["fw_app"])
        # what the slave adds to the application (with XCP less without it)
        report["xcp_adds"] = {"flash_bytes": foot["fw_xcp"]["text"] + foot["fw_xcp"]["rodata"] + foot["fw_xcp"]["data"],
                              "ram_bytes": sum(report["sizeof"][k] for k in ("fw_xcp", "fw_xcp_signals",
                                                                             "fw_xcp_calibration"))}
    return report


def _linux(steps: int) -> dict:
    sys.argv[1:] = []  # pyxcp's application reads the command line: this script's options are not its own
    sys.path.insert(0, str(ROOT / "firmware_sim" / "linux"))
    sys.path.insert(0, str(ROOT / "firmware_sim" / "tools"))
    import build_runner
    import make_a2l
    import xcp_master
    from pyxcp import Master
    from pyxcp.config import create_application_from_config, set_application
    from pyxcp.daq_stim import DaqList

    exe = build_runner.cached()
    layout = make_a2l.read_layout()
    sig = make_a2l.symbol_addresses(exe)[make_a2l.SIGNALS_SYMBOL]
    off = layout.signal_offsets

    weights = [(f"w{i}_{t}", sig + off["weights"] + 4 * (i * layout.terms_capacity + t), 0, "F32")
               for i, n in enumerate(layout.n_terms) for t in range(n)]
    health = [(f"{k}_{i}", sig + off[k] + 4 * i, 0, "F32") for k in ("nis", "trace_p") for i in range(6)]
    meas = ("measurements", sig + off["measurements"], 0, "U32")
    policy = xcp_master.Samples([DaqList(name="weights", event_num=0, stim=False, enable_timestamps=True,
                            measurements=[meas, *weights], priority=0, prescaler=1),
                    DaqList(name="health", event_num=0, stim=False, enable_timestamps=True,
                            measurements=[meas, *health], priority=0, prescaler=1)])
    duration = steps * 3e-4 * 4 + 10.0  # room for a loaded host's skipped periods: the run stops at `steps`
    proc = subprocess.Popen([str(exe), "--bus-less", "--duration", f"{duration:.1f}", "--xcp-udp", "0"],
                            stdout=subprocess.PIPE, text=True)
    port = int(re.search(r":(\d+),", proc.stdout.readline()).group(1))
    app = create_application_from_config({"Transport": {"Eth": {"host": "127.0.0.1", "port": port,
                                                                "protocol": "UDP"}}})
    app.general.seed_n_key_function = xcp_master.key
    set_application(app)
    with Master("eth", config=app, policy=policy) as x:
        x.connect()
        x.cond_unlock()
        sock = x.transport.sock
        local = sock.getsockname()[1]
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 8 << 20)  # capped by net.core.rmem_max
        rcvbuf = sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
        drops0 = xcp_master.udp_drops(local)
        policy.setup()

        def stepped() -> int:
            return int.from_bytes(x.shortUpload(4, sig + off["measurements"]), "little")

        first = stepped()
        t0 = time.monotonic()
        policy.start()
        while stepped() - first < steps and proc.poll() is None:
            time.sleep(0.25)
        policy.stop()
        elapsed = time.monotonic() - t0
        during = stepped() - first
        time.sleep(0.5)
        counters = {k: int.from_bytes(x.shortUpload(4, sig + off[k]), "little")
                    for k in ("measurements", "daq_dto_sent", "daq_dto_lost")}
        drops = xcp_master.udp_drops(local) - drops0
        x.disconnect()
    proc.terminate()
    proc.wait(timeout=10)
    result: dict = {"seconds": round(elapsed, 2), "steps_with_daq": during, "master_rcvbuf_bytes": rcvbuf,
                    "dto_sent": counters["daq_dto_sent"],
                    "dto_refused_by_slave_transport": counters["daq_dto_lost"],
                    "datagrams_dropped_by_master_queue": drops}
    for lst, name in ((0, "weights (3 ODTs)"), (1, "health (1 ODT)")):
        got = [int(v["measurements"]) for d, _ts, v in policy.rows if d == lst]
        span = got[-1] - got[0] + 1 if got else 0
        result[name] = {"samples": len(got), "steps_spanned": span, "missing": span - len(set(got)),
                        "duplicates": len(got) - len(set(got))}
    return result


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=100_000, help="steps of the Linux DAQ run (default 100000)")
    ap.add_argument("--frames", type=int, default=200, help="Measurements counted on the M4 (default 200)")
    ap.add_argument("--skip-m4", action="store_true", help="no Cortex-M4F figures")
    ap.add_argument("--skip-linux", action="store_true", help="no Linux DAQ run")
    ap.add_argument("--results", action="store_true", help="also write the figures to bench/results/xcp.json")
    args = ap.parse_args(argv)
    if args.results:  # imported now: it notes the load average at the start of the run
        from results_file import save  # noqa: E402 - beside this script
    if args.steps < 100 or args.frames < 10:
        ap.error("--steps: at least 100; --frames: at least 10")
    report: dict = {}
    if not args.skip_m4:
        m4 = report["cortex_m4"] = _m4(args.frames)
        plain, daq, ev = m4["plain"], m4["daq"], m4["daq_event"]
        print(f"Cortex-M4F, estimated cycles (share of 0.3 ms at 168 MHz = {BUDGET} cycles):")
        print(f"  Measurement frame without XCP       {plain['cycles_mean']:8.0f} (max {plain['cycles_max']:.0f}), "
              f"{plain['instructions_mean']:.0f} instructions")
        con = m4["connected"]
        print(f"  with XCP, a master connected, no DAQ {con['cycles_mean']:6.0f} (max {con['cycles_max']:.0f}), "
              f"{con['instructions_mean']:.0f} instructions")
        print(f"  with XCP, 1 DAQ list (3 ODTs)       {daq['cycles_mean']:8.0f} (max {daq['cycles_max']:.0f}), "
              f"{daq['instructions_mean']:.0f} instructions, {100 * daq['cycles_mean'] / BUDGET:.1f} %")
        dfr, poll = m4["deferred"], m4["deferred_poll"]
        print(f"  the same, sample deferred           {dfr['cycles_mean']:8.0f} (max {dfr['cycles_max']:.0f}), "
              f"{100 * dfr['cycles_mean'] / BUDGET:.1f} % (max {100 * dfr['cycles_max'] / BUDGET:.1f} %); "
              f"fw_xcp_poll after the frame {poll['cycles_mean']:.0f} (max {poll['cycles_max']:.0f})")
        print(f"  the step event (the difference)    {ev['cycles_mean']:8.0f}, {ev['instructions_mean']:.0f} "
              f"instructions, {100 * ev['cycles_mean'] / BUDGET:.1f} %: {ev['by_function']}")
        for k, v in m4["commands"].items():
            print(f"  command {k:27} {v['cycles_mean']:8.0f} (max {v['cycles_max']:.0f}), "
                  f"{v['instructions_mean']:.0f} instructions")
        print(f"  fw_xcp in the image: {m4['fw_xcp_object']}; object file {m4['fw_xcp_object_file']}")
        print(f"  RAM: {m4['sizeof']}")
    if not args.skip_linux:
        lx = report["linux"] = _linux(args.steps)
        print(f"Linux, {args.steps} steps of DAQ over UDP to pyxcp: {json.dumps(lx)}")
    print(json.dumps(report, indent=1))
    if args.results:
        for part in ("plain", "connected", "daq", "deferred", "deferred_poll", "daq_event",
                     *(f"commands.{k}" for k in
                                                                report.get("cortex_m4", {}).get("commands", {}))):
            if "cortex_m4" in report:
                entry = report["cortex_m4"]
                for key in part.split(".", 1):
                    entry = entry[key]
                entry["share_of_budget"] = entry["cycles_mean"] / BUDGET
        save("xcp", report, argv)
    return 0


if __name__ == "__main__":
    sys.exit(main())
