"""Estimated Cortex-M4 cycles of the identifier core, from the instructions
QEMU executes.

QEMU does not model the DWT cycle counter, so the estimate weights every
instruction the core executes with its cost in the Cortex-M4 Technical
Reference Manual's instruction timing tables (processor core and FPv4-SP
FPU). QEMU runs the image one instruction per translation block
(``-singlestep -d exec,nochain``) and logs the address of each one it
executes inside the core's functions (``-dfilter``); the disassembly names
each address's instruction.

The weights (cycles):

=====================================  ======  ====================================
instruction                            cycles  note
=====================================  ======  ====================================
VDIV.F32, VSQRT.F32                      14
VMLA/VMLS/VNMLA/VNMLS/VFMA/VFMS.F32       3    not emitted with -ffp-contract=off
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

Limits: no flash wait states (a 168 MHz part has 5 and an ART accelerator),
no bus contention, no pipelining of back-to-back loads beyond the table,
divide costs at their middle value. Real silicon with zero-wait-state
memory should land near this figure; from flash without a cache, above it.

    python firmware_sim/cortex_m4/cycles.py IMAGE.elf CORE.obj [--steps-symbol rhonn_step]
"""
from __future__ import annotations

import argparse
import collections
import json
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

QEMU = ["qemu-system-arm", "-M", "mps2-an386", "-nographic", "-semihosting-config", "enable=on,target=native",
        "-icount", "shift=0", "-singlestep", "-d", "exec,nochain"]
#: libc and libgcc routines the core calls (struct copies); counted with it
HELPERS = ("memcpy", "memset", "__aeabi_memcpy", "__aeabi_memset", "__aeabi_uidiv", "__aeabi_idiv",
           "__aeabi_uldivmod", "__udivsi3", "__divsi3")

_LINE = re.compile(r"^\s*([0-9a-f]+):\s+(\S+)\s*(.*)$")
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


def disassemble(elf: Path) -> dict[int, Instruction]:
    out = subprocess.run(["arm-none-eabi-objdump", "-d", "--no-show-raw-insn", str(elf)], check=True,
                         capture_output=True, text=True).stdout
    rows = []
    for line in out.splitlines():
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


def estimate(elf: Path, core_obj: Path, step_symbol: str = "rhonn_step", timeout: float = 600.0) -> dict:
    """Run the image once under QEMU, logging the core's instructions, and
    return executed instructions and estimated cycles per call of
    ``step_symbol``, with the share of each instruction class."""
    names = core_functions(core_obj) | set(HELPERS)
    ranges = functions(elf, names)
    if step_symbol not in ranges:
        raise RuntimeError(f"{step_symbol} is not in {elf}")
    table = disassemble(elf)
    dfilter = ",".join(f"0x{a:x}+0x{max(s, 2):x}" for a, s in sorted(ranges.values()))
    proc = subprocess.Popen([*QEMU, "-dfilter", dfilter, "-kernel", str(elf)], stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True)
    counts: collections.Counter[tuple[int, bool]] = collections.Counter()
    prev: int | None = None
    assert proc.stderr is not None
    for line in proc.stderr:
        m = _TRACE.search(line)
        if not m:
            continue
        pc = int(m.group(1), 16)
        if prev is not None:
            ins = table.get(prev)
            counts[(prev, ins is not None and pc != prev + ins.size)] += 1
        prev = pc
    if prev is not None:
        counts[(prev, False)] += 1
    if proc.wait(timeout=timeout) != 0:
        raise RuntimeError(f"QEMU exited with {proc.returncode}")
    entry = ranges[step_symbol][0]
    steps = sum(n for (pc, _), n in counts.items() if pc == entry)
    if steps == 0:
        raise RuntimeError(f"{step_symbol} never ran")
    instructions = cycles = 0
    by_class: collections.Counter[str] = collections.Counter()
    by_function: collections.Counter[str] = collections.Counter()
    starts = sorted((a, s, name) for name, (a, s) in ranges.items())
    for (pc, taken), n in counts.items():
        ins = table.get(pc)
        if ins is None:
            continue
        w = weight(ins, taken)
        instructions += n
        cycles += w * n
        m = ins.mnemonic.split(".")[0]
        cls = ("vdiv" if m in ("vdiv", "vsqrt") else "fpu load/store" if m in ("vldr", "vstr", "vldm", "vstm", "vpush", "vpop")
               else "fpu" if m.startswith("v") else "load/store" if m[:3] in ("ldr", "str", "ldm", "stm", "pus", "pop")
               else "branch" if w in (1, 3) and (m.startswith("b") or m in ("cbz", "cbnz", "tbb", "tbh")) else "integer")
        by_class[cls] += w * n
        owner = next((name for a, s, name in starts if a <= pc < a + max(s, 2)), "?")
        by_function[owner] += w * n
    return {
        "calls": steps,
        "instructions_per_call": instructions / steps,
        "estimated_cycles_per_call": cycles / steps,
        "cycle_share_by_class": {k: round(v / cycles, 4) for k, v in by_class.most_common()},
        "cycles_per_call_by_function": {k: round(v / steps, 1) for k, v in by_function.most_common()},
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("elf", type=Path)
    ap.add_argument("core_obj", type=Path, help="the core's object file (its functions are counted)")
    ap.add_argument("--steps-symbol", default="rhonn_step")
    args = ap.parse_args(argv)
    print(json.dumps(estimate(args.elf, args.core_obj, args.steps_symbol), indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
