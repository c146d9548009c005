"""``pyrhonn select`` then ``pyrhonn tune`` on the measured cascaded tanks, judged on data kept apart.

The estimation and validation records of ``bench/data/cascaded_tanks/`` are
written as CSV files (``t,y,u``); ``pyrhonn select`` runs on the estimation
record with its default options; ``pyrhonn tune`` then runs with its default
options (50 trials, seed 0) and ``--validate validation.csv``, once per
``--objective``, and once with ``--fit-rows 0:700`` (the rest of the
estimation record validates, the validation record untouched). Every
command runs through the installed command line. For each written config
the table gives the free-run and one-step RMSE on the validation record
with its weights learnt online on the estimation record, then frozen; and
for ``select``'s config also with its weights frozen at its w0. The same
for ``select --dtype float32``'s config, and for both configs the weights
learnt through the first 10 and 100 samples only, then frozen (how far a
few learning steps move a model that simulated well).

    python bench/bench_tune_validation.py [--keep DIR] [--results]

``--results`` also writes the figures to ``bench/results/tune_validation.json``
(the docs quote them from there): per row its free-run and one-step RMSE
and free-run RRSE, and per tune run whether it wrote a better config and the
held-out scores of its base and its best trial.
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

from bench_real_data import cascaded_tanks, write_record
from cli_run import run_cli
from results_file import save

from pyrhonn.configfile import load_named
from pyrhonn.datafile import read_data
from pyrhonn.experiments import Experiment
from pyrhonn.refine import DataRange
from pyrhonn.search import Validation, validate
from pyrhonn.tuning_validation import learnt

OBJECTIVES = ("one-step", "free-run", "mix", "k-step:10")
STEPS = (10, 100)  # learning steps from the start of the estimation record, then frozen


def _cli(folder: Path, *args: str) -> float:
    return run_cli(*args, cwd=folder).check().seconds


def _row(name: str, v: Validation, extra: str = "") -> str:
    free = "diverged" if v.left_range is not None else f"{v.free_rmse[0]:.4f}"
    return f"{name:44} {free:>9} {v.free_rrse[0]:>7.4f} {v.one_rmse[0]:>9.4f}  {extra}"


def _figures(v: Validation) -> dict[str, object]:
    return {"free_rmse": float(v.free_rmse[0]), "free_rrse": float(v.free_rrse[0]),
            "one_step_rmse": float(v.one_rmse[0]), "diverged": v.left_range is not None}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--keep", metavar="DIR", help="keep the CSV files, configs and JSON results in DIR")
    ap.add_argument("--results", action="store_true", help="also write bench/results/tune_validation.json")
    args = ap.parse_args(argv)
    figures: dict[str, object] = {}

    def row(key: str, name: str, v: Validation, extra: str = "") -> None:
        figures[key] = _figures(v)
        print(_row(name, v, extra))

    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(args.keep) if args.keep else Path(tmp)
        folder.mkdir(parents=True, exist_ok=True)
        ds = cascaded_tanks()
        write_record(folder / "est.csv", ds.est, ds.sampling_period)
        write_record(folder / "val.csv", ds.val, ds.sampling_period)
        seconds = {"select": _cli(folder, "select", "est.csv", "--states", "y", "--inputs", "u", "--out", "sel.toml")}
        seconds["select --dtype float32"] = _cli(folder, "select", "est.csv", "--states", "y", "--inputs", "u",
                                                 "--out", "sel32.toml", "--dtype", "float32")
        runs = {f"tune --validate val.csv --objective {o}": ("--validate", "val.csv", "--objective", o)
                for o in OBJECTIVES}
        runs["tune --fit-rows 0:700"] = ("--fit-rows", "0:700")
        for k, (label, extra) in enumerate(runs.items()):
            seconds[label] = _cli(folder, "tune", "--data", "est.csv", "--config", "sel.toml", "--out",
                                  f"tuned{k}.toml", "--json", f"tuned{k}.json", *extra)
        cf = load_named(str(folder / "sel.toml"))

        def record(name: str) -> Experiment:
            d = read_data(folder / name, cf)
            return Experiment(d.X, d.U, d.valid, name=name)

        est, val = record("est.csv"), record("val.csv")
        data_range = DataRange.of([est])
        print(f"{'model (validation record)':44} {'free RMSE':>9} {'RRSE':>7} {'1-step':>9}  seconds / result")
        row("select_frozen", "select, weights frozen at w0", validate(cf.config, [val], data_range),
            f"{seconds['select']:.1f} s")
        row("select_learnt", "select, learnt online on est, then frozen",
            validate(learnt(cf.config, [est]), [val], data_range))
        # the float32 config: learning keeps what the fit determined well (its P0's conditioning)
        cf32 = load_named(str(folder / "sel32.toml"))
        row("select32_frozen", "select --dtype float32, frozen at w0", validate(cf32.config, [val], data_range),
            f"{seconds['select --dtype float32']:.1f} s")
        for cfg, what in ((cf.config, "float64"), (cf32.config, "float32")):
            for steps in STEPS:
                start = Experiment(est.X[:steps], est.U[:steps], est.valid[:steps], name=f"est rows 0:{steps}")
                row(f"{what}_learnt_{steps}", f"{what}, learnt on est rows 0:{steps}, then frozen",
                    validate(learnt(cfg, [start]), [val], data_range))
        row("select32_learnt", "select --dtype float32, learnt online on est, then frozen",
            validate(learnt(cf32.config, [est]), [val], data_range))
        for k, label in enumerate(runs):
            cfg = load_named(str(folder / f"tuned{k}.toml")).config
            result = json.loads((folder / f"tuned{k}.json").read_text(encoding="utf-8"))
            what = "improved" if result["improved"] else f"kept the base ({result['kept_base']})"
            key = "tune_" + label.split()[-1].replace("-", "_").replace(":", "_")
            row(key, label, validate(learnt(cfg, [est]), [val], data_range), f"{seconds[label]:.1f} s, {what}")
            top = result["top_trials"]
            figures[key] = {**figures[key], "improved": bool(result["improved"]),
                            "base_objective": result["base"]["objective"],
                            "best_trial_objective": top[0]["objective"] if top else None,
                            "base_held_out_free_run": result["free_run"]["base"]}
    if args.results:
        save("tune_validation", figures, argv)
    return 0


if __name__ == "__main__":
    sys.exit(main())
