"""Soak: the LIM identifiers (`firmware-lim`, `example3`) over 10^7 steps per
precision, and what the covariance safeguards do to a quiet stretch and to
an outlier.

(a) exciting data: the simulated LIM (inputs on from t = 0, 0.3 ms) in runs of
    10^5 samples, one after the other with `restart` between them (a new run
    of the motor), 10^7 steps in all; the largest |w|, the smallest eigenvalue
    of any P_i (sampled after every run), refused updates and resets.
(b) windup: 10^6 unexcited steps (the motor at rest, inputs off), then the
    excited runs; the weight burst (largest one-step |dw| in the first 1,000
    excited steps) with windup protection off and on (p_trace_max = trace
    P_i(0) for every neuron), against the same 1,000 steps without the quiet
    stretch.
(c) an outlier: one sample of 10^6 on every state in the middle of a run,
    with and without automatic recovery (reset_after = 1).

    python bench/bench_soak.py            # 10^7 steps per precision (a few minutes)
    python bench/bench_soak.py --quick    # 10^6
    python bench/bench_soak.py --results  # also write bench/results/soak.json (the docs quote it)
"""
from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace

import numpy as np

from pyrhonn import Identifier, IdentifierConfig, IdentifierError
from pyrhonn.configfile import load_shipped
from pyrhonn.plants import lim

CHUNK = 100_000


def lim_run() -> tuple[np.ndarray, np.ndarray]:
    tr = lim.simulate(dt=3e-4, horizon=CHUNK * 3e-4, inputs=lim.LimInput(start=0.0), holds=())
    return tr.X[:CHUNK], tr.U[:CHUNK]


def configs(dtype: str) -> dict[str, IdentifierConfig]:
    return {name: load_shipped(name).config.replace(dtype=dtype) for name in ("firmware-lim", "example3")}


def protected(config: IdentifierConfig, **fields) -> IdentifierConfig:
    return config.replace(neurons=tuple(
        replace(nr, **{k: (float(np.trace(nr.p0_matrix())) if v == "trace0" else v) for k, v in fields.items()})
        for nr in config.neurons))


def min_eig(ident: Identifier) -> float:
    return min(float(np.linalg.eigvalsh(P.astype(np.float64))[0]) for P in ident.covariances)


def max_w(ident: Identifier) -> float:
    return max(float(np.max(np.abs(w))) for w in ident.weights)


def totals(ident: Identifier) -> tuple[int, int]:
    hs = ident.healths
    return sum(h.rejected for h in hs), sum(h.resets for h in hs)


def run_steps(ident: Identifier, X: np.ndarray, U: np.ndarray) -> int:
    """Run X, U; a refused step is counted and skipped (as firmware would)."""
    refused = 0
    k = 0
    while k < X.shape[0]:
        try:
            ident.run(X[k:], U[k:])
            return refused
        except IdentifierError as exc:
            at = exc.sample if exc.sample is not None else 0
            ident.run(X[k:k + at], U[k:k + at])
            k += at + 1
            refused += 1
    return refused


def exciting(config: IdentifierConfig, X: np.ndarray, U: np.ndarray, runs: int) -> dict:
    ident = Identifier(config)
    worst_w, worst_eig = 0.0, np.inf
    refused = 0
    for _ in range(runs):
        refused += run_steps(ident, X, U)
        ident.restart()
        worst_w, worst_eig = max(worst_w, max_w(ident)), min(worst_eig, min_eig(ident))
    rejected, resets = totals(ident)
    return dict(max_w=worst_w, min_eig=worst_eig, rejected=rejected, resets=resets, refused=refused)


def burst(config: IdentifierConfig, X: np.ndarray, U: np.ndarray, quiet: int) -> float:
    ident = Identifier(config)
    if quiet:
        rest = np.repeat(X[:1], quiet, axis=0)
        ident.run(rest, np.zeros((quiet, U.shape[1]), dtype=U.dtype))
        ident.restart()
    w = np.concatenate(ident.weights)
    largest = 0.0
    for k in range(1000):
        ident.step(X[k], U[k])
        w_new = np.concatenate(ident.weights)
        largest = max(largest, float(np.max(np.abs(w_new - w))))
        w = w_new
    return largest


def outlier(config: IdentifierConfig, X: np.ndarray, U: np.ndarray) -> dict:
    ident = Identifier(config)
    Xo = X.copy()
    Xo[CHUNK // 2] = 1e6
    refused = run_steps(ident, Xo, U)
    rejected, resets = totals(ident)
    return dict(max_w=max_w(ident), min_eig=min_eig(ident), refused=refused, rejected=rejected, resets=resets)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="10^6 steps per precision instead of 10^7")
    ap.add_argument("--results", action="store_true", help="also write the figures to bench/results/soak.json")
    args = ap.parse_args(argv)
    if args.results:  # imported now: it notes the load average at the start of the run
        from results_file import save  # noqa: E402 - beside this script
    runs = 10 if args.quick else 100
    quiet = 1_000_000
    figures: dict = {"settings": {"runs": runs, "run_samples": CHUNK, "steps": runs * CHUNK, "quiet_steps": quiet,
                                  "quick": args.quick}}
    X64, U64 = lim_run()
    print(f"exciting data: {runs} runs of {CHUNK} LIM samples per config and precision "
          f"({runs * CHUNK:.0e} steps); quiet stretch {quiet:.0e} steps")
    print(f"{'config':13} {'dtype':7} {'case':34} {'max |w|':>10} {'min eig P':>10} {'refused':>8} "
          f"{'resets':>7} {'seconds':>8}")
    for dtype in ("float32", "float64"):
        X, U = X64.astype(dtype), U64.astype(dtype)
        for name, config in configs(dtype).items():
            t0 = time.perf_counter()
            r = exciting(config, X, U, runs)
            entry = figures.setdefault(name.replace("-", "_"), {})[dtype] = {"exciting": r}
            print(f"{name:13} {dtype:7} {'(a) exciting':34} {r['max_w']:10.4g} {r['min_eig']:10.3g} "
                  f"{r['rejected']:8d} {r['resets']:7d} {time.perf_counter() - t0:8.1f}")
            for label, cfg in (("(c) outlier 1e6, no recovery", config),
                               ("(c) outlier 1e6, reset_after = 1", protected(config, reset_after=1))):
                r = outlier(cfg, X, U)
                entry["outlier_reset_after" if "reset_after" in label else "outlier"] = r
                print(f"{name:13} {dtype:7} {label:34} {r['max_w']:10.4g} {r['min_eig']:10.3g} "
                      f"{r['rejected']:8d} {r['resets']:7d}")
            base = burst(config, X, U, 0)
            off = burst(config, X, U, quiet)
            on = burst(protected(config, p_trace_max="trace0"), X, U, quiet)
            base_on = burst(protected(config, p_trace_max="trace0"), X, U, 0)
            print(f"{name:13} {dtype:7} (b) burst after quiet: no quiet {base:.3g} / {base_on:.3g} (off/on), "
                  f"protection off {off:.3g} ({off / base:.1f}x), on {on:.3g} ({on / base_on:.2f}x)")
            entry["burst"] = {"no_quiet_off": base, "no_quiet_on": base_on, "off": off, "on": on,
                              "off_ratio": off / base, "on_ratio": on / base_on}
    if args.results:
        save("soak", figures, argv)
    return 0


if __name__ == "__main__":
    sys.exit(main())
