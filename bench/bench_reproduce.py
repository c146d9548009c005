"""The paper's Tables 1-6 as ``pyrhonn reproduce all`` reproduces them, for the docs.

Runs ``pyrhonn reproduce all`` (its defaults: float64, Example 1 at both periods with the paper's
eq. 20 tuning and the tuned ``example1-tuned`` config, Examples 2 and 3) into a scratch folder and
prints, per scenario, estimator (the identifiers, the HONN observer, persistence) and state, the RMSE and absolute deviation (AD) against the
paper's with their ratios. ``--results`` also writes them to ``bench/results/reproduce.json``
(the docs quote them from there), under the scenario's key with its dots as underscores
(``example1-dt0.2`` -> ``example1-dt0_2``).

    python bench/bench_reproduce.py [--results]
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

from results_file import save

FIGURES = ("rmse", "paper_rmse", "rmse_ratio", "ad", "paper_ad", "ad_ratio")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--results", action="store_true", help="also write bench/results/reproduce.json")
    args = ap.parse_args(argv)
    figures: dict[str, object] = {}
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "out"
        proc = subprocess.run([sys.executable, "-m", "pyrhonn.cli", "reproduce", "all", "--out", str(out)],
                              capture_output=True, text=True)
        if proc.returncode != 0:
            raise SystemExit(f"pyrhonn reproduce all exited {proc.returncode}: {proc.stderr.strip()}")
        summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
        for key in summary["scenarios"]:
            result = json.loads((out / f"{key}.json").read_text(encoding="utf-8"))
            scenario: dict[str, object] = {}
            for est in result["estimators"]:
                scenario[est["key"]] = {name: {f: state[f] for f in FIGURES}
                                        for name, state in est["states"].items()}
                for name, state in est["states"].items():
                    print(f"{key:16} {est['key']:17} {name:7} RMSE {state['rmse']:.3g} (paper {state['paper_rmse']}) "
                          f"AD {state['ad']:.3g} (paper {state['paper_ad']})")
            horizons: dict[str, dict[str, object]] = {}
            for point in result.get("horizon_study") or []:  # Example 1: the same run at other horizons
                horizons.setdefault(f"h{point['horizon']:g}", {})[point["key"]] = {"rmse": point["rmse"],
                                                                                  "ad": point["ad"]}
            if horizons:
                scenario["horizons"] = horizons
            figures[key.replace(".", "_")] = scenario
        figures["seconds"] = summary["seconds"]
    if args.results:
        save("reproduce", figures, argv)
    return 0


if __name__ == "__main__":
    sys.exit(main())
