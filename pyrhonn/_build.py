"""cffi (API mode) builders for the C core, one extension per precision, and
for the firmware application of firmware_sim (``pyrhonn._fwapp``).

``pyrhonn._rhonn_f64`` and ``pyrhonn._rhonn_f32`` are compiled from the very
same ``csrc/src/rhonn.c`` that firmware links, with ``rhonn_population.c``
(:data:`CORE_SOURCES`; its member loops also compiled for AVX2 and AVX-512F,
``RHONN_TARGET_CLONES``, the CPU's widest picked at load time). Their capacities are larger
than the firmware default of ``csrc/include/rhonn_capacity.h``, sized for
structure search on the host (``pyrhonn select``): :data:`CAPACITIES`, which
the environment variable ``PYRHONN_CAPACITIES`` overrides at build time, e.g.
``PYRHONN_CAPACITIES="TERMS=32,DELAY=128"`` (names with or without the
``RHONN_MAX_`` prefix; the ones not given keep their value here).

Beside them, ``pyrhonn._rhonn_small_f64`` and ``pyrhonn._rhonn_small_f32``
are the same sources built with :data:`SMALL_CAPACITIES` (the firmware
default): room for the paper's examples and the LIM, in a ``rhonn_t`` over
20 times smaller whose arrays have short strides, with the unrolled kernels.
:class:`pyrhonn.Identifier` runs a config on the smallest build that holds
it; the builds give the same results bit for bit (tested), so which one runs
is invisible but for speed. ``pyrhonn info`` prints what the installed
builds hold. The firmware application (``pyrhonn._fwapp``) keeps the
firmware's own capacities. ``pyrhonn._csvtext`` is the CSV text codec of the
data files and predictions (:mod:`pyrhonn.csvcodec`; host code, no core).

The EKF kernel is unrolled per neuron size (``RHONN_UNROLL``) only when
``RHONN_MAX_TERMS`` is at most 16, the most the core unrolls; above that the
generic kernel runs (same results, bit for bit; see ``bench/``).

The cffi declarations are ``rhonn.h``
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
import tempfile
from pathlib import Path

from cffi import FFI

ROOT = Path(__file__).resolve().parent.parent
INCLUDE = ROOT / "csrc" / "include"
# Integer macros exposed as lib.<NAME>; cffi takes their values from the
# compiled header ("..."), so they cannot drift either.
CONSTANTS = (
    "RHONN_MAX_STATES", "RHONN_MAX_INPUTS", "RHONN_MAX_TERMS", "RHONN_MAX_FACTORS", "RHONN_MAX_DELAY",
    "RHONN_MAX_POWER", "RHONN_MAX_PACKED", "RHONN_HISTORY_LEN", "RHONN_SAMPLE_LEN", "RHONN_MAX_ENTRIES",
    "RHONN_VERSION_MAJOR", "RHONN_VERSION_MINOR",
)
#: The core's sources compiled into each precision's extension (as in CMake).
CORE_SOURCES = ("csrc/src/rhonn.c", "csrc/src/rhonn_population.c")
#: Its public headers the extension declares, in order (each includes the ones before).
CORE_HEADERS = ("rhonn.h", "rhonn_population.h")
#: The integer macros of the core extensions: CONSTANTS and rhonn_population.h's capacity.
CORE_CONSTANTS = CONSTANTS + ("RHONN_MAX_POPULATION",)
#: Host glue compiled into each core extension (not part of the core):
#: ``Identifier.step``'s fast path steps through one pointer to a struct of
#: its preallocated buffers, the cheapest call cffi makes (one argument to
#: convert instead of rhonn_step's five: about 75 ns less per step).
#:
#: The prediction goes straight into the next free row of a block of rows
#: (``rows``, ``n_rows`` of them, ``n`` values each, ``next_row`` the first
#: free one), and the call returns that row's index: the fast path returns
#: the row itself as its array (see ``Identifier._fast_step``), about
#: 150 ns less per step than copying a shared buffer into a new array. A
#: failed step returns minus its rhonn_status and takes no row. A used-up
#: block is signalled before anything is read or touched
#: (``PYRHONN_STEP_NO_ROW``), and the caller brings a new block and calls
#: again. Each call names the row it wrote, so a call whose result the
#: caller never takes (an exception between the call and the hand-out)
#: only leaves a row unused.
STEP_GLUE_DECLARATIONS = """
typedef struct {
    rhonn_t *net;
    rhonn_real *x;
    rhonn_real *u;
    uint8_t *valid;
    rhonn_real *rows;
    size_t n_rows, next_row, n;
    size_t x_bytes, u_bytes, valid_bytes;
    rhonn_population_work *work;
} pyrhonn_step_call;
int pyrhonn_step_from(pyrhonn_step_call *call, const char *x, const char *u, const char *valid);
int pyrhonn_step_settle(pyrhonn_step_call *call);
"""
#: ``pyrhonn_step_from`` takes the arguments' bytes (``ndarray.tobytes()``,
#: whose length the caller has checked: the array's dtype and shape): cffi
#: passes a bytes object to a ``char *`` without a copy or the buffer
#: protocol, which made a ``memmove`` from an array cost about 4x a
#: ``tobytes``. The bytes are copied into the call's own buffers, where
#: ``rhonn_step`` reads them aligned. With a workspace (``work``), the step
#: runs in the lanes (``rhonn_wide_step``), the identifier's learning state
#: lent to them from the first such step until ``pyrhonn_step_settle``
#: gives it back (lent while ``work->holder`` is the net: the core's own
#: record of the loan).
STEP_GLUE = """
#include <limits.h>
#include <string.h>
#define PYRHONN_STEP_NO_ROW INT_MIN
""" + STEP_GLUE_DECLARATIONS + """
int pyrhonn_step_from(pyrhonn_step_call *call, const char *x, const char *u, const char *valid)
{
    rhonn_status st;
    if (call->next_row >= call->n_rows) {
        return PYRHONN_STEP_NO_ROW;
    }
    memcpy(call->x, x, call->x_bytes);
    if (u != NULL) {
        memcpy(call->u, u, call->u_bytes);
    }
    if (valid != NULL) {
        memcpy(call->valid, valid, call->valid_bytes);
    }
    if (call->work != NULL && call->work->holder != call->net) {
        st = rhonn_wide_begin(call->net, call->work);
        if (st == RHONN_E_CONFIG) { /* the lanes cannot hold it: rhonn_step from now on */
            call->work = NULL;
        } else if (st != RHONN_OK) {
            return -(int)st;
        }
    }
    if (call->work == NULL) {
        st = rhonn_step(call->net, call->x, call->u, valid != NULL ? call->valid : NULL,
                        call->rows + call->n * call->next_row);
    } else {
        st = rhonn_wide_step(call->net, call->work, call->x, call->u, valid != NULL ? call->valid : NULL,
                             call->rows + call->n * call->next_row);
    }
    if (st != RHONN_OK) {
        return -(int)st;
    }
    return (int)call->next_row++;
}

