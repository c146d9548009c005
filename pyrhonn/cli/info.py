"""``pyrhonn info``: the builds the package was compiled with.

Each precision has two builds of the core: a large one whose capacities are
sized for structure search (``pyrhonn select``), and a small one with the
firmware default capacities (``csrc/include/rhonn_capacity.h``), which runs
every identifier that fits in it (faster, same results bit for bit). The
top-level ``capacities``, ``unrolled_kernels`` and ``sizeof_rhonn_t`` are
the large build's (what an identifier can hold at most); ``builds`` lists
both, each with ``sizeof_population_work``: the vector lanes' workspace
that ``run`` uses per thread, and that ``step`` allocates per identifier
whose neurons it keeps in the lanes. The README says how to build the
extension with other capacities."""
from __future__ import annotations

import argparse
import json
from typing import Any

from .. import __version__
from ..identifier import _BUILDS, build_capacities, capacities
from ..population import max_population


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("info", help="show the compiled capacities and sizes of the C core",
                       description="Show the compile-time capacities and struct sizes of the C core.")
    p.add_argument("--json", action="store_true", help="print as JSON")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from .. import _rhonn_f32, _rhonn_f64

    data: dict[str, Any] = {
        "version": __version__,
        "capacities": capacities("float64"),
        "unrolled_kernels": bool(getattr(_rhonn_f64.lib, "RHONN_UNROLL", 0)),
        "max_population": max_population("float64"),
        "sizeof_rhonn_t": {"float64": _rhonn_f64.ffi.sizeof("rhonn_t"), "float32": _rhonn_f32.ffi.sizeof("rhonn_t")},
        "builds": [{"module": build.__name__, "dtype": dtype, "capacities": build_capacities(build),
                    "unrolled_kernels": bool(getattr(build.lib, "RHONN_UNROLL", 0)),
                    "sizeof_rhonn_t": build.ffi.sizeof("rhonn_t"),
                    "sizeof_population_work": build.ffi.sizeof("rhonn_population_work")}
                   for dtype, builds in _BUILDS.items() for build in builds],
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
    print("builds (an identifier runs on the smallest that holds its config):")
    for b in data["builds"]:
        caps = ", ".join(f"{k[len('RHONN_MAX_'):]}={v}" for k, v in b["capacities"].items())
        print(f"  {b['module']:26} {b['dtype']:8} sizeof(rhonn_t) {b['sizeof_rhonn_t']:8} bytes, "
              f"unrolled {'yes' if b['unrolled_kernels'] else 'no '}, lanes workspace "
              f"{b['sizeof_population_work']:8} bytes; {caps}")
    return 0
