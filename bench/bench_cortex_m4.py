"""Cortex-M4F figures of the LIM identifier step (float32), from the QEMU
run of firmware_sim/cortex_m4/run_m4.py: instructions per step against the
0.3 ms budget of a 168 MHz core (50,400 cycles), code and RAM size, worst
stack. QEMU counts instructions exactly (-icount shift=0).

Then the whole firmware application on the M4F (fw_app over the memory
HAL: decode, checks, rhonn_step, Estimate encode, commands, diagnostics) fed
a recorded stream of 1000 LIM Measurements with every other frame kind in
it: whether it sends exactly the host firmware's frames, the estimated
cycles per frame by kind against the whole-frame target (15 % of 0.3 ms at
168 MHz: 7,560 cycles) and per rhonn_step inside it, flash, RAM and stack.

Then the estimated cycles per step for three covariance forms of the same
identifier: as the `firmware-lim` config says (U D U^T for the position
neuron, the full form with its positive-definiteness check for the others),
every neuron full, every neuron U D U^T; unrolled build, a 100-sample vector.

Cycles are estimates (firmware_sim/cortex_m4/cycles.py): every executed
instruction weighted by the Cortex-M4 timing table printed below, with no
flash wait states and no pipelining effects beyond the table.

    python bench/bench_cortex_m4.py [--frames N] [--results]

``--results`` also writes every figure to bench/results/cortex_m4.json,
which the docs quote (see bench/results_file.py).
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
STEP_TARGET = 5000  # estimated cycles aimed at for a learning step inside the application


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=1000, help="Measurements in the application's stream (default 1000)")
    ap.add_argument("--results", action="store_true", help="also write the figures to bench/results/cortex_m4.json")
    args = ap.parse_args(argv)
    if args.results:  # imported now: it notes the load average at the start of the run
        from results_file import save  # noqa: E402 - beside this script
    if args.frames < 20:
        ap.error(f"--frames: at least 20, got {args.frames}")
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        proc = subprocess.run([sys.executable, str(ROOT / "firmware_sim" / "cortex_m4" / "run_m4.py"),
                               "--out", str(out / "build"), "--json", str(out / "r.json"), "--frames",
                               str(args.frames), "--cycle-frames", str(10 * args.frames)],
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
    print_cycle_table()
    application(report["application"], budget)
    forms: dict[str, dict[str, float]] = {}
    code = covariance_forms(budget, forms)
    if code == 0 and args.results:
        c = report["application"]["cycles"]
        shares = {"step_p99_share": c["step_p99"] / budget, "step_max_share": c["step_max"] / budget,
                  "measurement_frame_max_share": c["measurement_frame_max"] / budget,
                  "step_median_over_step_target": c["step_median"] / STEP_TARGET,
                  "step_margin_to_step_target": STEP_TARGET - c["step_median"], "step_target": STEP_TARGET,
                  "application_flash_kb": report["application"]["flash_bytes"] / 1000,
                  "core_flash_kb": sum(report["application"]["objects"]["rhonn"][k] for k in ("text", "rodata")) / 1000}
        save("cortex_m4", {**report, "covariance_forms": forms, "derived": shares}, argv)
    return code


def print_cycle_table() -> None:
    """The estimator's weights and limits, from its own documentation."""
    sys.path.insert(0, str(ROOT / "firmware_sim" / "cortex_m4"))
    import cycles  # noqa: E402 - the estimator beside the image

    doc = cycles.__doc__ or ""
    print("\ncycle estimate (firmware_sim/cortex_m4/cycles.py): Cortex-M4 cycles per executed instruction")
    print(doc[doc.index("The weights (cycles):"):doc.index("    python firmware_sim")].rstrip())


