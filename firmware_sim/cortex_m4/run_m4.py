"""Build the identifier for a Cortex-M4F, run it under QEMU (mps2-an386), and
compare every prediction, bit for bit, with the host's float32 build of the
same source on the same test vector. Reports instructions per step, image
sizes, the worst-case stack of rhonn_step and the identifier's RAM; then
checks the command authentication's AES-CMAC against RFC 4493 on the target
and counts the instructions of verifying a secured Control and WeightLoad
(secoc_main.c).

Then the whole firmware application (app_main.c: fw_app over fw_hal_mem)
over a recorded frame stream (make_frames.py): every status and every frame
it sends must equal the host firmware's (pyrhonn._fwapp); reports its flash
and RAM (linker map), the worst stack of fw_app_on_frame, and the estimated
cycles (cycles.py) of the first --cycle-frames frames, by kind of frame and
of rhonn_step inside them, against the whole-frame target (7,560 cycles).

    python firmware_sim/cortex_m4/run_m4.py [--out build/m4] [--samples N] [--frames N]
                                            [--cycle-frames N] [--json report.json]
    python firmware_sim/cortex_m4/run_m4.py --identifier CFG.toml --dbc ID.dbc --trajectory DATA.csv
                                            [--out build/m4-id] [--frames N] [--cycle-frames N]

With ``--identifier`` only the application image is built, for another
identifier (a float32 config file and the DBC ``pyrhonn export --dbc`` wrote
for it: the protocol generated from that DBC, the config compiled in, the
core's capacities the smallest that hold it), and run over its recording
(make_frames.py --identifier): every status and every frame it sends must
equal the twin's built for that DBC.

Exit status 0 when every comparison agrees, 1 when one does not, 2
when a tool is missing or a build fails. Needs arm-none-eabi-gcc with newlib
(Debian: gcc-arm-none-eabi libnewlib-arm-none-eabi), qemu-system-arm, cmake,
a host C compiler and pyrhonn installed.
"""
from __future__ import annotations

import argparse
import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

from pyrhonn import atomic

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent.parent
if str(HERE) not in sys.path:   # imported from elsewhere (the tests, the bench): the estimator beside it
    sys.path.insert(0, str(HERE))
import cycles  # noqa: E402
# The LIM identifier's capacities: 6 states, 2 inputs, at most 8 terms of at
# most 2 factors, taps one sample back (the velocity neuron's i(k-1);
# make_vector.py's configuration).
LIM_CAPACITIES = {"RHONN_MAX_STATES": 6, "RHONN_MAX_INPUTS": 2, "RHONN_MAX_TERMS": 8, "RHONN_MAX_FACTORS": 2,
                  "RHONN_MAX_DELAY": 1, "RHONN_MAX_POWER": 2}
CYCLE_BUDGET = 50_400  # 0.3 ms at 168 MHz
FRAME_TARGET = 7_560   # the whole frame, decode to encode: 15 % of CYCLE_BUDGET
#: the firmware's objects in the application image; the rest is the harness (app_main.c) and newlib
APP_OBJECTS = ("fw_app", "fw_protocol", "fw_hal_mem", "rhonn_id", "rhonn", "fw_secoc", "fw_aes_cmac")
#: the harness functions around fw_app_on_frame (not counted)
APP_HARNESS = ("main", "handle_frame")
#: what the application calls through the HAL's function pointers
APP_HAL = ("fw_mem_hal_send", "fw_mem_hal_now", "fw_mem_hal_receive")
#: libgcc's software double-precision routines (the FPv4-SP FPU has single precision only):
#: __aeabi_dadd, __aeabi_cdcmple, __aeabi_i2d, __aeabi_d2f, ... and their aliases __adddf3, __cmpdf2, ...
SOFT_DOUBLE = re.compile(r"^__aeabi_(c?d[a-z]|\w*2d$|d2)|^__\w*df\w*$")
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