int pyrhonn_step_settle(pyrhonn_step_call *call)
{
    rhonn_status st;
    if (call->work == NULL || call->work->holder != call->net) {
        return 0; /* nothing lent */
    }
    st = rhonn_wide_end(call->net, call->work);
    return st != RHONN_OK ? -(int)st : 0;
}
"""

#: Capacities of the Python extension (``RHONN_MAX_*``): room for structure
#: search (64 terms per neuron, 16 states and inputs, delays up to 64,
#: products of up to 4 factors). Override with PYRHONN_CAPACITIES.
CAPACITIES: dict[str, int] = {
    "RHONN_MAX_STATES": 16, "RHONN_MAX_INPUTS": 16, "RHONN_MAX_TERMS": 64, "RHONN_MAX_FACTORS": 4,
    "RHONN_MAX_DELAY": 64, "RHONN_MAX_POWER": 8,
}
#: Capacities of the small pair of extensions (``pyrhonn._rhonn_small_*``):
#: the firmware default of rhonn_capacity.h, which holds the paper's examples
#: and the LIM with room to spare (8 states, 4 inputs, 16 terms per neuron,
#: products of 4 factors, delays up to 8, powers up to 8); not overridden by
#: PYRHONN_CAPACITIES (a config that does not fit runs on the large build).
SMALL_CAPACITIES: dict[str, int] = {
    "RHONN_MAX_STATES": 8, "RHONN_MAX_INPUTS": 4, "RHONN_MAX_TERMS": 16, "RHONN_MAX_FACTORS": 4,
    "RHONN_MAX_DELAY": 8, "RHONN_MAX_POWER": 8,
}
#: The most terms the core's unrolled kernels cover (``RHONN_UNROLL`` in rhonn.c).
UNROLL_MAX_TERMS = 16
_LIMITS = {"RHONN_MAX_DELAY": (0, 254)}  # the others are 1..255 (rhonn_capacity.h)


def capacities(spec: str | None = None) -> dict[str, int]:
    """The capacities to build with: :data:`CAPACITIES` updated by ``spec``
    (``"NAME=VALUE,..."``; default: the PYRHONN_CAPACITIES environment
    variable). ValueError naming PYRHONN_CAPACITIES for a bad entry."""
    text = os.environ.get("PYRHONN_CAPACITIES", "") if spec is None else spec
    caps = dict(CAPACITIES)
    for item in (part.strip() for part in text.split(",")):
        if not item:
            continue
        name, sep, value = item.partition("=")
        key = name.strip().upper()
        key = key if key.startswith("RHONN_MAX_") else f"RHONN_MAX_{key}"
        if not sep or key not in caps:
            raise ValueError(f"PYRHONN_CAPACITIES: {item!r}: expected NAME=VALUE with NAME one of "
                             f"{', '.join(n[len('RHONN_MAX_'):] for n in caps)}")
        lo, hi = _LIMITS.get(key, (1, 255))
        if not value.strip().isdigit() or not lo <= int(value) <= hi:
            raise ValueError(f"PYRHONN_CAPACITIES: {item!r}: {key} must be a whole number in {lo}..{hi}")
        caps[key] = int(value)
    return caps


def capacity_macros(caps: dict[str, int]) -> list[tuple[str, str]]:
    """The -D macros of a build with capacities ``caps`` (unrolled kernels when they fit)."""
    unroll = "1" if caps["RHONN_MAX_TERMS"] <= UNROLL_MAX_TERMS else "0"
    return [(name, str(value)) for name, value in caps.items()] + [("RHONN_UNROLL", unroll)]


def header_declarations(dtype: str, caps: dict[str, int] | None = None) -> str:
    """rhonn.h and rhonn_population.h run through the C preprocessor for one
    precision: the exact declarations the extension is compiled against,
    every array size resolved, for cffi's cdef. The headers are the single
    source of truth; nothing here restates them."""
    header = "".join((INCLUDE / name).read_text() for name in CORE_HEADERS)
    # cffi knows the standard types itself; only the project's own include
    # (rhonn_capacity.h, which sizes the arrays) is kept.
    body = re.sub(r"^\s*#\s*include\s*<.*>\s*$", "", header, flags=re.M)
    defines = ["-DRHONN_SINGLE"] if dtype == "float32" else []
    defines += [f"-D{name}={value}" for name, value in (caps or {}).items()]
    cc = shlex.split(os.environ.get("CC", "cc"))
    result = subprocess.run([*cc, "-E", "-P", "-x", "c", f"-I{INCLUDE}", *defines, "-"], input=body,
                            capture_output=True, text=True, check=False)
    if result.returncode != 0:
        raise RuntimeError(f"preprocessing rhonn.h failed: {result.stderr}")
    return "".join(f"#define {name} ...\n" for name in CORE_CONSTANTS) + result.stdout


def build_depends(include_dirs: tuple[str, ...] | list[str]) -> list[str]:
    """What an extension's build depends on beyond its sources, relative to
    the project root: the headers of its include folders and this file (its
    flags and capacities). setuptools rebuilds an extension only when one of
    its sources or of these is newer than it, so without them a changed
    header or flag would leave a stale extension to install."""
    headers = sorted(str(h.relative_to(ROOT)) for d in include_dirs for h in (ROOT / d).glob("*.h"))
    return headers + [str(Path(__file__).resolve().relative_to(ROOT))]


def module_name(dtype: str, small: bool = False) -> str:
    """The extension module of one precision, large (default) or small build."""
    return f"pyrhonn._rhonn_{'small_' if small else ''}{'f64' if dtype == 'float64' else 'f32'}"


def make_ffi(dtype: str, caps: dict[str, int] | None = None, small: bool = False, *,
             vector_unit: str | None = None, module: str | None = None) -> FFI:
    """An FFI builder for the float64 or float32 core with capacities
    ``caps`` (default :func:`capacities`, or :data:`SMALL_CAPACITIES` for
    the ``small`` build, which is another module). With ``vector_unit``
    (``"avx512f"``, ``"avx2"`` or ``"default"``, x86-64 only), the lanes'
    kernels are compiled for that unit alone instead of cloned for each
    (``RHONN_POP_TARGET``), as module ``module``: bench/bench_wide.py's
    builds, which measure each unit a CPU has."""
    if vector_unit not in (None, "avx512f", "avx2", "default"):
        raise ValueError(f"vector_unit: expected 'avx512f', 'avx2' or 'default', got {vector_unit!r}")
    if dtype not in ("float64", "float32"):
        raise ValueError(f"dtype: expected 'float64' or 'float32', got {dtype!r}")
    caps = (dict(SMALL_CAPACITIES) if small else capacities()) if caps is None else caps
    ffi = FFI()
    # RHONN_UNROLL is a build option of rhonn.c, not of the header: declared here so `pyrhonn info` can say.
    ffi.cdef(header_declarations(dtype, caps) + "#define RHONN_UNROLL ...\n" + STEP_GLUE_DECLARATIONS
             + "#define PYRHONN_STEP_NO_ROW ...\n")
    # Paths relative to the project root, where setup.py runs; absolute for a module compiled
    # elsewhere (FFI.compile runs the compiler in its own folder).
    def here(path: str) -> str:
        return str(ROOT / path) if module else path

    clones = [("RHONN_TARGET_CLONES", "1")] if vector_unit is None else [("RHONN_TARGET_CLONES", "0")] + (
        [("RHONN_POP_TARGET", f'"{vector_unit}"')] if vector_unit != "default" else [])
    ffi.set_source(
        module or module_name(dtype, small),
        "".join(f'#include "{name}"\n' for name in CORE_HEADERS) + STEP_GLUE,
        sources=[here(source) for source in CORE_SOURCES],
        include_dirs=[here("csrc/include")],
        depends=build_depends(["csrc/include"]),
        # The host has room for one unrolled EKF kernel per neuron size (up to 16 terms).
        define_macros=capacity_macros(caps) + clones
        + ([("RHONN_SINGLE", "1")] if dtype == "float32" else []),
        # -O3 as CMake's Release build of the core: about 10% off the LIM's
        # batched step against -O2 (same run). Strict IEEE arithmetic either
        # way (no contraction, no reassociation), so the same bits as the
        # -O2 builds of tests/test_export.py and of the firmware.
        extra_compile_args=["-O3", "-ffp-contract=off", "-fno-fast-math"],
    )
    return ffi


FIRMWARE = ROOT / "firmware_sim"
FIRMWARE_INCLUDES = ("csrc/include", "firmware_sim/app", "firmware_sim/generated", "firmware_sim/config")
FIRMWARE_SOURCES = ("csrc/src/rhonn.c", "firmware_sim/app/fw_app.c", "firmware_sim/app/fw_protocol.c",
                    "firmware_sim/app/fw_hal_mem.c", "firmware_sim/app/fw_secoc.c", "firmware_sim/app/fw_aes_cmac.c",
                    "firmware_sim/generated/rhonn_id.c")
FIRMWARE_CONSTANTS = CONSTANTS + (
    "FW_N_STATES", "FW_N_INPUTS", "FW_WEIGHTS_PER_FRAME", "FW_MAX_FRAME_LEN", "FW_MEM_HAL_DEPTH", "FW_FRAME_FD",
    "FW_FRAME_BRS", "FW_CAN_EFF_FLAG", "FW_CAN_RTR_FLAG", "FW_CAN_ERR_FLAG", "FW_SECOC", "FW_SECOC_FV_BYTES",
    "FW_SECOC_MAC_BYTES", "FW_SECOC_TRAILER_BYTES", "FW_SECOC_ACCEPTANCE_WINDOW", "FW_AES128_KEY", "FW_AES_BLOCK",
)
# Host glue of pyrhonn._fwapp: the in-memory HAL with the host's monotonic
# clock, and the DBC the extension was built from (so the Python side of the
# protocol can never read another one).
FIRMWARE_GLUE = """
#include <time.h>
#include "fw_app.h"
#include "fw_hal_mem.h"
#include "rhonn_id.h"
#include "fw_secoc_key.h"

