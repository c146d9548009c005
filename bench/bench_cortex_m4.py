"""Cortex-M4F figures of the LIM identifier step (float32), from the QEMU
run of firmware_sim/cortex_m4/run_m4.py: instructions per step against the
0.3 ms budget of a 168 MHz core (50,400 cycles), code and RAM size, worst
stack. QEMU counts instructions exactly (-icount shift=0); cycles on real
silicon are 1-2x the instruction count for this code (FPU and load latency).

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
    return 0


if __name__ == "__main__":
    sys.exit(main())
