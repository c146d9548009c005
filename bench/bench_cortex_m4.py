"""Cortex-M4F figures of the LIM identifier step (float32), from the QEMU
run of firmware_sim/cortex_m4/run_m4.py: instructions per step against the
0.3 ms budget of a 168 MHz core (50,400 cycles), code and RAM size, worst
stack. QEMU counts instructions exactly (-icount shift=0).

Then the estimated cycles per step (firmware_sim/cortex_m4/cycles.py: every
executed instruction of the core weighted by the Cortex-M4 timing tables,
zero wait states) for three covariance forms of the same identifier: as the
`firmware-lim` config says (U D U^T for the position neuron, the full form
with its positive-definiteness check for the others), every neuron full,
every neuron U D U^T; unrolled build, a 100-sample vector.

    python bench/bench_cortex_m4.py
"""
from __future__ import annotations

import json
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def main() -> int:
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        proc = subprocess.run([sys.executable, str(ROOT / "firmware_sim" / "cortex_m4" / "run_m4.py"),
                               "--out", str(out / "build"), "--json", str(out / "r.json")],
                              capture_output=True, text=True)
        if proc.returncode == 2:
            print(proc.stderr, file=sys.stderr)
            return 2
        report = json.loads((out / "r.json").read_text())
    budget = report["cycle_budget_168MHz_0.3ms"]
    print(f"{'build':10} {'instr/step':>11} {'x budget':>9} {'core .text':>11} {'rhonn_t':>8} {'stack':>6} {'bit-exact':>9}")
    for name in ("unrolled", "generic"):
        r = report[name]
        print(f"{name:10} {r['instructions_per_step']:11.0f} {r['instructions_per_step'] / budget:9.3f} "
              f"{r['core_object']['text']:10d}B {r['sizeof_rhonn_t']:7d}B {r['rhonn_step_worst_stack_bytes']:5d}B "
              f"{str(r['bit_identical_to_host_float32']):>9}")
    for name in ("unrolled", "generic"):
        im = report[name]["image"]
        print(f"{name} image (core + test vector + newlib semihosting stdio): .text {im['text']} B, "
              f".data {im['data']} B, .bss {im['bss']} B")
    print(f"budget = {budget} cycles (0.3 ms at 168 MHz); capacities {report['capacities']}")
    return covariance_forms(budget)


def covariance_forms(budget: int) -> int:
    sys.path.insert(0, str(ROOT / "firmware_sim" / "cortex_m4"))
    import cycles  # noqa: E402 - the estimator beside the image
    import run_m4  # noqa: E402

    print(f"\n{'covariance form':28} {'instr/step':>11} {'est. cycles':>12} {'x budget':>9}  largest shares")
    with tempfile.TemporaryDirectory() as tmp:
        for form, label in (("config", "firmware-lim (UD position)"), ("full", "every neuron full"),
                            ("ud", "every neuron U D U^T")):
            vec, build = Path(tmp) / f"v-{form}", Path(tmp) / f"b-{form}"
            try:
                run_m4.run([sys.executable, str(ROOT / "firmware_sim" / "cortex_m4" / "make_vector.py"), str(vec),
                            "--samples", "100", "--covariance", form])
                elf = run_m4.build_m4(vec, build, unroll=True)
                est = cycles.estimate(elf, next(build.rglob("rhonn.c.obj")))
            except (run_m4.ToolError, RuntimeError) as exc:
                print(f"bench_cortex_m4: {exc}", file=sys.stderr)
                return 2
            shares = ", ".join(f"{k} {v:.0%}" for k, v in list(est["cycle_share_by_class"].items())[:3])
            print(f"{label:28} {est['instructions_per_call']:11.0f} {est['estimated_cycles_per_call']:12.0f} "
                  f"{est['estimated_cycles_per_call'] / budget:9.3f}  {shares}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
