"""Neurons side by side (``rhonn_run_wide``) against neuron by neuron
(``rhonn_run``) on this CPU: for identifiers of 2-8 neurons of 8 terms, each
covariance form and precision, the ratio of the two batched runs' times
(above 1: the lanes are faster), and whether ``rhonn_wide_pays`` -- which
``Identifier.run`` follows -- sends that identifier into the lanes. A row
where the advice and the measurement disagree by more than the noise is
marked; the thresholds are in csrc/src/rhonn_population.c. A second table
does the same for ``Identifier.step`` one sample per call, which follows
the same advice (in the lanes, the neurons stay lent to them between
steps: ``rhonn_wide_step``).

Both runs give the same bits (tests/test_identifier_wide.py); this is only
about speed. Best of several interleaved repeats, ratios from one run.

The extension picks the widest vector unit the CPU has at load time. A third
table measures ``Identifier.run`` on each unit this CPU can run (x86-64:
AVX-512F, AVX2 in float only, as the extension's clones are, and the SSE2
default), on builds of the core whose lanes are compiled for that unit alone
(``make_ffi(vector_unit=...)`` in pyrhonn/_build.py; about a minute each,
kept in build/bench_wide/ for the next run; not in ``--quick``).

    python bench/bench_wide.py            # full run (a few minutes; the first compiles the per-unit builds)
    python bench/bench_wide.py --quick    # smoke run (CI)
    python bench/bench_wide.py --results  # also write bench/results/wide.json (the docs quote it)
"""
from __future__ import annotations

import argparse
import hashlib
import importlib.util
import os
import platform
import time
from pathlib import Path
from types import ModuleType

import numpy as np

from pyrhonn import CovarianceForm, Factor, Identifier, IdentifierConfig, NeuronConfig
from pyrhonn import _build
from pyrhonn import identifier as _identifier

ROOT = Path(__file__).resolve().parent.parent
CACHE = ROOT / "build" / "bench_wide"
#: The precisions the extension clones each unit's kernels for (pyrhonn/_build.py, RHONN_TARGET_CLONES):
#: no AVX2 copy in double.
UNIT_DTYPES = {"avx512f": ("float64", "float32"), "avx2": ("float32",), "default": ("float64", "float32")}
UNIT_NAMES = {"avx512f": "AVX-512", "avx2": "AVX2", "default": "SSE2 (128-bit)"}


def uniform_config(n: int, dtype: str, form: CovarianceForm) -> IdentifierConfig:
    """n states, 2 inputs, every neuron 8 terms: S(x) of its own state round,
    a bilinear term, an input, raw states to fill up."""
    neurons = []
    for i in range(n):
        terms = [(Factor.s((i + j) % n),) for j in range(min(n, 5))]
        terms.append((Factor.s(i), Factor.s((i + 1) % n)))
        terms.append((Factor.u(i % 2),))
        j = 0
        while len(terms) < 8:
            terms.append((Factor.x((i + j) % n),) if j < n else (Factor.u((i + 1) % 2, delay=j - n + 1),))
            j += 1
        neurons.append(NeuronConfig(terms=tuple(terms), covariance=form, p0=10.0, q=1e-3, r=1e-2, eta=1.0))
    return IdentifierConfig(n_states=n, n_inputs=2, neurons=tuple(neurons), dtype=dtype)


def trajectory(n: int, T: int, dtype: str) -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(T)[:, None] * 1e-3
    X = np.sin(t * (1.0 + np.arange(n))) + 0.1 * np.cos(7.3 * t * (1 + np.arange(n)))
    U = np.sin(t * (0.7 + np.arange(2)))
    return np.ascontiguousarray(X.astype(dtype)), np.ascontiguousarray(U.astype(dtype))


def ratio(cfg: IdentifierConfig, T: int, repeats: int, per_step: bool = False) -> tuple[float, bool]:
    """(neuron-by-neuron time / lanes time, what rhonn_wide_pays advises),
    of one ``run`` over T samples, or with ``per_step`` of T ``step`` calls."""
    X, U = trajectory(cfg.n_states, T, cfg.dtype)
    out = np.empty_like(X)
    rows = list(zip(X, U))
    best = {False: float("inf"), True: float("inf")}
    advised = Identifier(cfg)._wide
    for _ in range(repeats):
        for wide in (False, True):  # interleaved: a load spike hits both alike
            ident = Identifier(cfg)
            ident._wide = wide
            step = ident.step
            t0 = time.perf_counter()
            if per_step:
                for x, u in rows:
                    step(x, u)
            else:
                ident.run(X, U, out=out)
            best[wide] = min(best[wide], time.perf_counter() - t0)
    return best[False] / best[True], advised


def vector_units() -> list[str]:
    """The vector units of the lanes' clones this CPU can run, widest first; none but the
    extension's own build off x86-64 (the clones are x86-64 only)."""
    if platform.machine() != "x86_64":
        return []
    flags: set[str] = set()
    for line in Path("/proc/cpuinfo").read_text(encoding="utf-8").splitlines():
        if line.startswith("flags"):
            flags = set(line.split(":", 1)[1].split())
            break
    return [unit for unit in ("avx512f", "avx2") if unit in flags] + ["default"]


