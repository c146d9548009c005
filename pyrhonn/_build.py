"""cffi (API mode) builders for the C core, one extension per precision.

``pyrhonn._rhonn_f64`` and ``pyrhonn._rhonn_f32`` are compiled from the very
same ``csrc/src/rhonn.c`` that firmware links, with the capacities of
``csrc/include/rhonn_capacity.h``. The declarations below mirror ``rhonn.h``;
cffi checks every struct field's offset against the real header when the
extension is compiled, so a drift between the two fails the build.

Used by setup.py (``cffi_modules``); run directly to build in place.
"""
from __future__ import annotations

import re
from pathlib import Path

from cffi import FFI

ROOT = Path(__file__).resolve().parent.parent
CAPACITY_HEADER = ROOT / "csrc" / "include" / "rhonn_capacity.h"
CAPACITY_NAMES = (
    "RHONN_MAX_STATES",
    "RHONN_MAX_INPUTS",
    "RHONN_MAX_TERMS",
    "RHONN_MAX_FACTORS",
    "RHONN_MAX_DELAY",
    "RHONN_MAX_POWER",
)


def default_capacities() -> dict[str, int]:
    """The capacity macros' default values, read from rhonn_capacity.h."""
    text = CAPACITY_HEADER.read_text()
    caps: dict[str, int] = {}
    for name in CAPACITY_NAMES:
        match = re.search(rf"#define\s+{name}\s+(\d+)", text)
        if match is None:
            raise RuntimeError(f"{CAPACITY_HEADER}: no default for {name}")
        caps[name] = int(match.group(1))
    return caps


