"""Estimated Cortex-M4 cycles of a function of the firmware (rhonn_step,
fw_app_on_frame), from the instructions QEMU executes.

QEMU does not model the DWT cycle counter, so the estimate weights every
instruction executed with its cost in the Cortex-M4 Technical Reference
Manual's instruction timing tables (processor core and FPv4-SP FPU). QEMU
runs the image one instruction per translation block (``-singlestep -d
exec,nochain``) and logs the address of each one it executes inside the
counted functions (``-dfilter``); the disassembly names each address's
instruction. Counted: the functions of the given object files and every
library routine they reach by direct calls (memcpy, the soft-float double
arithmetic), from each entry of the measured function until the program is
back in its caller (the harness, not counted), so one figure per call.

The weights (cycles):

=====================================  ======  ====================================
instruction                            cycles  note
=====================================  ======  ====================================
VDIV.F32, VSQRT.F32                      14
VMLA/VMLS/VNMLA/VNMLS/VFMA/VFMS.F32       3    no VFMA with -ffp-contract=off
other FPU data processing, VMOV, VCMP     1    VADD, VSUB, VMUL, VNEG, VABS, VCVT
VLDR, VSTR                                2
VLDM, VSTM, VPUSH, VPOP                 1 + N  N registers
LDR*, STR* (one register)                 2
LDM, STM, PUSH                          1 + N  POP with PC: 1 + N + 2
SDIV, UDIV                                7    2-12 depending on the operands
MLA, MLS, UMULL, SMULL, ...               2    MUL: 1
branch, taken                             3    1 + a pipeline refill of 2
branch, not taken                         1    (the next executed address tells)
other integer instructions                1
=====================================  ======  ====================================

Limits: no flash wait states (a 168 MHz part has 5 and an ART accelerator:
the figure is that of code in zero-wait-state memory); no pipelining effects
beyond the table (back-to-back loads are charged 2 each where the M4 can
overlap them to 1 + N, FPU result hazards and branch-target alignment are
not charged); no bus contention, no interrupts; divides at their middle
value. Real silicon with zero-wait-state memory should land near this
figure; from flash without a cache, above it.

    python firmware_sim/cortex_m4/cycles.py IMAGE.elf OBJECT... [--steps-symbol rhonn_step] [--harness main]
"""
from __future__ import annotations

import argparse
import collections
import json
import re
import subprocess
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

QEMU = ["qemu-system-arm", "-M", "mps2-an386", "-nographic", "-semihosting-config", "enable=on,target=native",
        "-icount", "shift=0", "-singlestep", "-d", "exec,nochain"]

_LINE = re.compile(r"^\s*([0-9a-f]+):\s+(\S+)\s*(.*)$")
_FUNCTION = re.compile(r"^[0-9a-f]+ <([^>]+)>:$")
_CALL = re.compile(r"^b(l|lx|\.w|\.n)?$")
_TARGET = re.compile(r"<([^>+]+)(\+0x[0-9a-f]+)?>")
_TRACE = re.compile(r"Trace \d+: 0x[0-9a-f]+ \[[0-9a-f]+/([0-9a-f]+)/")


@dataclass(frozen=True)
class Instruction:
    address: int
    size: int
    mnemonic: str
    operands: str


def functions(elf: Path, names: set[str]) -> dict[str, tuple[int, int]]:
    """Address and size of the named functions in the image."""
    out = subprocess.run(["arm-none-eabi-nm", "-S", str(elf)], check=True, capture_output=True, text=True).stdout
    found = {}
    for line in out.splitlines():
        parts = line.split()
        if len(parts) == 4 and parts[2] in "tT" and parts[3] in names:
            found[parts[3]] = (int(parts[0], 16) & ~1, int(parts[1], 16))
    return found


def core_functions(obj: Path) -> set[str]:
    """The functions a core object file defines."""
    out = subprocess.run(["arm-none-eabi-nm", str(obj)], check=True, capture_output=True, text=True).stdout
    return {parts[2] for parts in (line.split() for line in out.splitlines()) if len(parts) == 3 and parts[1] in "tT"}