def build_m4(vector_dir: Path, build_dir: Path, unroll: bool, frames_dir: Path | None = None,
             target: str | None = None, capacities: dict[str, int] | None = None,
             protocol_dir: Path | None = None) -> Path:
    """Configure and build the images; the core image's path. ``frames_dir``
    (frames.h) adds the application image fw_app_m4.elf; ``target`` builds
    that one target only; ``capacities`` and ``protocol_dir`` (another
    identifier's protocol and fw_identifier.h) replace the LIM's."""
    defines = {**(LIM_CAPACITIES if capacities is None else capacities), "RHONN_UNROLL": int(unroll)}
    run(["cmake", "-S", str(HERE), "-B", str(build_dir), f"-DCMAKE_TOOLCHAIN_FILE={ROOT / 'cmake' / 'arm-none-eabi.cmake'}",
         f"-DVECTOR_DIR={vector_dir}", f"-DFRAMES_DIR={frames_dir or ''}", f"-DPROTOCOL_DIR={protocol_dir or ''}",
         "-DRHONN_CAPACITY_DEFINES=" + ";".join(f"{k}={v}" for k, v in defines.items())])
    run(["cmake", "--build", str(build_dir), *(["--target", target] if target else [])])
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


def worst_stack(callgraphs: Path | list[Path], root: str, indirect: tuple[str, ...] = ()) -> tuple[int, list[str]]:
    """Deepest stack from ``root`` in GCC's -fcallgraph-info=su output (one
    or several objects' files): the sum of static frames along the heaviest
    call path (the code has no recursion and no dynamic frames). Calls
    through a function pointer go to each of ``indirect`` (the HAL's
    functions). Library routines (memcpy, the soft-float arithmetic) count
    as 0."""
    size: dict[str, int] = {}
    edges: dict[str, set[str]] = {}
    for callgraph in [callgraphs] if isinstance(callgraphs, Path) else callgraphs:
        text = callgraph.read_text()
        for title, label in re.findall(r'node: \{ title: "([^"]+)" label: "([^"]*)"', text):
            m = re.search(r"(\d+) bytes \((\w+)\)", label)
            if m and m.group(2) != "static":
                raise ToolError(f"{title}: {m.group(2)} stack frame, not bounded statically")
            size[title] = int(m.group(1)) if m else size.get(title, 0)
        for src, dst in re.findall(r'edge: \{ sourcename: "([^"]+)" targetname: "([^"]+)"', text):
            edges.setdefault(src, set()).update(indirect if dst == "__indirect_call" else (dst,))

    done: dict[str, tuple[int, list[str]]] = {}

    def deepest(node: str, seen: tuple[str, ...]) -> tuple[int, list[str]]:
        if node in seen:
            raise ToolError(f"recursion through {node}")
        if node not in done:
            best: tuple[int, list[str]] = (0, [])
            for nxt in sorted(edges.get(node, ())):
                best = max(best, deepest(nxt, seen + (node,)))
            done[node] = (size.get(node, 0) + best[0], [node.split(":")[-1]] + best[1])
        return done[node]

    return deepest(root, ())


def app_objects(build_dir: Path) -> dict[str, Path]:
    """The firmware's object files of the application image, by source name."""
    found = {obj.name.split(".")[0]: obj for lib in ("fw_app_m4.dir", "fw_secoc_m4.dir")
             for obj in (build_dir / "CMakeFiles" / lib).rglob("*.c.obj")}
    missing = [name for name in APP_OBJECTS if name not in found]
    if missing:
        raise ToolError(f"{build_dir}: no object for {missing}")
    return {name: found[name] for name in APP_OBJECTS}


_MAP_INPUT = re.compile(r"^ (\S+)?\s+0x([0-9a-f]+)\s+0x([0-9a-f]+)\s+(\S+)$")


def map_footprint(map_file: Path, objects: tuple[str, ...]) -> dict[str, dict[str, int]]:
    """Bytes each object puts in the image, from the linker's map file
    (after --gc-sections): code (.text), constants (.rodata), initialised
    (.data: in flash and in RAM) and zeroed RAM (.bss)."""
    out = {name: {"text": 0, "rodata": 0, "data": 0, "bss": 0} for name in objects}
    text = map_file.read_text()
    section = pending = None
    for line in text[text.index("Linker script and memory map"):].splitlines():
        head = re.match(r"^(\.\S+)", line)
        if head:
            section = head.group(1)
            continue
        m = _MAP_INPUT.match(line)
        if not m:
            name_only = re.match(r"^ (\.\S+)\s*$", line)
            pending = name_only.group(1) if name_only else None
            continue
        input_section = m.group(1) or pending or ""
        pending = None
        obj = re.search(r"\((\w+)\.c\.obj\)$", m.group(4))
        if not obj or obj.group(1) not in out or section not in (".text", ".data", ".bss"):
            continue
        kind = "rodata" if section == ".text" and input_section.startswith(".rodata") else section[1:]
        out[obj.group(1)][kind] += int(m.group(3), 16)
    return out


