"""Time per identifier step: the C core batched and per call from Python,
float64 and float32, against the NumPy reference and a per-neuron filterpy
loop measured in the same run, for two sizes:

  example1   4 states, 1 input, 4 terms per neuron (the paper's eq. 20 setting)
  lim        6 states, 2 inputs, 8 terms per neuron (a LIM-sized identifier)

Every figure is the best of several repeats (the least disturbed by other
load), and every comparison is a ratio between figures of this same run.
The flop count per step is printed so the achieved rate can be read against
the machine's limit.

    python bench/bench_identifier.py            # full run (about a minute)
    python bench/bench_identifier.py --quick    # smoke run (CI)
    python bench/bench_identifier.py --json out.json
    python bench/bench_identifier.py --results  # also bench/results/identifier.json, which the docs quote
"""
from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from dataclasses import dataclass
from typing import Callable

import numpy as np

from pyrhonn import Activation, Factor, FactorKind, Identifier, IdentifierConfig, atomic, presets, terms
from pyrhonn.reference import ReferenceIdentifier

try:
    from filterpy.kalman import KalmanFilter
except ImportError:  # the baseline is optional outside CI
    KalmanFilter = None


def example1_config(dtype: str) -> IdentifierConfig:
    return presets.example1(dtype)


def lim_config(dtype: str) -> IdentifierConfig:
    # Eight weights per neuron: the six S(x_j), one bilinear S(x_i) S(x_i+1)
    # and one input, the shape of a LIM identifier.
    per = []
    for i in range(6):
        per.append(terms.first_order(6) + ((Factor.s(i), Factor.s((i + 1) % 6)),) + terms.inputs([i % 2]))
    return IdentifierConfig.uniform(per, n_states=6, n_inputs=2, dtype=dtype, beta=1.0, p0=10.0, q=1e-3, r=1e-2)


def flops_per_step(cfg: IdentifierConfig) -> int:
    """Floating-point operations of one learning step, counted from the code:
    per activation group n S(x) at ~22 flops each (exp polynomial, scaling,
    one division); per term (factors - 1 + extra powers) products; per
    neuron with L weights: P z 2L^2, z^T P z 2L + 1, gain L + 1 (division),
    w update 3L + 1, P update (L^2 + L) + L, prediction 2L."""
    groups = {(nr.activation, nr.beta) for nr in cfg.neurons}
    total = 22 * cfg.n_states * len(groups)
    for nr in cfg.neurons:
        L = nr.n_terms
        for term in nr.terms:
            total += sum(f.power for f in term) - 1
        total += 2 * L * L + (2 * L + 1) + (L + 1) + (3 * L + 1) + (L * L + 2 * L) + 2 * L
    return total


def trajectory(cfg: IdentifierConfig, T: int) -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(T)[:, None] * 1e-3
    X = np.sin(t * (1.0 + np.arange(cfg.n_states))) + 0.1 * np.cos(7.3 * t * (1 + np.arange(cfg.n_states)))
    U = np.sin(t * (0.7 + np.arange(cfg.n_inputs)))
    return X.astype(cfg.dtype), U.astype(cfg.dtype)


def best_of(repeats: int, fn: Callable[[], float]) -> float:
    return min(fn() for _ in range(repeats))


def time_batched(cfg: IdentifierConfig, T: int, repeats: int) -> float:
    X, U = trajectory(cfg, T)
    out = np.empty_like(X)

    def once() -> float:
        ident = Identifier(cfg)
        t0 = time.perf_counter()
        ident.run(X, U, out=out)
        return (time.perf_counter() - t0) / T

    return best_of(repeats, once)


def time_per_call(cfg: IdentifierConfig, T: int, repeats: int) -> float:
    X, U = trajectory(cfg, T)
    rows = [(X[k], U[k]) for k in range(T)]

    def once() -> float:
        ident = Identifier(cfg)
        step = ident.step
        t0 = time.perf_counter()
        for x, u in rows:
            step(x, u)
        return (time.perf_counter() - t0) / T

    return best_of(repeats, once)


def time_reference(cfg: IdentifierConfig, T: int, repeats: int) -> float:
    cfg64 = cfg.replace(dtype="float64")
    X, U = trajectory(cfg64, T)

    def once() -> float:
        ref = ReferenceIdentifier(cfg64)
        t0 = time.perf_counter()
        for k in range(T):
            ref.step(X[k], U[k])
        return (time.perf_counter() - t0) / T

    return best_of(repeats, once)


def _regressor(cfg: IdentifierConfig, i: int, hist: list[np.ndarray], u: np.ndarray) -> np.ndarray:
    nr = cfg.neurons[i]
    beta = nr.beta
    z = np.empty(nr.n_terms)
    for t, term in enumerate(nr.terms):
        v = 1.0
        for f in term:
            if f.kind is FactorKind.U:
                base = u[f.index]
            elif f.kind is FactorKind.ONE:
                base = 1.0
            else:
                xj = hist[min(f.delay, len(hist) - 1)][f.index]
                if f.kind is FactorKind.X:
                    base = xj
                elif nr.activation is Activation.LOGISTIC:
                    base = 1.0 / (1.0 + np.exp(-beta * xj))
                else:
                    base = np.tanh(beta * xj / 2.0)
            v *= base ** f.power
        z[t] = v
    return z