def _objdump(elf: Path) -> str:
    return subprocess.run(["arm-none-eabi-objdump", "-d", "--no-show-raw-insn", str(elf)], check=True,
                          capture_output=True, text=True).stdout


def callees(elf: Path, roots: set[str]) -> set[str]:
    """``roots`` and every function they reach by direct calls and branches
    to other functions (the library routines the code calls: memcpy, the
    soft-float double arithmetic, ...), from the image's disassembly.
    Indirect calls are not followed: the caller names their targets' objects."""
    edges: dict[str, set[str]] = collections.defaultdict(set)
    current = None
    for line in _objdump(elf).splitlines():
        f = _FUNCTION.match(line)
        if f:
            current = f.group(1)
            continue
        m = _LINE.match(line)
        if m and current and (_CALL.match(m.group(2)) or m.group(2) in ("cbz", "cbnz")):
            t = _TARGET.search(m.group(3))
            if t and t.group(1) != current:
                edges[current].add(t.group(1))
    seen, todo = set(roots), list(roots)
    while todo:
        for nxt in edges.get(todo.pop(), ()):
            if nxt not in seen:
                seen.add(nxt)
                todo.append(nxt)
    return seen


def disassemble(elf: Path) -> dict[int, Instruction]:
    rows = []
    for line in _objdump(elf).splitlines():
        m = _LINE.match(line)
        if m:
            rows.append((int(m.group(1), 16), m.group(2), m.group(3)))
    table = {}
    for (addr, mnem, ops), nxt in zip(rows, rows[1:] + [(rows[-1][0] + 4, "", "")]):
        table[addr] = Instruction(addr, max(2, min(4, nxt[0] - addr)), mnem.lower(), ops.lower())
    return table


def _registers(operands: str) -> int:
    m = re.search(r"\{([^}]*)\}", operands)
    if not m:
        return 1
    count = 0
    for part in m.group(1).split(","):
        part = part.strip()
        r = re.fullmatch(r"([rsd])(\d+)-[rsd](\d+)", part)
        count += int(r.group(3)) - int(r.group(2)) + 1 if r else 1
    return count


def weight(ins: Instruction, taken: bool) -> int:
    """Cycles of one executed instruction (see the module table)."""
    m, ops = ins.mnemonic.split(".")[0], ins.operands
    if m in ("vdiv", "vsqrt"):
        return 14
    if m in ("vmla", "vmls", "vnmla", "vnmls", "vfma", "vfms", "vfnma", "vfnms"):
        return 3
    if m in ("vldr", "vstr"):
        return 2
    if m in ("vldm", "vstm", "vpush", "vpop", "vldmia", "vstmia", "vldmdb", "vstmdb"):
        return 1 + _registers(ops)
    if m.startswith("v"):
        return 1
    if m in ("pop", "ldm", "ldmia", "ldmfd") or m.startswith("ldm"):
        return 1 + _registers(ops) + (2 if "pc" in ops else 0)
    if m in ("push", "stm", "stmia", "stmdb") or m.startswith("stm"):
        return 1 + _registers(ops)
    if m.startswith("ldr") or m.startswith("str"):
        return 2
    if m in ("sdiv", "udiv"):
        return 7
    if m in ("mla", "mls", "umull", "smull", "umlal", "smlal"):
        return 2
    if m in ("b", "bl", "blx", "bx", "cbz", "cbnz", "tbb", "tbh") or re.fullmatch(r"b(eq|ne|cs|cc|hs|lo|mi|pl|vs|vc|hi|ls|ge|lt|gt|le)", m):
        return 3 if taken else 1
    return 1


def _class(m: str, w: int) -> str:
    if m in ("vdiv", "vsqrt"):
        return "vdiv"
    if m in ("vldr", "vstr", "vldm", "vstm", "vpush", "vpop"):
        return "fpu load/store"
    if m.startswith("v"):
        return "fpu"
    if m[:3] in ("ldr", "str", "ldm", "stm", "pus", "pop"):
        return "load/store"
    if w in (1, 3) and (m.startswith("b") or m in ("cbz", "cbnz", "tbb", "tbh")):
        return "branch"
    return "integer"


