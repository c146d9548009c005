"""The HIL round trip over udp_multicast: the rig (python-can)
replays N measurement frames at 0.3 ms against the C firmware
(``rhonn_runner --udp-multicast``), once sleeping between frames (the
``hil replay`` default, busy-polling 50 us either side of each expected frame)
and once busy-polling (``hil bench``'s default, 149 us: it never sleeps) and,
as the baseline in the same run, against the Python firmware node (the same
firmware logic through cffi).

    python bench/bench_hil_udp.py [--cycles N] [--rounds R] [--fifo PRIO] [--cpus RIG,FIRMWARE] [--results]

For each it reports the share of estimates back within one period (at the
rig's socket, by the kernel's receive timestamp, and picked up by the rig
process), the round trip's p50/p99.9 and the firmware's handling time; then
the ratios against the Python node of the late share and of the p99.9 round
trip (target: 99.9 % within one period; the ratios say what the C firmware
and its busy-polling buy on this host, whose scheduling noise moves the
absolute figures from minute to minute, which is why the variants alternate
in rounds), and the hypervisor's steal time during each (hil.host).
"""
from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
# the installed pyrhonn and hil first (the source tree's pyrhonn/ has no compiled core); the
# checkout's hil only where none is installed
sys.path.append(str(ROOT))

from hil.host import StealMeter  # noqa: E402
from hil.transport import RUNNER_SPIN_MAX_US, RUNNER_SPIN_US, parse_cpu_pair, use_fifo  # noqa: E402

#: name -> (firmware, runner busy-poll margin in us)
VARIANTS = {"python node": ("python", RUNNER_SPIN_US), "runner": ("runner", RUNNER_SPIN_US),
            "runner busy-poll": ("runner", RUNNER_SPIN_MAX_US)}


def build_runner() -> Path:
    """rhonn_runner from this checkout (firmware_sim/linux/build_runner.py, cached per source)."""
    sys.path.insert(0, str(ROOT / "firmware_sim" / "linux"))
    try:
        from build_runner import cached
    finally:
        sys.path.pop(0)
    try:
        return cached()
    except (RuntimeError, OSError) as exc:
        raise SystemExit(f"bench_hil_udp: cannot build rhonn_runner: {exc}") from None


def measure(firmware: str, spin_us: float, cycles: int, firmware_cpu: int | None, runner: Path) -> dict:
    """One replay of ``cycles`` frames; its latencies (ns), counts and the
    host's steal time during it."""
    import numpy as np

    from hil.scenario import Scenario
    from hil.score import score
    from hil.transport import run_replay

    steal = StealMeter()
    steal.start()
    rec = run_replay(Scenario.at_rest(cycles), "udp_multicast", firmware=firmware, firmware_cpu=firmware_cpu,
                     runner=str(runner) if firmware == "runner" else None, runner_spin_us=spin_us)
    stolen = steal.stop()
    r = score(rec)
    side = rec.meta.get("firmware_side") or {}
    lat = r["latency_us"]
    n = int(lat.get("n", 0))
    return {"latency_ns": np.asarray(r["_series"]["latency_ns"], dtype=np.int64),
            "picked_up": round(lat.get("within_period_picked_up", float("nan")) * n),
            "handling": (side.get("handling_us") or {}).get("avg"), "accounted": r["frames"]["accounted"],
            "served_by": side.get("firmware"), "steal_ms": stolen.get("total_ms") if stolen["available"] else None}