def time_filterpy(cfg: IdentifierConfig, T: int, repeats: int) -> float:
    """The same identifier as n filterpy KalmanFilters (F = I, H = z^T) with
    the regressor formed in NumPy: what one would write without pyrhonn."""
    cfg64 = cfg.replace(dtype="float64")
    X, U = trajectory(cfg64, T)

    def once() -> float:
        kfs = []
        for nr in cfg64.neurons:
            kf = KalmanFilter(dim_x=nr.n_terms, dim_z=1)
            kf.x = nr.w0_vector().reshape(-1, 1)
            kf.P = nr.p0_matrix()
            kf.Q = np.diag(nr.q_diagonal())
            kf.R = np.array([[nr.r]])
            kf.F = np.eye(nr.n_terms)
            kfs.append(kf)
        hist: list[np.ndarray] = []
        zs: list[np.ndarray] | None = None
        t0 = time.perf_counter()
        for k in range(T):
            if zs is not None:
                for i, kf in enumerate(kfs):
                    kf.update(np.array([[X[k, i]]]), H=zs[i].reshape(1, -1))
                    kf.predict()
            hist.insert(0, X[k])
            del hist[cfg64.max_delay + 1:]
            zs = [_regressor(cfg64, i, hist, U[k]) for i in range(cfg64.n_states)]
            _ = [float(kf.x.ravel() @ z) for kf, z in zip(kfs, zs)]
        return (time.perf_counter() - t0) / T

    return best_of(repeats, once)


@dataclass
class Row:
    size: str
    dtype: str
    flops: int
    batched_ns: float
    per_call_ns: float
    reference_ns: float
    filterpy_ns: float | None
    lanes: bool  # run() and step() put the neurons side by side in the vector lanes on this CPU

    def as_dict(self) -> dict[str, object]:
        d = dict(self.__dict__)
        d["steps_per_s"] = 1e9 / self.batched_ns
        d["overhead_ns"] = self.per_call_ns - self.batched_ns
        d["speedup_vs_reference"] = self.reference_ns / self.batched_ns
        d["speedup_vs_filterpy"] = None if self.filterpy_ns is None else self.filterpy_ns / self.batched_ns
        d["gflops"] = self.flops / self.batched_ns
        return d


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small smoke run")
    ap.add_argument("--json", metavar="FILE", help="also write the figures as JSON")
    ap.add_argument("--results", action="store_true",
                    help="also write the figures to bench/results/identifier.json (by size and dtype)")
    args = ap.parse_args(argv)
    if args.results:  # imported now: it notes the load average at the start of the run
        from results_file import save  # noqa: E402 - beside this script
    T_batch, T_call, T_slow, reps = (20_000, 5_000, 200, 2) if args.quick else (400_000, 100_000, 2_000, 5)

    print(f"pyrhonn identifier benchmark on {platform.machine()} / {platform.processor() or 'cpu'}, "
          f"Python {platform.python_version()}, numpy {np.__version__}")
    rows: list[Row] = []
    for size, make in (("example1", example1_config), ("lim", lim_config)):
        slow = {}
        slow["reference"] = time_reference(make("float64"), T_slow, max(1, reps // 2))
        slow["filterpy"] = (time_filterpy(make("float64"), T_slow, max(1, reps // 2))
                            if KalmanFilter is not None else None)
        for dtype in ("float64", "float32"):
            cfg = make(dtype)
            rows.append(Row(size, dtype, flops_per_step(cfg), 1e9 * time_batched(cfg, T_batch, reps),
                            1e9 * time_per_call(cfg, T_call, reps), 1e9 * slow["reference"],
                            None if slow["filterpy"] is None else 1e9 * slow["filterpy"], Identifier(cfg)._wide))

    head = (f"{'size':9} {'dtype':8} {'flops':>6} {'batched':>10} {'steps/s':>10} {'GFLOP/s':>8} "
            f"{'step()':>9} {'overhead':>9} {'numpy ref':>10} {'x ref':>7} {'filterpy':>10} {'x fpy':>7} {'lanes':>5}")
    print(head)
    print("-" * len(head))
    for r in rows:
        d = r.as_dict()
        fp = "-" if r.filterpy_ns is None else f"{r.filterpy_ns / 1e3:8.1f}us"
        xfp = "-" if d["speedup_vs_filterpy"] is None else f"{d['speedup_vs_filterpy']:6.0f}x"
        print(f"{r.size:9} {r.dtype:8} {r.flops:6d} {r.batched_ns:8.0f}ns {d['steps_per_s'] / 1e6:8.2f}M "
              f"{d['gflops']:8.2f} {r.per_call_ns / 1e3:7.2f}us {d['overhead_ns'] / 1e3:7.2f}us "
              f"{r.reference_ns / 1e3:8.1f}us {d['speedup_vs_reference']:6.0f}x {fp:>10} {xfp:>7} "
              f"{'yes' if r.lanes else 'no':>5}")
    print("batched = Identifier.run per step; step() = one Identifier.step call; overhead = step() - batched;"
          " x ref / x fpy = how many times faster the batched C step is than that baseline;"
          " lanes = run() and step() put the neurons side by side in the vector lanes on this CPU.")
    if args.json:
        atomic.write_text(args.json, json.dumps([r.as_dict() for r in rows], indent=2))
    if args.results:
        figures: dict[str, object] = {"batched_steps": T_batch, "call_steps": T_call, "repeats": reps}
        for r in rows:
            figures.setdefault(r.size, {})[r.dtype] = r.as_dict()  # type: ignore[union-attr]
        save("identifier", figures, argv)
    return 0


if __name__ == "__main__":
    sys.exit(main())