def percentile(values: list[float], q: float) -> float:
    """The q-quantile of values (nearest rank, from below)."""
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))]


def estimate(elf: Path, objects: Path | Sequence[Path], step_symbol: str = "rhonn_step", *,
             harness: Sequence[str] = ("main",), nested: tuple[str, Path] | None = None,
             args: Sequence[str] = (), timeout: float = 600.0, by_address: bool = False) -> dict:
    """Run the image once under QEMU and estimate the cycles of every call
    of ``step_symbol``: from its entry until the program is back in one of
    the ``harness`` functions (its callers), counting the instructions of
    the functions ``objects`` define and the library helpers they call.
    Whatever the harness itself runs (printing, libc) is not counted.

    ``nested`` = (symbol, object): also the cycles of each call of that
    symbol made inside a call (e.g. rhonn_step inside fw_app_on_frame),
    from its entry until control is back in a counted function that the
    object does not define, and the index of the call each was made in.
    ``args``: the image's semihosting command line. ``by_address``: also
    the cycles per call spent at each instruction address (for
    ``source_lines``).

    Returns the calls, instructions and estimated cycles per call (mean,
    min, max, 99th percentile and every call's in ``cycles_each``), and the
    share of each instruction class and function."""
    objs = [objects] if isinstance(objects, Path) else list(objects)
    own = set().union(*(core_functions(o) for o in objs))
    names = callees(elf, own)
    ranges = functions(elf, names | set(harness))
    if step_symbol not in ranges:
        raise RuntimeError(f"{step_symbol} is not in {elf}")
    missing = [h for h in harness if h not in ranges]
    if missing:
        raise RuntimeError(f"harness functions {missing} are not in {elf}")
    table = disassemble(elf)
    dfilter = ",".join(f"0x{a:x}+0x{max(s, 2):x}" for a, s in sorted(ranges.values()))
    semihosting = ["-semihosting-config", "enable=on,target=native" + "".join(f",arg={a}" for a in ("image", *args))]
    cmd = [*QEMU[:QEMU.index("-semihosting-config")], *semihosting, *QEMU[QEMU.index("-semihosting-config") + 2:]]
    starts = sorted((a, s, name) for name, (a, s) in ranges.items())
    owner_of: dict[int, str] = {}

    def owner(pc: int) -> str:
        if pc not in owner_of:
            owner_of[pc] = next((name for a, s, name in starts if a <= pc < a + max(s, 2)), "?")
        return owner_of[pc]

    entry = ranges[step_symbol][0]
    outside = {name for name in harness}
    nested_entry = ranges[nested[0]][0] if nested and nested[0] in ranges else None
    # the nested code: its object's functions and the library routines (not in ``objects``)
    nested_own = core_functions(nested[1]) | (names - own) if nested else set()
    counts: collections.Counter[tuple[int, bool]] = collections.Counter()
    per_call: list[int] = []
    per_nested: list[int] = []
    nested_in: list[int] = []  # the call of step_symbol each nested call was made in
    per_call_instructions: list[int] = []
    inside = in_nested = False
    proc = subprocess.Popen([*cmd, "-dfilter", dfilter, "-kernel", str(elf)], stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True)
    assert proc.stderr is not None
    prev: int | None = None

    def account(pc: int, taken: bool) -> None:
        nonlocal in_nested
        ins = table.get(pc)
        if ins is None:
            return
        w = weight(ins, taken)
        counts[(pc, taken)] += 1
        per_call[-1] += w
        per_call_instructions[-1] += 1
        if in_nested:
            per_nested[-1] += w

    for line in proc.stderr:
        m = _TRACE.search(line)
        if not m:
            continue
        pc = int(m.group(1), 16)
        if prev is not None and inside:
            ins = table.get(prev)
            account(prev, ins is not None and pc != prev + ins.size)
        name = owner(pc)
        if pc == entry:
            inside = True
            per_call.append(0)
            per_call_instructions.append(0)
        elif name in outside:
            inside = in_nested = False
        if inside:
            if pc == nested_entry:
                in_nested = True
                per_nested.append(0)
                nested_in.append(len(per_call) - 1)
            elif in_nested and name not in nested_own:
                in_nested = False
        prev = pc
    if proc.wait(timeout=timeout) != 0:
        raise RuntimeError(f"QEMU exited with {proc.returncode}")
    if not per_call:
        raise RuntimeError(f"{step_symbol} never ran")
    by_class: collections.Counter[str] = collections.Counter()
    by_function: collections.Counter[str] = collections.Counter()
    cycles = 0
    for (pc, taken), n in counts.items():
        ins = table[pc]
        w = weight(ins, taken)
        cycles += w * n
        by_class[_class(ins.mnemonic.split(".")[0], w)] += w * n
        by_function[owner(pc)] += w * n
    calls = len(per_call)
    out = {
        "calls": calls,
        "instructions_per_call": sum(per_call_instructions) / calls,
        "estimated_cycles_per_call": cycles / calls,
        "estimated_cycles_min": min(per_call),
        "estimated_cycles_max": max(per_call),
        "estimated_cycles_p99": percentile(per_call, 0.99),
        "cycles_each": per_call,
        "instructions_each": per_call_instructions,
        "cycle_share_by_class": {k: round(v / cycles, 4) for k, v in by_class.most_common()},
        "cycles_per_call_by_function": {k: round(v / calls, 1) for k, v in by_function.most_common()},
    }
    if by_address:
        at: collections.Counter[int] = collections.Counter()
        for (pc, taken), n in counts.items():
            at[pc] += weight(table[pc], taken) * n
        out["cycles_per_call_by_address"] = {pc: c / calls for pc, c in at.items()}
    if nested:
        out["nested"] = {"symbol": nested[0], "calls": len(per_nested),
                         "estimated_cycles_per_call": sum(per_nested) / len(per_nested) if per_nested else 0.0,
                         "estimated_cycles_max": max(per_nested, default=0), "cycles_each": per_nested,
                         "call_of_each": nested_in}
    return out