def application(app: dict, budget: int) -> None:
    c = app["cycles"]
    print(f"\nwhole application on the M4F (fw_app over fw_hal_mem, unrolled core): {app['frames']} frames in, "
          f"{app['frames_sent']} out, identical to the host firmware (pyrhonn._fwapp): {app['identical_to_host']}")
    print(f"{'frame kind':44} {'frames':>6} {'est. cycles':>12} {'max':>7} {'x budget':>9}")
    for kind, k in sorted(c["by_kind"].items(), key=lambda kv: -kv[1]["frames"]):
        print(f"{kind:44} {k['frames']:6d} {k['mean']:12.0f} {k['max']:7d} {k['mean'] / budget:9.3f}")
    print(f"{'rhonn_step inside a measurement frame':44} {c['steps']:6d} {c['step_mean']:12.0f} {c['step_max']:7d} "
          f"{c['step_mean'] / budget:9.3f}")
    print(f"{'  its median, 99th percentile':44} {'':6} {c['step_median']:12.0f} {c['step_p99']:7.0f} "
          f"{c['step_p99'] / budget:9.3f}")
    print(f"the application around the step (decode, checks, encode, HAL): {c['app_overhead_mean']:.0f} cycles per "
          f"measurement frame; library routines ({', '.join(app['library_routines'])}): "
          f"{c['library_cycles_per_frame']:.0f} per frame, of them software double arithmetic "
          f"{c['soft_double_cycles_per_frame']:.0f}, averaged over the {c['frames']} frames")
    top = ", ".join(f"{name} {v:.0f}" for name, v in list(c["cycles_per_frame_by_function"].items())[:12])
    print(f"cycles per frame by function (mean over the {c['frames']} frames): {top}")
    met = "MET" if c["frame_target_met"] else "NOT MET"
    print(f"target: the whole measurement frame within {c['frame_target']} cycles (15 % of {budget}): {met} "
          f"(mean {c['measurement_frame_mean']:.0f}, max {c['measurement_frame_max']}, "
          f"{c['measurement_frame_max'] / c['frame_target']:.2f}x the target)")
    print("flash (map file, after --gc-sections):")
    for name, o in app["objects"].items():
        print(f"  {name:12} .text {o['text']:6d} B  .rodata {o['rodata']:5d} B  .data {o['data']:4d} B  "
              f".bss {o['bss']:4d} B")
    print(f"  library routines it calls: {app['library_code_bytes']} B; total flash {app['flash_bytes']} B")
    print(f"RAM: fw_app {app['sizeof_fw_app']} B (rhonn_t {app['sizeof_rhonn_t']} B inside), static RAM of the "
          f"objects above {app['ram_bytes_static'] - app['sizeof_fw_app']} B, worst stack of fw_app_on_frame "
          f"{app['fw_app_on_frame_worst_stack_bytes']} B ({' > '.join(app['fw_app_on_frame_worst_stack_path'])}); "
          f"the memory HAL's queues (fw_mem_hal, test HAL) {app['sizeof_fw_mem_hal']} B")
    im = app["image"]
    print(f"application image (+ the frame stream, newlib semihosting stdio): .text {im['text']} B, "
          f".data {im['data']} B, .bss {im['bss']} B")


def covariance_forms(budget: int, out: dict[str, dict[str, float]]) -> int:
    """Print (and put into ``out``, by form) the estimated cycles per step of each covariance form."""
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
                elf = run_m4.build_m4(vec, build, unroll=True, target="rhonn_m4.elf")
                est = cycles.estimate(elf, next(build.glob("CMakeFiles/rhonn_m4.elf.dir/**/rhonn.c.obj")))
            except (run_m4.ToolError, RuntimeError) as exc:
                print(f"bench_cortex_m4: {exc}", file=sys.stderr)
                return 2
            out[form] = {"instructions_per_step": est["instructions_per_call"],
                         "estimated_cycles_per_step": est["estimated_cycles_per_call"],
                         "share_of_budget": est["estimated_cycles_per_call"] / budget}
            shares = ", ".join(f"{k} {v:.0%}" for k, v in list(est["cycle_share_by_class"].items())[:3])
            print(f"{label:28} {est['instructions_per_call']:11.0f} {est['estimated_cycles_per_call']:12.0f} "
                  f"{est['estimated_cycles_per_call'] / budget:9.3f}  {shares}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
