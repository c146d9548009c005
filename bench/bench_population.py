"""Throughput of rhonn_run_population: 8 members of one structure in one call
against 8 sequential rhonn_run calls (Identifier.run), on the LIM-size
configs (firmware-lim: a 2-term U D U^T neuron and five full-form neurons
of 5-7 terms; example3: six U D U^T neurons), float64 and float32, the
simulated LIM (0.3 ms) with the paper's 1 s position hold, measured in the
same run.

Two comparisons, each the ratio of the best of several repeats (the least
disturbed by other load), both ways interleaved so load drifts hit both:

  core      run_identifiers(8 identifiers) vs 8 x Identifier.run, the
            identifiers built beforehand: the C calls (and the state copies
            both make to restore on error)
  end-to-end run_population(8 configs) vs [Identifier(c).run(...) for c]:
            what a caller of either writes, construction included

Then the core comparison with innovation gates (``gated``): firmware-lim's
members, every other one with a gate of 9 (chi-square, 1 degree of
freedom, 99.7 %) on every neuron, the gated and ungated members in one
call (the gates run in the lanes), on the LIM samples with an outlier
every 499 samples (10 times the state's range), with how many updates the
gates skipped.

Then `pyrhonn tune`'s search itself: the same number of trials with
``batch`` = 8 (8 trials per core call) against ``batch`` = 1, on example3
and the LIM trajectory, the wall time of the whole search (TPE included);
and the structure search's (``tune --structure``): 8 tunings of one
selection scored in population calls against one by one, at three
selection sizes, and a whole search batch 8 against batch 1.

The members differ in P0, Q, R and eta (a tuning search's candidates). Every
member's predictions are checked bit for bit against its single run first.
The machine load (1-minute load average, cores) is printed with the figures.

    python bench/bench_population.py            # 20,000 samples, 7 repeats
    python bench/bench_population.py --quick    # 3,000 samples, 3 repeats
    python bench/bench_population.py --results  # also bench/results/population.json, which the docs quote
"""
from __future__ import annotations

import argparse
import os
import platform
import time
from dataclasses import replace
from typing import Any

import numpy as np

from pyrhonn import Identifier, IdentifierConfig
from pyrhonn.configfile import load_shipped
from pyrhonn.plants import lim
from pyrhonn.population import max_population, run_identifiers, run_population


def members(base: IdentifierConfig, count: int) -> list[IdentifierConfig]:
    return [base.replace(neurons=tuple(replace(nr, p0=nr.p0_matrix() * (1.0 + 0.5 * k), q=nr.q_diagonal() * (1.0 + 0.3 * k),
                                               r=nr.r * (1.0 + 0.2 * k), eta=nr.eta / (1.0 + 0.1 * k))
                                       for nr in base.neurons))
            for k in range(count)]


def best(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="3,000 samples, 3 repeats")
    parser.add_argument("--results", action="store_true", help="also write the figures to bench/results/population.json")
    args = parser.parse_args()
    if args.results:  # imported now: it notes the load average at the start of the run
        from results_file import save  # noqa: E402 - beside this script
    T, repeats = (3000, 3) if args.quick else (20000, 7)
    figures: dict = {"samples": T, "repeats": repeats, "runs": {}, "gated": {}, "tune": {}, "structure": {}}
    tr = lim.simulate(dt=3e-4, horizon=T * 3e-4, inputs=lim.LimInput(start=0.0), holds=lim.paper_holds())
    load = os.getloadavg()[0]
    print(f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, load average {load:.2f} "
          f"(1 min) at the start; {T} LIM samples, best of {repeats}")
    print(f"{'config':<14}{'dtype':<9}{'N':>3}  {'core: 8 runs':>13} {'population':>11} {'ratio':>6}"
          f"  {'end-to-end: 8 runs':>19} {'population':>11} {'ratio':>6}")
    for name in ("firmware-lim", "example3"):
        for dtype in ("float64", "float32"):
            base = load_shipped(name).config.replace(dtype=dtype)
            N = max_population(dtype)
            cfgs = members(base, N)
            X = np.ascontiguousarray(np.where(tr.valid[:T], tr.X_meas[:T], np.nan).astype(dtype))
            U = np.ascontiguousarray(tr.U[:T].astype(dtype))
            V = np.ascontiguousarray(tr.valid[:T])
            got = run_population(cfgs, X, U, V)
            for k, cfg in enumerate(cfgs):
                if got[k].tobytes() != Identifier(cfg).run(X, U, V).tobytes():
                    raise SystemExit(f"{name} {dtype}: member {k} differs from its single run")
            seq_core = pop_core = seq_all = pop_all = float("inf")
            for _ in range(repeats):  # interleaved: a load spike hits both sides alike
                seq_core, pop_core = core_times(cfgs, X, U, V, seq_core, pop_core)
                seq_all = min(seq_all, best(lambda: [Identifier(c).run(X, U, V) for c in cfgs], 1))
                pop_all = min(pop_all, best(lambda: run_population(cfgs, X, U, V), 1))
            figures["runs"].setdefault(name, {})[dtype] = {
                "members": N, "core_runs_ms": seq_core * 1e3, "core_population_ms": pop_core * 1e3,
                "core_ratio": seq_core / pop_core, "end_to_end_runs_ms": seq_all * 1e3,
                "end_to_end_population_ms": pop_all * 1e3, "end_to_end_ratio": seq_all / pop_all}
            print(f"{name:<14}{dtype:<9}{N:>3}  {seq_core * 1e3:>10.1f} ms {pop_core * 1e3:>8.1f} ms "
                  f"{seq_core / pop_core:>5.2f}x  {seq_all * 1e3:>16.1f} ms {pop_all * 1e3:>8.1f} ms "
                  f"{seq_all / pop_all:>5.2f}x")
    gated_ratio(tr, T, repeats, figures["gated"])
    tune_ratio(tr, T, repeats, figures["tune"])
    structure_ratio(tr, T, repeats, figures["structure"])
    print(f"load average {os.getloadavg()[0]:.2f} (1 min) at the end")
    if args.results:
        save("population", figures)