def source_lines(elf: Path, by_address: dict[int, float]) -> list[tuple[str, float]]:
    """The cycles of ``by_address`` summed per source line (file:line, from
    the image's debug information), most expensive first."""
    addrs = sorted(by_address)
    out = subprocess.run(["arm-none-eabi-addr2line", "-e", str(elf)], input="".join(f"0x{a:x}\n" for a in addrs),
                         check=True, capture_output=True, text=True).stdout.splitlines()
    per_line: collections.Counter[str] = collections.Counter()
    for a, where in zip(addrs, out):
        per_line[Path(where.split(" ")[0]).name if ":" in where else where] += by_address[a]
    return per_line.most_common()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("elf", type=Path)
    ap.add_argument("objects", type=Path, nargs="+", help="object files whose functions are counted")
    ap.add_argument("--steps-symbol", default="rhonn_step", help="the function whose calls are estimated")
    ap.add_argument("--harness", default="main", help="comma-separated callers of it, not counted (default main)")
    ap.add_argument("--args", default="", help="comma-separated command line for the image (semihosting)")
    ap.add_argument("--lines", type=int, default=0, metavar="N",
                    help="also list the N source lines that cost the most cycles per call")
    args = ap.parse_args(argv)
    if args.lines < 0:
        ap.error(f"--lines must be >= 0, not {args.lines}")
    for path in (args.elf, *args.objects):
        if not path.is_file():
            ap.error(f"{path}: no such file")
    try:
        est = estimate(args.elf, args.objects, args.steps_symbol, harness=args.harness.split(","),
                       args=[a for a in args.args.split(",") if a], by_address=args.lines > 0)
        if args.lines > 0:
            est["cycles_per_call_by_line"] = dict(
                (k, round(v, 1)) for k, v in source_lines(args.elf, est.pop("cycles_per_call_by_address"))[:args.lines])
    except (RuntimeError, OSError, subprocess.SubprocessError) as exc:
        print(f"cycles: {exc}", file=sys.stderr)
        return 2
    est.pop("cycles_each")
    print(json.dumps(est, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