def summary(blocks: list[dict]) -> dict:
    import numpy as np

    lat = np.concatenate([b["latency_ns"] for b in blocks]) / 1e3
    handling = [b["handling"] for b in blocks if b["handling"] is not None]
    steal = [b["steal_ms"] for b in blocks]
    return {"steal_ms": None if None in steal else float(sum(steal)),"n": lat.size, "within": float(np.mean(lat <= 300.0)),
            "picked_up": sum(b["picked_up"] for b in blocks) / max(lat.size, 1),
            "p50": float(np.percentile(lat, 50)), "p999": float(np.percentile(lat, 99.9)),
            "handling": float(np.mean(handling)) if handling else None,
            "accounted": all(b["accounted"] for b in blocks), "served_by": blocks[0]["served_by"]}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cycles", type=int, default=100_000, help="per firmware (default 100000)")
    ap.add_argument("--rounds", type=int, default=4,
                    help="alternate the two firmwares this many times, cycles/rounds each, so that the host's "
                         "minute-to-minute noise falls on both (default 4)")
    ap.add_argument("--fifo", type=int, default=None, metavar="PRIO")
    ap.add_argument("--cpus", type=parse_cpu_pair, default=None, metavar="RIG,FIRMWARE")
    ap.add_argument("--results", action="store_true", help="also write the figures to bench/results/hil_udp.json")
    args = ap.parse_args(argv)
    if args.results:  # imported now: it notes the load average at the start of the run
        from results_file import save  # noqa: E402 - beside this script
    policy = use_fifo(args.fifo)
    allowed = os.sched_getaffinity(0)
    if args.cpus is not None and not set(args.cpus) <= allowed:
        print(f"note: CPUs {args.cpus} are not all available here ({sorted(allowed)}): not pinned")
        args.cpus = None
    if args.cpus is not None:
        os.sched_setaffinity(0, {args.cpus[0]})
        policy += f", rig on CPU {args.cpus[0]}, firmware on CPU {args.cpus[1]}"
    fw_cpu = args.cpus[1] if args.cpus else None
    if args.cycles < 2 * args.rounds or args.rounds < 1:
        ap.error("--cycles must be at least 2 x --rounds, --rounds at least 1")
    runner = build_runner()
    blocks: dict[str, list[dict]] = {name: [] for name in VARIANTS}
    for _ in range(args.rounds):
        for name, (firmware, spin) in VARIANTS.items():
            blocks[name].append(measure(firmware, spin, args.cycles // args.rounds, fw_cpu, runner))
    rows = {name: summary(b) for name, b in blocks.items()}
    print(f"hil round trip over udp_multicast, {args.cycles} cycles per variant at 0.3 ms in {args.rounds} "
          f"alternating rounds, {policy}")
    print(f"{'firmware':<40}{'within period':>14}{'picked up':>11}{'p50 us':>9}{'p99.9 us':>10}{'handling us':>13}"
          f"{'steal ms':>10}")
    for name, r in rows.items():
        handling = f"{r['handling']:13.1f}" if r["handling"] is not None else f"{'-':>13}"
        steal = f"{r['steal_ms']:10.0f}" if r["steal_ms"] is not None else f"{'-':>10}"
        print(f"{name + ' (' + str(r['served_by']) + ')':<40}{100 * r['within']:13.3f}%{100 * r['picked_up']:10.3f}%"
              f"{r['p50']:9.1f}{r['p999']:10.1f}{handling}{steal}")
    py = rows["python node"]
    for name in ("runner", "runner busy-poll"):
        c = rows[name]
        late_ratio = (1 - c["within"]) / (1 - py["within"]) if py["within"] < 1 else float("nan")
        print(f"{name} / python node: late share x{late_ratio:.2f}, p99.9 round trip x{c['p999'] / py['p999']:.2f}")
    best = max(rows, key=lambda n: rows[n]["within"])
    print(f"(target: 99.9 % within one period; best here: {best}, {100 * rows[best]['within']:.3f} %; steal: "
          "what the hypervisor took from all CPUs during the variant's rounds)")
    if args.results:
        figures: dict = {"settings": {"cycles": args.cycles, "rounds": args.rounds, "policy": policy}}
        for name, r in rows.items():
            figures[name.replace(" ", "_").replace("-", "_")] = {
                "within": r["within"], "picked_up": r["picked_up"], "p50_us": r["p50"], "p999_us": r["p999"],
                "handling_us": r["handling"], "steal_ms": r["steal_ms"], "accounted": r["accounted"]}
        save("hil_udp", figures, argv)
    return 0 if all(r["accounted"] for r in rows.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