def unit_build(unit: str, dtype: str) -> ModuleType:
    """The core with its lanes compiled for ``unit`` alone (the small capacities, which hold
    this bench's identifiers), compiled once per source content into build/bench_wide/."""
    digest = hashlib.sha256(f"{unit} {dtype}".encode())
    for source in (*_build.CORE_SOURCES, *_build.build_depends(["csrc/include"])):
        digest.update((ROOT / source).read_bytes())
    name = f"_bench_wide_{unit}_{dtype}_{digest.hexdigest()[:12]}"
    folder = CACHE / name
    built = sorted(folder.glob(f"{name}.*.so")) if folder.is_dir() else []
    if not built:
        print(f"compiling the core for {UNIT_NAMES[unit]}, {dtype} (about a minute) ...", flush=True)
        ffi = _build.make_ffi(dtype, small=True, vector_unit=unit, module=name)
        built = [Path(ffi.compile(tmpdir=str(folder), verbose=False))]
    spec = importlib.util.spec_from_file_location(name, built[0])
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def unit_ratio(build: ModuleType, cfg: IdentifierConfig, T: int, repeats: int) -> float:
    """:func:`ratio` of ``Identifier.run`` with the identifiers on ``build``."""
    saved = _identifier._BUILDS[cfg.dtype]
    _identifier._BUILDS[cfg.dtype] = (build,)
    try:
        return ratio(cfg, T, repeats)[0]
    finally:
        _identifier._BUILDS[cfg.dtype] = saved


def lanes_from(row: dict[str, float]) -> int | str:
    """The fewest neurons from which the lanes are faster at every size measured above."""
    sizes = sorted(int(n) for n in row)
    pays = [n for n in sizes if all(row[str(m)] > 1.0 for m in sizes if m >= n)]
    return pays[0] if pays else f"over {sizes[-1]}"


def measure_units(T: int, repeats: int) -> dict:
    """Per vector unit, dtype and form: the ratio at each size and ``lanes_from``."""
    out: dict = {"load_1min": os.getloadavg()[0], "units": vector_units()}
    print(f"Identifier.run per vector unit: load average {os.getloadavg()[0]:.2f} (1 min); {T} samples, "
          f"best of {repeats}; the lanes compiled for one unit alone")
    print(f"{'unit':<16}{'dtype':<9}{'form':<6}" + "".join(f"{n:>7}" for n in range(2, 9)) + "   lanes from")
    for unit in out["units"]:
        for dtype in UNIT_DTYPES[unit]:
            build = unit_build(unit, dtype)
            for form in (CovarianceForm.FULL, CovarianceForm.UD):
                row = {str(n): unit_ratio(build, uniform_config(n, dtype, form), T, repeats) for n in range(2, 9)}
                first = lanes_from(row)
                out.setdefault(unit, {}).setdefault(dtype, {})[form.value] = {**row, "lanes_from": first}
                print(f"{UNIT_NAMES[unit]:<16}{dtype:<9}{form.value:<6}" + "".join(f"{r:>7.2f}" for r in row.values())
                      + f"   {first}")
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small smoke run")
    ap.add_argument("--results", action="store_true", help="also write the figures to bench/results/wide.json")
    args = ap.parse_args(argv)
    if args.results:  # imported now: it notes the load average at the start of the run
        from results_file import save  # noqa: E402 - beside this script
    T, T_step, repeats = (500, 200, 2) if args.quick else (20000, 5000, 5)
    sizes = range(2, 9)
    disagree = 0
    figures: dict = {"settings": {"run_samples": T, "step_calls": T_step, "repeats": repeats, "quick": args.quick}}
    for per_step, samples, what in ((False, T, "Identifier.run"), (True, T_step, "Identifier.step, one call a sample")):
        table = figures["step" if per_step else "run"] = {"load_1min": os.getloadavg()[0]}
        print(f"{what}: load average {os.getloadavg()[0]:.2f} (1 min); {samples} samples, best of {repeats}; "
              "ratio = neuron by neuron / side by side (* = rhonn_wide_pays sends it into the lanes)")
        print(f"{'dtype':<9}{'form':<6}" + "".join(f"{n:>9}" for n in sizes))
        for dtype in ("float64", "float32"):
            for form in (CovarianceForm.FULL, CovarianceForm.UD):
                cells = []
                row = table.setdefault(dtype, {})[form.value] = {}
                for n in sizes:
                    r, advised = ratio(uniform_config(n, dtype, form), samples, repeats, per_step)
                    row[str(n)] = {"ratio": r, "advised": advised}
                    # noise margin: a 10 % loss or gain either way is not a wrong call
                    wrong = (advised and r < 0.9) or (not advised and r > 1.1)
                    disagree += wrong
                    cells.append(f"{r:>7.2f}{'*' if advised else ' '}{'!' if wrong else ' '}")
                print(f"{dtype:<9}{form.value:<6}" + "".join(cells))
    print(f"{disagree} advice(s) off by more than 10 % (!)" if disagree else "the advice agrees with the times")
    if not args.quick:
        figures["units"] = measure_units(T, repeats)
    if args.results:
        figures["advice_off"] = disagree
        save("wide", figures, argv)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
