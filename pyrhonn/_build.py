"""cffi (API mode) builders for the C core, one extension per precision.

``pyrhonn._rhonn_f64`` and ``pyrhonn._rhonn_f32`` are compiled from the very
same ``csrc/src/rhonn.c`` that firmware links, with the capacities of
``csrc/include/rhonn_capacity.h``. The cffi declarations are ``rhonn.h``
itself, run through the C preprocessor (so sizes are resolved and nothing is
restated by hand); cffi also checks every struct field's offset when the
extension is compiled.

Used by setup.py (``cffi_modules``); run directly to build in place.
"""
from __future__ import annotations

import os
import re
import shlex
import subprocess
from pathlib import Path

from cffi import FFI

ROOT = Path(__file__).resolve().parent.parent
INCLUDE = ROOT / "csrc" / "include"
# Integer macros exposed as lib.<NAME>; cffi takes their values from the
# compiled header ("..."), so they cannot drift either.
CONSTANTS = (
    "RHONN_MAX_STATES", "RHONN_MAX_INPUTS", "RHONN_MAX_TERMS", "RHONN_MAX_FACTORS", "RHONN_MAX_DELAY",
    "RHONN_MAX_POWER", "RHONN_MAX_PACKED", "RHONN_HISTORY_LEN", "RHONN_VERSION_MAJOR", "RHONN_VERSION_MINOR",
)


def header_declarations(dtype: str) -> str:
    """rhonn.h run through the C preprocessor for one precision: the exact
    declarations the extension is compiled against, every array size
    resolved, for cffi's cdef. The header is the single source of truth;
    nothing here restates it."""
    header = (INCLUDE / "rhonn.h").read_text()
    # cffi knows the standard types itself; only the project's own include
    # (rhonn_capacity.h, which sizes the arrays) is kept.
    body = re.sub(r"^\s*#\s*include\s*<.*>\s*$", "", header, flags=re.M)
    defines = ["-DRHONN_SINGLE"] if dtype == "float32" else []
    cc = shlex.split(os.environ.get("CC", "cc"))
    result = subprocess.run([*cc, "-E", "-P", "-x", "c", f"-I{INCLUDE}", *defines, "-"], input=body,
                            capture_output=True, text=True, check=False)
    if result.returncode != 0:
        raise RuntimeError(f"preprocessing rhonn.h failed: {result.stderr}")
    return "".join(f"#define {name} ...\n" for name in CONSTANTS) + result.stdout


def make_ffi(dtype: str) -> FFI:
    """An FFI builder for the float64 or float32 core."""
    if dtype not in ("float64", "float32"):
        raise ValueError(f"dtype: expected 'float64' or 'float32', got {dtype!r}")
    ffi = FFI()
    ffi.cdef(header_declarations(dtype))
    # Paths relative to the project root, where setup.py runs.
    ffi.set_source(
        f"pyrhonn._rhonn_{'f64' if dtype == 'float64' else 'f32'}",
        '#include "rhonn.h"',
        sources=["csrc/src/rhonn.c"],
        include_dirs=["csrc/include"],
        # The host has room for one unrolled EKF kernel per neuron size.
        define_macros=[("RHONN_UNROLL", "1")] + ([("RHONN_SINGLE", "1")] if dtype == "float32" else []),
        extra_compile_args=["-O2", "-ffp-contract=off", "-fno-fast-math"],
    )
    return ffi


ffi_f64 = make_ffi("float64")
ffi_f32 = make_ffi("float32")

if __name__ == "__main__":
    os.chdir(ROOT)
    for builder in (ffi_f64, ffi_f32):
        builder.compile(tmpdir=str(ROOT), verbose=True)