uint64_t fwpy_now_ns(void)
{
    struct timespec ts;
    if (clock_gettime(CLOCK_MONOTONIC, &ts) != 0) return 0;
    return (uint64_t)ts.tv_sec * 1000000000u + (uint64_t)ts.tv_nsec;
}

static fw_status fwpy_host_now(void *ctx, uint64_t *ns)
{
    (void)ctx;
    *ns = fwpy_now_ns();
    return *ns ? FW_OK : FW_E_HAL;
}

fw_status fwpy_bind_hal(fw_mem_hal *m, fw_hal *hal, int host_clock)
{
    fw_status st = fw_mem_hal_init(m, hal);
    if (st == FW_OK && host_clock) hal->now = fwpy_host_now;
    return st;
}

/* The public test key compiled into this build's firmware
 * (config/fw_secoc_key.h), for the simulated rig. A provisioned key
 * (FW_SECOC_KEY_HEADER) is not handed out: 0 bytes. */
#if FW_SECOC_KEY_IS_TEST_KEY
static const unsigned char fwpy_secoc_key_bytes[FW_AES128_KEY] = FW_SECOC_KEY_BYTES;
size_t fwpy_secoc_key(const unsigned char **key)
{
    *key = fwpy_secoc_key_bytes;
    return sizeof fwpy_secoc_key_bytes;
}
#else
size_t fwpy_secoc_key(const unsigned char **key)
{
    *key = NULL;
    return 0;
}
#endif