def core_times(cfgs: list[IdentifierConfig], X: np.ndarray, U: np.ndarray, V: np.ndarray,
               seq: float, pop: float) -> tuple[float, float]:
    """One repeat of the core comparison, folded into the best times so far:
    8 x Identifier.run against run_identifiers, the identifiers built first."""
    alone = [Identifier(c) for c in cfgs]
    seq = min(seq, best(lambda: [a.run(X, U, V) for a in alone], 1))
    group = [Identifier(c) for c in cfgs]
    pop = min(pop, best(lambda: run_identifiers(group, X, U, V), 1))
    return seq, pop


def gated_ratio(tr, T: int, repeats: int, out: dict) -> None:
    """The core comparison on firmware-lim with a gate of 9 on every neuron of
    every other member, outliers in the samples (into ``out`` by dtype), the
    members checked bit for bit against their single runs, health included."""
    for dtype in ("float64", "float32"):
        base = load_shipped("firmware-lim").config.replace(dtype=dtype)
        cfgs = [c.replace(neurons=tuple(replace(nr, gate=9.0) for nr in c.neurons)) if k % 2 else c
                for k, c in enumerate(members(base, max_population(dtype)))]
        X = np.where(tr.valid[:T], tr.X_meas[:T], np.nan)
        for k in range(101, T, 499):  # an outlier now and then: 10 times the state's range, one state at a time
            j = k % X.shape[1]
            X[k, j] += 10.0 * float(np.nanmax(X[:, j]) - np.nanmin(X[:, j]))
        X = np.ascontiguousarray(X.astype(dtype))
        U = np.ascontiguousarray(tr.U[:T].astype(dtype))
        V = np.ascontiguousarray(tr.valid[:T])
        group, alone = [Identifier(c) for c in cfgs], [Identifier(c) for c in cfgs]
        got = run_identifiers(group, X, U, V)
        for k, a in enumerate(alone):
            if got[k].tobytes() != a.run(X, U, V).tobytes() or group[k].healths != a.healths:
                raise SystemExit(f"gated {dtype}: member {k} differs from its single run")
        skipped = sum(h.gated for ident in group for h in ident.healths)
        seq = pop = float("inf")
        for _ in range(repeats):
            seq, pop = core_times(cfgs, X, U, V, seq, pop)
        out[dtype] = {"members": len(cfgs), "gated_members": len(cfgs) // 2, "gated_updates": skipped,
                      "core_runs_ms": seq * 1e3, "core_population_ms": pop * 1e3, "core_ratio": seq / pop}
        print(f"firmware-lim {dtype}, gate 9 in {len(cfgs) // 2} of {len(cfgs)} members ({skipped} updates "
              f"gated): 8 runs {seq * 1e3:.1f} ms, population {pop * 1e3:.1f} ms: {seq / pop:.2f}x")


