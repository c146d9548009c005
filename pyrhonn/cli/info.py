"""``pyrhonn info``: the build the package was compiled with.

The capacities are those of the Python extension, sized for structure
search (``pyrhonn select``); firmware builds the core with its own (the
defaults of ``csrc/include/rhonn_capacity.h`` unless it sets them). The
README says how to build the extension with other capacities."""
from __future__ import annotations

import argparse
import json

from .. import __version__
from ..identifier import capacities
from ..population import max_population


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("info", help="show the compiled capacities and sizes of the C core",
                       description="Show the compile-time capacities and struct sizes of the C core.")
    p.add_argument("--json", action="store_true", help="print as JSON")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from .. import _rhonn_f32, _rhonn_f64

    data = {
        "version": __version__,
        "capacities": capacities("float64"),
        "unrolled_kernels": bool(getattr(_rhonn_f64.lib, "RHONN_UNROLL", 0)),
        "max_population": max_population("float64"),
        "sizeof_rhonn_t": {"float64": _rhonn_f64.ffi.sizeof("rhonn_t"), "float32": _rhonn_f32.ffi.sizeof("rhonn_t")},
    }
    if args.json:
        print(json.dumps(data, indent=2))
        return 0
    print(f"pyrhonn {data['version']}")
    for name, value in data["capacities"].items():
        print(f"  {name:18} {value}")
    print(f"  unrolled EKF kernels: {'yes' if data['unrolled_kernels'] else 'no (RHONN_MAX_TERMS above 16)'}")
    print(f"  identifiers per run_population call: {data['max_population']} (RHONN_MAX_POPULATION)")
    for dtype, size in data["sizeof_rhonn_t"].items():
        print(f"  sizeof(rhonn_t) {dtype}: {size} bytes")
    return 0
