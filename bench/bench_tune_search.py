"""``pyrhonn tune`` on Example 1: the search of P0, Q, R, eta and beta against the structure search.

Runs four ``pyrhonn tune`` commands on the built-in Example 1 record (T = 0.2 s, 100 s, 501 samples),
from the shipped ``example1`` config, 40 trials, seed 0, through the installed command line: the
search of P0, Q, R, eta and beta; the structure search (``--structure --max-delay 0:20 --degree 1:3
--max-terms 2:16``); and each with ``--folds 4``. For each it records what the command's JSON says:
the held-out score of the base config and of the written one (mean over states of the one-step RMSE
over the held-out targets' standard deviation; with folds, the mean over folds, and each fold's
score), x4's normalised RMSE, the held-out free-run RRSE (the written config's against the base's),
the selection settings of the best trial (structure searches), and the command's wall time.

    python bench/bench_tune_search.py [--results]

``--results`` also writes them to ``bench/results/tune_search.json`` (the docs quote them from there).
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path
from typing import Any

from cli_run import run_cli
from results_file import save

TRIALS = 40
STRUCTURE = ("--structure", "--max-delay", "0:20", "--degree", "1:3", "--max-terms", "2:16")
RUNS: dict[str, tuple[str, ...]] = {
    "factors": (),
    "structure": STRUCTURE,
    "factors_folds4": ("--folds", "4"),
    "structure_folds4": (*STRUCTURE, "--folds", "4"),
}
X4 = 3  #: x4's column in the JSON's per-state lists


def tune(folder: Path, key: str, extra: tuple[str, ...]) -> dict[str, Any]:
    """One ``pyrhonn tune`` run and its figures."""
    run = run_cli("tune", "--example", "example1", "--config", "example1", "--trials", str(TRIALS), "--seed", "0",
                  "--out", f"{key}.toml", "--json", f"{key}.json", *extra, cwd=folder).check()
    result = json.loads((folder / f"{key}.json").read_text(encoding="utf-8"))
    base, best = result["base"], result["best"]
    out: dict[str, Any] = {
        "command": ["pyrhonn", "tune", "--example", "example1", "--config", "example1", "--trials", str(TRIALS),
                    "--seed", "0", *extra],
        "seconds": run.seconds,
        "improved": bool(result["improved"]),
        "base_score": base["objective"], "score": best["objective"],
        "base_x4": base["normalised_rmse"][X4], "x4": best["normalised_rmse"][X4],
        "folds": best["folds"],
        "base_free_run": result["free_run"]["base"], "free_run": result["free_run"]["written"],
    }
    if result["best_structure"]:
        out["selection"] = dict(result["best_structure"])
    print(f"{key:17} score {out['base_score']:.3f} -> {out['score']:.3f}, x4 {out['base_x4']:.3f} -> {out['x4']:.3f}, "
          f"free run {out['base_free_run']:.3g} -> {out['free_run']:.3g}, {run.seconds:.1f} s"
          + (f", {out['selection']}" if "selection" in out else ""))
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--results", action="store_true", help="also write bench/results/tune_search.json")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        figures: dict[str, Any] = {key: tune(Path(tmp), key, extra) for key, extra in RUNS.items()}
    figures["structure_over_factors_seconds"] = figures["structure"]["seconds"] / figures["factors"]["seconds"]
    figures["folds4_over_single_seconds"] = (figures["structure_folds4"]["seconds"]
                                             / figures["structure"]["seconds"])
    if args.results:
        save("tune_search", figures, argv)
    return 0


if __name__ == "__main__":
    sys.exit(main())