def tune_ratio(tr, T: int, repeats: int, out: dict) -> None:
    """A whole tune search, batch 8 against batch 1, same trials count, same run (into ``out`` by dtype)."""
    import optuna

    from pyrhonn import tuning

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    trials = 32
    for dtype in ("float64", "float32"):
        base = load_shipped("example3").config.replace(dtype=dtype)
        X, U, V = tr.X_meas[:T], tr.U[:T], tr.valid[:T]
        one = eight = float("inf")
        for _ in range(max(1, repeats // 2)):
            one = min(one, best(lambda: tuning.tune(base, X, U, V, n_trials=trials, batch=1), 1))
            eight = min(eight, best(lambda: tuning.tune(base, X, U, V, n_trials=trials, batch=8), 1))
        out[dtype] = {"trials": trials, "batch_1_s": one, "batch_8_s": eight, "ratio": one / eight}
        print(f"tune example3 {dtype}, {trials} trials over {T} samples: batch 1 {one:.2f} s, batch 8 "
              f"{eight:.2f} s: {one / eight:.2f}x")


def scores(problem: Any, trial: list[IdentifierConfig]) -> bool:
    """Whether a structure trial can be scored (the core takes its configs)."""
    from pyrhonn import tuning

    try:
        problem.score_folds(trial)
    except tuning.TrialFailure:
        return False
    return True


def structure_ratio(tr, T: int, repeats: int, out: dict) -> None:
    """The structure search's trials: 8 tunings of one selection (the terms
    pyrhonn select picks on the training part, at three max_terms settings),
    scored as a batch of ``tune --structure --batch 8`` scores them (one
    population call per fold; a tuning whose configs the core refuses left
    out, as a search scores it as failed) against one by one as ``--batch 1`` does (each
    an Identifier.run, neurons side by side where their sizes allow); then a
    whole 32-trial structure search, batch 8 against batch 1 (different
    trials: a batch shares its settings, so it also runs fewer selections)."""
    import optuna

    from pyrhonn import tuning

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    X, U, V = tr.X_meas[:T], tr.U[:T], tr.valid[:T]
    search = tuning.StructureSearch()
    for dtype in ("float64", "float32"):
        base = load_shipped("example3").config.replace(dtype=dtype)
        problem = tuning._Problem(base, X, U, V, None, tuning.DEFAULT_TRAIN_FRACTION, 1)
        selector = tuning._Selector(problem, search)
        space = tuning.search_space(base, relative=True)
        for max_terms in (4, 8, 16):
            selected = selector.configs({"max_delay": 2, "degree": 2, "max_terms": max_terms})
            trials = [[tuning.apply_factors(c, space, {d.name: 1.0 + 0.1 * k for d in space}) for c in selected]
                      for k in range(max_population(dtype))]
            trials = [t for t in trials if scores(problem, t)]  # a tuning the core refuses is not timed
            alone = batched = float("inf")
            for _ in range(repeats):
                alone = min(alone, best(lambda: [problem.score_folds(t) for t in trials], 1))
                batched = min(batched, best(lambda: problem.score_folds_many(trials), 1))
            if [s.value for s in problem.score_folds_many(trials)] != [problem.score_folds(t).value for t in trials]:
                raise SystemExit(f"structure trials {dtype}: a batched score differs from its trial alone")
            sizes = sorted({nr.n_terms for nr in selected[0].neurons})
            out.setdefault(dtype, {})[f"max_terms_{max_terms}"] = {
                "tunings": len(trials), "terms_min": sizes[0], "terms_max": sizes[-1], "one_by_one_ms": alone * 1e3,
                "batched_ms": batched * 1e3, "ratio": alone / batched}
            print(f"structure trials {dtype}, {len(trials)} tunings of a selection with {sizes[0]}-{sizes[-1]} terms per neuron: "
                  f"one by one {alone * 1e3:.1f} ms, batched {batched * 1e3:.1f} ms: {alone / batched:.2f}x")
        one = eight = float("inf")
        for _ in range(max(1, repeats // 2)):
            one = min(one, best(lambda: tuning.tune(base, X, U, V, n_trials=32, batch=1, structure=search), 1))
            eight = min(eight, best(lambda: tuning.tune(base, X, U, V, n_trials=32, batch=8, structure=search), 1))
        out[dtype]["search"] = {"trials": 32, "batch_1_s": one, "batch_8_s": eight, "ratio": one / eight}
        print(f"tune --structure example3 {dtype}, 32 trials over {T} samples: batch 1 {one:.2f} s, batch 8 "
              f"{eight:.2f} s: {one / eight:.2f}x")


if __name__ == "__main__":
    main()