CDEF = """
typedef {real} rhonn_real;
#define RHONN_MAX_STATES {RHONN_MAX_STATES}
#define RHONN_MAX_INPUTS {RHONN_MAX_INPUTS}
#define RHONN_MAX_TERMS {RHONN_MAX_TERMS}
#define RHONN_MAX_FACTORS {RHONN_MAX_FACTORS}
#define RHONN_MAX_DELAY {RHONN_MAX_DELAY}
#define RHONN_MAX_POWER {RHONN_MAX_POWER}
#define RHONN_MAX_PACKED {packed}
#define RHONN_HISTORY_LEN {history}
#define RHONN_VERSION_MAJOR ...
#define RHONN_VERSION_MINOR ...

typedef enum {{
    RHONN_OK = 0, RHONN_E_NULL = 1, RHONN_E_NOT_INIT = 2, RHONN_E_CONFIG = 3,
    RHONN_E_ARGUMENT = 4, RHONN_E_INPUT_NONFINITE = 5, RHONN_E_INNOVATION = 6,
    RHONN_E_COVARIANCE = 7, RHONN_E_DIVERGED = 8, RHONN_E_VALUE = 9
}} rhonn_status;

typedef enum {{
    RHONN_FACTOR_S = 0, RHONN_FACTOR_X = 1, RHONN_FACTOR_U = 2, RHONN_FACTOR_ONE = 3
}} rhonn_factor_kind;

typedef enum {{ RHONN_LOGISTIC = 0, RHONN_BIPOLAR = 1 }} rhonn_activation;

typedef enum {{
    RHONN_FIELD_NONE = 0,
    RHONN_FIELD_N_STATES, RHONN_FIELD_N_INPUTS, RHONN_FIELD_X0,
    RHONN_FIELD_N_TERMS, RHONN_FIELD_ACTIVATION, RHONN_FIELD_BETA,
    RHONN_FIELD_ETA, RHONN_FIELD_R, RHONN_FIELD_Q, RHONN_FIELD_W0, RHONN_FIELD_P0,
    RHONN_FIELD_N_FACTORS, RHONN_FIELD_FACTOR_KIND, RHONN_FIELD_FACTOR_INDEX,
    RHONN_FIELD_FACTOR_DELAY, RHONN_FIELD_FACTOR_POWER
}} rhonn_field;

typedef struct {{ uint8_t kind; uint8_t index; uint8_t delay; uint8_t power; }} rhonn_factor;

typedef struct {{
    uint8_t n_factors;
    rhonn_factor factors[{RHONN_MAX_FACTORS}];
}} rhonn_term;

typedef struct {{
    uint8_t n_terms;
    uint8_t activation;
    rhonn_real beta;
    rhonn_real eta;
    rhonn_real r;
    rhonn_real q[{RHONN_MAX_TERMS}];
    rhonn_real w0[{RHONN_MAX_TERMS}];
    rhonn_real p0[{packed}];
    rhonn_term terms[{RHONN_MAX_TERMS}];
}} rhonn_neuron_config;

typedef struct {{
    uint8_t n_states;
    uint8_t n_inputs;
    rhonn_real x0[{RHONN_MAX_STATES}];
    rhonn_neuron_config neurons[{RHONN_MAX_STATES}];
}} rhonn_config;

typedef struct {{ uint8_t field; uint8_t neuron; uint8_t term; uint8_t factor; }} rhonn_config_error;

typedef struct {{
    uint32_t magic;
    rhonn_config cfg;
    uint8_t n_groups;
    uint8_t group_of[{RHONN_MAX_STATES}];
    uint8_t group_activation[{RHONN_MAX_STATES}];
    rhonn_real group_beta[{RHONN_MAX_STATES}];
    uint8_t bank[{RHONN_MAX_STATES}];
    rhonn_real w[{RHONN_MAX_STATES}][2][{RHONN_MAX_TERMS}];
    rhonn_real p[{RHONN_MAX_STATES}][2][{packed}];
    uint8_t zbank;
    rhonn_real z[2][{RHONN_MAX_STATES}][{RHONN_MAX_TERMS}];
    rhonn_real xhat[{RHONN_MAX_STATES}];
    uint8_t head;
    rhonn_real xh[{history}][{RHONN_MAX_STATES}];
    rhonn_real sh[{RHONN_MAX_STATES}][{history}][{RHONN_MAX_STATES}];
    uint8_t started;
    uint8_t learning;
    uint32_t steps;
    uint8_t fault_neuron;
}} rhonn_t;

rhonn_status rhonn_validate_config(const rhonn_config *cfg, rhonn_config_error *where);
rhonn_status rhonn_init(rhonn_t *net, const rhonn_config *cfg, rhonn_config_error *where);
rhonn_status rhonn_reset(rhonn_t *net);
rhonn_status rhonn_step(rhonn_t *net, const rhonn_real *x, const rhonn_real *u,
                        const uint8_t *valid, rhonn_real *xhat_next);
rhonn_status rhonn_run(rhonn_t *net, size_t T, const rhonn_real *X, const rhonn_real *U,
                       const uint8_t *valid, rhonn_real *Xhat, size_t *done);
rhonn_status rhonn_set_learning(rhonn_t *net, int on);
rhonn_status rhonn_get_weights(const rhonn_t *net, size_t neuron, rhonn_real *w, size_t len);
rhonn_status rhonn_set_weights(rhonn_t *net, size_t neuron, const rhonn_real *w, size_t len);
rhonn_status rhonn_get_covariance(const rhonn_t *net, size_t neuron, rhonn_real *p, size_t len);
rhonn_status rhonn_set_covariance(rhonn_t *net, size_t neuron, const rhonn_real *p, size_t len);
rhonn_status rhonn_get_prediction(const rhonn_t *net, rhonn_real *xhat, size_t len);
rhonn_real rhonn_activate(uint8_t activation, rhonn_real beta, rhonn_real s);
rhonn_real rhonn_exp_neg(rhonn_real a);
const char *rhonn_status_name(rhonn_status status);
"""


def make_ffi(dtype: str) -> FFI:
    """An FFI builder for the float64 or float32 core."""
    if dtype not in ("float64", "float32"):
        raise ValueError(f"dtype: expected 'float64' or 'float32', got {dtype!r}")
    caps = default_capacities()
    terms = caps["RHONN_MAX_TERMS"]
    ffi = FFI()
    ffi.cdef(
        CDEF.format(
            real="double" if dtype == "float64" else "float",
            packed=terms * (terms + 1) // 2,
            history=caps["RHONN_MAX_DELAY"] + 1,
            **caps,
        )
    )
    macros = [(name, str(value)) for name, value in caps.items()]
    if dtype == "float32":
        macros.append(("RHONN_SINGLE", "1"))
    # Paths relative to the project root, where setup.py runs.
    ffi.set_source(
        f"pyrhonn._rhonn_{'f64' if dtype == 'float64' else 'f32'}",
        '#include "rhonn.h"',
        sources=["csrc/src/rhonn.c"],
        include_dirs=["csrc/include"],
        define_macros=macros,
        extra_compile_args=["-O2", "-ffp-contract=off", "-fno-fast-math"],
    )
    return ffi


ffi_f64 = make_ffi("float64")
ffi_f32 = make_ffi("float32")

if __name__ == "__main__":
    import os

    os.chdir(ROOT)
    for builder in (ffi_f64, ffi_f32):
        builder.compile(tmpdir=str(ROOT), verbose=True)
