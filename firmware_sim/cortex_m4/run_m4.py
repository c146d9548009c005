"""Build the identifier for a Cortex-M4F, run it under QEMU (mps2-an386), and
compare every prediction, bit for bit, with the host's float32 build of the
same source on the same test vector. Reports instructions per step, image
sizes, the worst-case stack of rhonn_step and the identifier's RAM; then
checks the command authentication's AES-CMAC against RFC 4493 on the target
and counts the instructions of verifying a secured Control and WeightLoad
(secoc_main.c).

    python firmware_sim/cortex_m4/run_m4.py [--out build/m4] [--json report.json]

Exit status 0 when both builds agree on every bit, 1 when they do not, 2
when a tool is missing or a build fails. Needs arm-none-eabi-gcc with newlib
(Debian: gcc-arm-none-eabi libnewlib-arm-none-eabi), qemu-system-arm, cmake
and a host C compiler.
"""
from __future__ import annotations

import argparse
import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent.parent
# The LIM identifier's capacities: 6 states, 2 inputs, at most 6 terms of at
# most 2 factors, no delayed taps (make_vector.py's configuration).
LIM_CAPACITIES = {"RHONN_MAX_STATES": 6, "RHONN_MAX_INPUTS": 2, "RHONN_MAX_TERMS": 8, "RHONN_MAX_FACTORS": 2,
                  "RHONN_MAX_DELAY": 0, "RHONN_MAX_POWER": 2}
CYCLE_BUDGET = 50_400  # 0.3 ms at 168 MHz
QEMU = ["qemu-system-arm", "-M", "mps2-an386", "-nographic", "-semihosting-config", "enable=on,target=native",
        "-icount", "shift=0"]


class ToolError(RuntimeError):
    pass


def run(cmd: list[str], **kw) -> subprocess.CompletedProcess:
    try:
        return subprocess.run(cmd, check=True, capture_output=True, text=True, **kw)
    except FileNotFoundError as exc:
        raise ToolError(f"{cmd[0]}: not found") from exc
    except subprocess.CalledProcessError as exc:
        raise ToolError(f"{' '.join(cmd[:3])} ... failed ({exc.returncode}):\n{exc.stdout}\n{exc.stderr}") from exc
    except subprocess.TimeoutExpired as exc:
        raise ToolError(f"{' '.join(cmd[:3])} ... timed out after {exc.timeout} s") from exc


def build_m4(vector_dir: Path, build_dir: Path, unroll: bool) -> Path:
    defines = {**LIM_CAPACITIES, "RHONN_UNROLL": int(unroll)}
    run(["cmake", "-S", str(HERE), "-B", str(build_dir), f"-DCMAKE_TOOLCHAIN_FILE={ROOT / 'cmake' / 'arm-none-eabi.cmake'}",
         f"-DVECTOR_DIR={vector_dir}", "-DRHONN_CAPACITY_DEFINES=" + ";".join(f"{k}={v}" for k, v in defines.items())])
    run(["cmake", "--build", str(build_dir)])
    return build_dir / "rhonn_m4.elf"


def build_host(vector_dir: Path, build_dir: Path) -> Path:
    cc = shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        raise ToolError("no host C compiler (cc) on PATH")
    exe = build_dir / "rhonn_host_f32"
    run([cc, "-std=c99", "-O2", "-ffp-contract=off", "-DRHONN_SINGLE",
         *[f"-D{k}={v}" for k, v in LIM_CAPACITIES.items()], f"-I{ROOT / 'csrc' / 'include'}", f"-I{vector_dir}",
         str(HERE / "vector_main.c"), str(ROOT / "csrc" / "src" / "rhonn.c"), "-o", str(exe)])
    return exe


def predictions(output: str) -> list[str]:
    return [line for line in output.splitlines() if re.match(r"^\d+ ", line)]


def field(output: str, name: str) -> float:
    m = re.search(rf"^{name} ([0-9.]+)$", output, re.M)
    if m is None:
        raise ToolError(f"the M4 run printed no '{name}'")
    return float(m.group(1))