static const unsigned char fwpy_dbc_bytes[] = {%s};
size_t fwpy_dbc(const unsigned char **text)
{
    *text = fwpy_dbc_bytes;
    return sizeof fwpy_dbc_bytes;
}
"""
FIRMWARE_GLUE_CDEF = """
uint64_t fwpy_now_ns(void);
fw_status fwpy_bind_hal(fw_mem_hal *m, fw_hal *hal, int host_clock);
size_t fwpy_dbc(const unsigned char **text);
size_t fwpy_secoc_key(const unsigned char **key);
"""


def firmware_declarations(includes: tuple[str, ...] = FIRMWARE_INCLUDES) -> str:
    """The firmware application's headers (fw_app.h with rhonn.h and
    fw_protocol.h, fw_hal_mem.h, and the cantools-generated rhonn_id.h) run
    through the C preprocessor for the float32 core, with empty stand-ins
    for the system headers whose types cffi knows itself. ``includes``: the
    include path (relative to the source tree, or absolute)."""
    with tempfile.TemporaryDirectory() as stubs:
        for name in ("stddef.h", "stdint.h", "stdbool.h"):
            (Path(stubs) / name).write_text("")
        source = "".join(f'#include "{h}"\n' for h in ("fw_app.h", "fw_hal_mem.h", "rhonn_id.h"))
        cc = shlex.split(os.environ.get("CC", "cc"))
        result = subprocess.run([*cc, "-E", "-P", "-nostdinc", "-isystem", stubs, "-x", "c", "-DRHONN_SINGLE",
                                 *(f"-I{ROOT / d}" for d in includes), "-"], input=source,
                                capture_output=True, text=True, check=False)
    if result.returncode != 0:
        raise RuntimeError(f"preprocessing the firmware headers failed: {result.stderr}")
    return "".join(f"#define {name} ...\n" for name in FIRMWARE_CONSTANTS) + result.stdout + FIRMWARE_GLUE_CDEF


def make_fwapp_ffi(module: str = "pyrhonn._fwapp", protocol_dir: str | Path | None = None) -> FFI:
    """The builder of pyrhonn._fwapp: firmware_sim's application (fw_app,
    the generated pack/unpack of rhonn_id.dbc, the in-memory HAL) on the
    float32 core, the firmware's precision, compiled from the same sources
    and flags as the CMake targets.

    ``protocol_dir``: a folder holding another DBC (``rhonn_id.dbc``) and the
    protocol firmware_sim/tools/generate_protocol.py generated from it: the
    same application for that identifier's frames, as ``module``
    (firmware_sim/tools/build_twin.py builds it from a source tree)."""
    ffi = FFI()
    includes = FIRMWARE_INCLUDES
    sources = list(FIRMWARE_SOURCES)
    dbc_path = FIRMWARE / "rhonn_id.dbc"
    if protocol_dir is not None:
        pdir = Path(protocol_dir).resolve()
        includes = (str(pdir), *FIRMWARE_INCLUDES)
        sources = [str(pdir / "rhonn_id.c") if src == "firmware_sim/generated/rhonn_id.c" else str(ROOT / src)
                   for src in sources]
        dbc_path = pdir / "rhonn_id.dbc"
    ffi.cdef(firmware_declarations(includes))
    dbc = dbc_path.read_bytes()
    ffi.set_source(
        module,
        FIRMWARE_GLUE % ", ".join(str(b) for b in dbc),
        sources=sources,
        include_dirs=[str(ROOT / d) for d in includes] if protocol_dir is not None else list(includes),
        depends=build_depends(FIRMWARE_INCLUDES) if protocol_dir is None else [],
        define_macros=[("RHONN_UNROLL", "1"), ("RHONN_SINGLE", "1")],
        extra_compile_args=["-O2", "-ffp-contract=off", "-fno-fast-math"],
    )
    return ffi


CSV_SOURCE = "pyrhonn/csv_c/pyrhonn_csv.c"
#: The CSV text codec's entry points (:mod:`pyrhonn.csvcodec`; host only, not the core).
CSV_DECLARATIONS = """
long long pyrhonn_csv_format(const double *values, const unsigned char *show, size_t rows, size_t cols,
                             const unsigned char *integer, char sep, char *out, size_t cap);