def library_bytes(elf: Path, own: dict[str, Path]) -> tuple[int, list[str]]:
    """Code of the library routines (libc, libgcc: memcpy, the soft-float
    double arithmetic) the firmware's objects call, from the image."""
    names = set().union(*(cycles.core_functions(o) for o in own.values()))
    lib = cycles.callees(elf, names) - names
    where = cycles.functions(elf, lib)
    by_address = {a: s for a, s in where.values()}   # aliases (__aeabi_dmul = __muldf3) once
    return sum(by_address.values()), sorted(lib)


def lines_sent(output: str) -> list[str]:
    """app_main.c's per-frame lines (the format of frames_expected.txt)."""
    return [line for line in output.splitlines() if line.startswith(("F ", "T "))]


def run_app(build_dir: Path, frames_dir: Path, cycle_frames: int) -> dict[str, object]:
    """Run the application image over the recorded stream, compare what it
    sent with the host's firmware, and measure it: footprint, stack, and
    (``cycle_frames`` > 0) the estimated cycles of the first frames."""
    elf = build_dir / "fw_app_m4.elf"
    output = run([*QEMU, "-kernel", str(elf)], timeout=300).stdout
    got, want = lines_sent(output), (frames_dir / "frames_expected.txt").read_text().splitlines()
    kinds = json.loads((frames_dir / "frames.json").read_text())["kinds"]
    diff = next((i for i, (a, b) in enumerate(zip(got, want)) if a != b), None)
    if diff is None and len(got) != len(want):
        diff = min(len(got), len(want))
    statuses: dict[str, int] = {}
    for line in got:
        if line.startswith("F "):
            statuses[line.split()[2]] = statuses.get(line.split()[2], 0) + 1
    objs = app_objects(build_dir)
    lib_code, lib_names = library_bytes(elf, objs)
    footprint = map_footprint(build_dir / "fw_app_m4.map", APP_OBJECTS)
    sizeof_app = int(field(output, r"sizeof\(fw_app\)"))
    flash = sum(v["text"] + v["rodata"] + v["data"] for v in footprint.values()) + lib_code
    stack, path = worst_stack([o.with_suffix("").with_suffix(".c.ci") for o in objs.values()], "fw_app_on_frame",
                              APP_HAL)
    report: dict[str, object] = {
        "frames": len(kinds),
        "identical_to_host": diff is None,
        "lines_compared": len(want),
        "first_difference": None if diff is None else {
            "line": diff, "m4": got[diff] if diff < len(got) else None, "host": want[diff] if diff < len(want) else None},
        "status_counts": statuses,
        "frames_sent": sum(line.startswith("T ") for line in got),
        "sizeof_fw_app": sizeof_app,
        "sizeof_rhonn_t": int(field(output, r"sizeof\(rhonn_t\)")),
        "sizeof_fw_mem_hal": int(field(output, r"sizeof\(fw_mem_hal\)")),
        "objects": footprint,
        "library_code_bytes": lib_code,
        "library_routines": lib_names,
        "soft_double_routines": [name for name in lib_names if SOFT_DOUBLE.match(name)],
        "flash_bytes": flash,
        "ram_bytes_static": sum(v["data"] + v["bss"] for v in footprint.values()) + sizeof_app,
        "fw_app_on_frame_worst_stack_bytes": stack,
        "fw_app_on_frame_worst_stack_path": path,
        "image": sizes(elf),
    }
    if cycle_frames > 0:
        report["cycles"] = frame_cycles(elf, objs, got, kinds, cycle_frames)
    return report


