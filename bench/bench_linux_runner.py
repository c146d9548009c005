"""The firmware's Linux runner in its bus-less timing mode: 100,000 cycles
at 0.3 ms (30 s) with the default scheduler and with SCHED_FIFO, reporting
step time and wake-up latency percentiles and overruns. The step's p99.9
is read against the 0.3 ms period (target: under 10 %), overruns against
the cycle count (target on this shared VM: at most 0.1 %; zero on a
real-time kernel).

    python bench/bench_linux_runner.py [--cycles N] [--runner PATH] [--results]

``--results`` also writes the figures to bench/results/linux_runner.json, which the docs quote.

Builds the runner with cc when no --runner is given. Needs root (or
CAP_SYS_NICE) for the SCHED_FIFO row; without it the runner says so and
that row runs with the default policy.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PERIOD_US = 300.0


def build_runner(out: Path) -> Path:
    sys.path.insert(0, str(ROOT / "firmware_sim" / "linux"))
    from build_runner import build  # the runner's one build recipe without CMake

    try:
        return build(out)
    except RuntimeError as exc:
        raise SystemExit(f"bench_linux_runner: {exc}") from None


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cycles", type=int, default=100_000)
    ap.add_argument("--runner", type=Path)
    ap.add_argument("--results", action="store_true", help="also write the figures to bench/results/linux_runner.json")
    args = ap.parse_args(argv)
    if args.cycles < 1:
        ap.error("--cycles: at least 1")
    if args.results:  # imported now: it notes the load average at the start of the run
        from results_file import save  # noqa: E402 - beside this script
    with tempfile.TemporaryDirectory() as tmp:
        runner = args.runner or build_runner(Path(tmp))
        rows = []
        for label, extra in (("SCHED_OTHER", []), ("SCHED_FIFO 80", ["--fifo", "80"])):
            report = Path(tmp) / "r.json"
            proc = subprocess.run([str(runner), "--bus-less", "--cycles", str(args.cycles), "--period-us",
                                   str(PERIOD_US), "--quiet", "--json", str(report), *extra], capture_output=True, text=True)
            if proc.returncode != 0:
                print(proc.stderr, file=sys.stderr)
                return 1
            if proc.stderr:
                print(proc.stderr.strip(), file=sys.stderr)
            r = json.loads(report.read_text())
            rows.append((label, r))
    print(f"rhonn_runner --bus-less, period {PERIOD_US:.0f} us, {args.cycles} cycles each")
    print(f"{'policy':14} {'step p99':>9} {'step p99.9':>11} {'p99.9/period':>13} {'step max':>9} "
          f"{'wake p99.9':>11} {'wake max':>9} {'overruns':>9} {'overrun %':>10}")
    for _label, r in rows:
        st, wk = r["step"], r["wake-up"]
        print(f"{r['policy']:14} {st['p99_us']:8.2f}u {st['p999_us']:10.2f}u {st['p999_us'] / PERIOD_US:12.2%} "
              f"{st['max_us']:8.1f}u {wk['p999_us']:10.1f}u {wk['max_us']:8.1f}u {r['overruns']:9d} "
              f"{100 * r['overruns'] / max(r['cycles'], 1):9.3f}%")
    if args.results:
        figures: dict = {"settings": {"cycles": args.cycles, "period_us": PERIOD_US}}
        for label, r in rows:
            st, wk = r["step"], r["wake-up"]
            figures["fifo" if "FIFO" in label else "other"] = {
                "policy": r["policy"], "step_p99_us": st["p99_us"], "step_p999_us": st["p999_us"],
                "step_p999_of_period": st["p999_us"] / PERIOD_US, "step_max_us": st["max_us"],
                "wake_p999_us": wk["p999_us"], "wake_max_us": wk["max_us"], "overruns": r["overruns"],
                "overrun_share": r["overruns"] / max(r["cycles"], 1)}
        save("linux_runner", figures, argv)
    return 0


if __name__ == "__main__":
    sys.exit(main())