def worst_stack(callgraph: Path, root: str) -> tuple[int, list[str]]:
    """Deepest stack from ``root`` in GCC's -fcallgraph-info=su output: the
    sum of static frames along the heaviest call path (the core has no
    recursion and no dynamic frames). Library leaves (memcpy) count as 0."""
    text = callgraph.read_text()
    size: dict[str, int] = {}
    for title, label in re.findall(r'node: \{ title: "([^"]+)" label: "([^"]*)"', text):
        m = re.search(r"(\d+) bytes \((\w+)\)", label)
        if m and m.group(2) != "static":
            raise ToolError(f"{title}: {m.group(2)} stack frame, not bounded statically")
        size[title] = int(m.group(1)) if m else 0
    edges: dict[str, set[str]] = {}
    for src, dst in re.findall(r'edge: \{ sourcename: "([^"]+)" targetname: "([^"]+)"', text):
        edges.setdefault(src, set()).add(dst)

    def deepest(node: str, seen: tuple[str, ...]) -> tuple[int, list[str]]:
        if node in seen:
            raise ToolError(f"recursion through {node}")
        best = (0, [])
        for nxt in edges.get(node, ()):
            best = max(best, deepest(nxt, seen + (node,)))
        return size.get(node, 0) + best[0], [node.split(":")[-1]] + best[1]

    return deepest(root, ())


def sizes(path: Path) -> dict[str, int]:
    out = run(["arm-none-eabi-size", str(path)]).stdout.splitlines()[1].split()
    return {"text": int(out[0]), "data": int(out[1]), "bss": int(out[2])}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=ROOT / "build" / "m4", help="build folder")
    ap.add_argument("--samples", type=int, default=2000, help="rows of the test vector")
    ap.add_argument("--json", type=Path, help="write the report as JSON here")
    args = ap.parse_args(argv)
    out = args.out.resolve()
    out.mkdir(parents=True, exist_ok=True)
    try:
        run([sys.executable, str(HERE / "make_vector.py"), str(out / "vector"), "--samples", str(args.samples)])
        report: dict[str, object] = {"samples": args.samples, "capacities": LIM_CAPACITIES,
                                     "cycle_budget_168MHz_0.3ms": CYCLE_BUDGET}
        host = run([str(build_host(out / "vector", out))]).stdout
        agree = True
        for unroll in (True, False):
            name = "unrolled" if unroll else "generic"
            elf = build_m4(out / "vector", out / name, unroll)
            m4 = run([*QEMU, "-kernel", str(elf)], timeout=300).stdout
            same = predictions(m4) == predictions(host) and len(predictions(m4)) == args.samples
            agree = agree and same
            core_obj = next((out / name).rglob("rhonn.c.obj"))
            stack, path = worst_stack(core_obj.with_suffix("").with_suffix(".c.ci"), "rhonn_step")
            report[name] = {
                "bit_identical_to_host_float32": same,
                "predictions_compared": len(predictions(m4)),
                "distinct_predictions": len(set(line.split(" ", 1)[1] for line in predictions(m4))),
                "instructions_per_step": field(m4, "instructions_per_step"),
                "budget_fraction": field(m4, "instructions_per_step") / CYCLE_BUDGET,
                "sizeof_rhonn_t": int(field(m4, r"sizeof\(rhonn_t\)")),
                "core_object": sizes(core_obj),
                "image": sizes(elf),
                "rhonn_step_worst_stack_bytes": stack,
                "rhonn_step_worst_stack_path": path,
            }
        secoc = run([*QEMU, "-kernel", str(out / "unrolled" / "secoc_m4.elf")], timeout=300).stdout
        secoc_ok = "cmac_rfc4493 ok" in secoc and "verified ok" in secoc
        agree = agree and secoc_ok
        report["secoc"] = {
            "cmac_rfc4493_and_verification_on_target": secoc_ok,
            "instructions_per_control_verify": field(secoc, "instructions_per_control_verify"),
            "instructions_per_weight_load_verify": field(secoc, "instructions_per_weight_load_verify"),
            "control_verify_budget_fraction": field(secoc, "instructions_per_control_verify") / CYCLE_BUDGET,
            "objects": {obj.name.split(".")[0]: sizes(obj) for obj in sorted((out / "unrolled").rglob("fw_*.c.obj"))},
        }
    except ToolError as exc:
        print(f"run_m4: {exc}", file=sys.stderr)
        return 2
    text = json.dumps(report, indent=2)
    print(text)
    if args.json:
        args.json.write_text(text + "\n")
    return 0 if agree else 1


if __name__ == "__main__":
    sys.exit(main())