long long pyrhonn_csv_parse(const char *text, size_t n, char sep, size_t fields, const unsigned char *kind,
                            const size_t *slot, double *numbers, size_t n_numbers, unsigned char *flags,
                            size_t n_flags, size_t max_rows, long long *bad_field);
#define PYRHONN_CSV_CELL_MAX ...
"""


def _words(value: int) -> str:
    """A 128-bit value as C's {low 64 bits, high 64 bits}."""
    return f"{{{value & (2**64 - 1)}u, {value >> 64}u}}"


def csv_tables() -> str:
    """The powers of 5 the CSV codec multiplies by, computed here with exact integers (see
    pyrhonn/csv_c/pyrhonn_csv.c): Ryu's 125-bit tables for writing, and 5^q on 128 bits (rounded
    down) with its binary exponent for reading, q = -342..308."""
    inv = [(1 << ((5**q).bit_length() - 1 + 125)) // 5**q + 1 for q in range(342)]
    split = []
    for i in range(326):
        bits = (5**i).bit_length()
        split.append(5**i << (125 - bits) if bits <= 125 else 5**i >> (bits - 125))
    wide, exps = [], []
    for q in range(-342, 309):
        if q >= 0:
            bits = (5**q).bit_length()
            value, exp = (5**q << (128 - bits), bits - 128) if bits <= 128 else (5**q >> (bits - 128), bits - 128)
        else:
            bits = (5**-q).bit_length()
            value, exp = (1 << (127 + bits)) // 5**-q, -(127 + bits)
        assert 1 << 127 <= value < 1 << 128
        wide.append(value)
        exps.append(exp)

    def table(name: str, values: list[int]) -> str:
        return f"static const uint64_t {name}[{len(values)}][2] = {{\n" + ",\n".join(
            _words(v) for v in values) + "\n};\n"

    return ("#include <stdint.h>\n" + table("PYRHONN_POW5_INV", inv) + table("PYRHONN_POW5", split)
            + table("PYRHONN_POW5_128", wide)
            + f"static const int32_t PYRHONN_POW5_128_EXP[{len(exps)}] = {{{', '.join(map(str, exps))}}};\n")


def make_csv_ffi() -> FFI:
    """The builder of ``pyrhonn._csvtext``, the CSV text codec (pyrhonn/csv_c/pyrhonn_csv.c, with the
    tables of :func:`csv_tables`)."""
    ffi = FFI()
    ffi.cdef(CSV_DECLARATIONS)
    ffi.set_source(
        "pyrhonn._csvtext",
        "#ifndef _GNU_SOURCE\n#define _GNU_SOURCE 1\n#endif\n" + csv_tables() + (ROOT / CSV_SOURCE).read_text(),
        depends=[CSV_SOURCE, str(Path(__file__).resolve().relative_to(ROOT))],
        extra_compile_args=["-O2", "-fno-fast-math"],
    )
    return ffi


ffi_f64 = make_ffi("float64")
ffi_f32 = make_ffi("float32")
ffi_small_f64 = make_ffi("float64", small=True)
ffi_small_f32 = make_ffi("float32", small=True)
ffi_fwapp = make_fwapp_ffi()
ffi_csv = make_csv_ffi()

if __name__ == "__main__":
    os.chdir(ROOT)
    for builder in (ffi_f64, ffi_f32, ffi_small_f64, ffi_small_f32, ffi_fwapp, ffi_csv):
        builder.compile(tmpdir=str(ROOT), verbose=True)