def frame_cycles(elf: Path, objs: dict[str, Path], lines: list[str], kinds: list[str], n: int) -> dict[str, object]:
    """Estimated cycles (cycles.py) of fw_app_on_frame over the first ``n``
    frames, by kind of frame, and of rhonn_step inside it."""
    try:
        est = cycles.estimate(elf, list(objs.values()), "fw_app_on_frame", harness=APP_HARNESS,
                              nested=("rhonn_step", objs["rhonn"]), args=[str(n)])
    except (RuntimeError, subprocess.SubprocessError) as exc:
        raise ToolError(f"cycle estimate: {exc}") from exc
    # what each frame was and did: its kind, its status, whether a Diagnostics frame followed
    frames: list[list[str]] = []
    for line in lines:
        if line.startswith("F "):
            frames.append([line.split()[2]])
        else:
            frames[-1].append(line.split()[1])
    each, steps = est.pop("cycles_each"), est["nested"].pop("cycles_each")
    step_of = est["nested"].pop("call_of_each")
    stepped = [k for k in range(len(each)) if kinds[k] == "measurement" and frames[k][0] in ("FW_OK", "FW_E_STEP")]
    # the step cycles inside each frame (a weight transfer's warm start steps too)
    in_frame: dict[int, int] = {}
    for k, s in zip(step_of, steps):
        in_frame[k] = in_frame.get(k, 0) + s
    groups: dict[str, list[int]] = {}
    overhead: list[int] = []
    for k, c in enumerate(each):
        kind = kinds[k]
        if kind == "measurement":
            kind += " + Diagnostics and Health" if "130" in frames[k][1:] else "" if k in stepped else " (rejected)"
        groups.setdefault(kind, []).append(c)
    overhead = [each[k] - in_frame[k] for k in stepped if k in in_frame and "130" not in frames[k][1:]]
    plain = groups.get("measurement", [0])
    own = set().union(*(cycles.core_functions(o) for o in objs.values()))
    by_function = est["cycles_per_call_by_function"]
    return {
        "frames": len(each),
        "by_kind": {kind: {"frames": len(v), "mean": sum(v) / len(v), "max": max(v)} for kind, v in groups.items()},
        "measurement_frame_mean": sum(plain) / len(plain),
        "measurement_frame_max": max(plain),
        "step_mean": est["nested"]["estimated_cycles_per_call"],
        "step_max": est["nested"]["estimated_cycles_max"],
        # a real-time loop's figures: the typical step and all but the slowest 1 %
        "step_median": sorted(steps)[len(steps) // 2] if steps else 0,
        "step_p99": cycles.percentile(steps, 0.99) if steps else 0,
        "steps": est["nested"]["calls"],
        "app_overhead_mean": sum(overhead) / len(overhead) if overhead else None,
        "library_cycles_per_frame": round(sum(v for k, v in by_function.items() if k not in own), 1),
        "soft_double_cycles_per_frame": round(sum(v for k, v in by_function.items() if SOFT_DOUBLE.match(k)), 1),
        "frame_target": FRAME_TARGET,
        "frame_target_met": max(plain) <= FRAME_TARGET,
        "instructions_per_frame": est["instructions_per_call"],
        "cycle_share_by_class": est["cycle_share_by_class"],
        "cycles_per_frame_by_function": dict(list(by_function.items())[:15]),
    }


def run_identifier(out: Path, config: Path, dbc: Path, trajectory: Path, n_frames: int,
                   cycle_frames: int) -> dict[str, object]:
    """The application image of another identifier over its recording (see the module docstring)."""
    import importlib.util

    from pyrhonn.configfile import load_config
    from pyrhonn.export import min_capacities

    script = ROOT / "firmware_sim" / "linux" / "build_runner.py"
    spec = importlib.util.spec_from_file_location("_m4_build_runner", script)
    build_runner = importlib.util.module_from_spec(spec)
    assert spec.loader is not None
    spec.loader.exec_module(build_runner)
    try:
        build_runner.write_identifier_sources(out / "protocol", config, dbc)
    except (OSError, ValueError) as exc:
        raise ToolError(str(exc)) from exc
    capacities = min_capacities(load_config(config).config)
    run([sys.executable, str(HERE / "make_vector.py"), str(out / "vector"), "--samples", "1"])  # CMake asks for one
    frames_dir = out / "frames"
    run([sys.executable, str(HERE / "make_frames.py"), str(frames_dir), "--frames", str(n_frames), "--identifier",
         str(config), "--dbc", str(dbc), "--trajectory", str(trajectory)])
    build_m4(out / "vector", out / "identifier", True, frames_dir, target="fw_app_m4.elf", capacities=capacities,
             protocol_dir=out / "protocol")
    kinds = json.loads((frames_dir / "frames.json").read_text())["kinds"]
    return {"identifier": str(config), "dbc": str(dbc), "capacities": capacities,
            "application": run_app(out / "identifier", frames_dir, min(cycle_frames, len(kinds)))}


def sizes(path: Path) -> dict[str, int]:
    out = run(["arm-none-eabi-size", str(path)]).stdout.splitlines()[1].split()
    return {"text": int(out[0]), "data": int(out[1]), "bss": int(out[2])}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=ROOT / "build" / "m4", help="build folder")
    ap.add_argument("--samples", type=int, default=2000, help="rows of the core's test vector (default 2000)")
    ap.add_argument("--frames", type=int, default=1000,
                    help="Measurements in the application's frame stream (default 1000; 0: no application run)")
    ap.add_argument("--cycle-frames", type=int, default=200,
                    help="frames of the stream whose cycles are estimated (default 200; 0: none)")
    ap.add_argument("--json", type=Path, help="write the report as JSON here")
    ap.add_argument("--identifier", type=Path, help="another identifier's config file (float32): build and run "
                                                    "its application image only; with --dbc and --trajectory")
    ap.add_argument("--dbc", type=Path, help="with --identifier: the DBC pyrhonn export --dbc wrote for it")
    ap.add_argument("--trajectory", type=Path, help="with --identifier: its recording (t, states, inputs)")
    args = ap.parse_args(argv)
    given = [args.identifier, args.dbc, args.trajectory]
    if any(g is not None for g in given) and any(g is None for g in given):
        ap.error("--identifier, --dbc, --trajectory: give all three, or none for the LIM")
    if args.samples < 1:
        ap.error(f"--samples: at least 1, got {args.samples}")
    if args.frames != 0 and args.frames < 20:
        ap.error(f"--frames: 0 or at least 20, got {args.frames}")
    if args.cycle_frames < 0:
        ap.error(f"--cycle-frames: at least 0, got {args.cycle_frames}")
    out = args.out.resolve()
    out.mkdir(parents=True, exist_ok=True)
    if args.identifier is not None and args.frames < 20:
        ap.error(f"--frames: at least 20 with --identifier, got {args.frames}")
    try:
        if args.identifier is not None:
            report = run_identifier(out, args.identifier.resolve(), args.dbc.resolve(), args.trajectory.resolve(),
                                    args.frames, args.cycle_frames)
            agree = bool(report["application"]["identical_to_host"])
        else:
            run([sys.executable, str(HERE / "make_vector.py"), str(out / "vector"), "--samples", str(args.samples)])
            frames_dir = out / "frames" if args.frames else None
            if frames_dir is not None:
                run([sys.executable, str(HERE / "make_frames.py"), str(frames_dir), "--frames", str(args.frames)])
            report: dict[str, object] = {"samples": args.samples, "capacities": LIM_CAPACITIES,
                                         "cycle_budget_168MHz_0.3ms": CYCLE_BUDGET}
            host = run([str(build_host(out / "vector", out))]).stdout
            agree = True
            for unroll in (True, False):
                name = "unrolled" if unroll else "generic"
                elf = build_m4(out / "vector", out / name, unroll, frames_dir if unroll else None)
                m4 = run([*QEMU, "-kernel", str(elf)], timeout=300).stdout
                same = predictions(m4) == predictions(host) and len(predictions(m4)) == args.samples
                agree = agree and same
                core_obj = next((out / name).glob("CMakeFiles/rhonn_m4.elf.dir/**/rhonn.c.obj"))
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
                "objects": {obj.name.split(".")[0]: sizes(obj)
                            for obj in sorted((out / "unrolled").glob("CMakeFiles/fw_secoc_m4.dir/**/fw_*.c.obj"))},
            }
            if frames_dir is not None:
                app = run_app(out / "unrolled", frames_dir, min(args.cycle_frames, len(
                    json.loads((frames_dir / "frames.json").read_text())["kinds"])))
                report["application"] = app
                agree = agree and bool(app["identical_to_host"])
    except ToolError as exc:
        print(f"run_m4: {exc}", file=sys.stderr)
        return 2
    text = json.dumps(report, indent=2)
    print(text)
    if args.json:
        atomic.write_text(args.json, text + "\n")
    return 0 if agree else 1


if __name__ == "__main__":
    sys.exit(main())
