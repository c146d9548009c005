"""``pyrhonn reproduce``: the paper's Tables 1-6 from one command.

    pyrhonn reproduce example1 --dt 0.2      # Tables 1-2 (and the HONN observer)
    pyrhonn reproduce example1 --dt 0.02     # Tables 3 (absent in the OCR) and 4
    pyrhonn reproduce example2               # Table 5 (robot)
    pyrhonn reproduce example3               # Table 6 (linear induction motor)
    pyrhonn reproduce all                    # everything above

For every state the table shows the paper's figure, ours and ours / paper,
for RMSE and absolute deviation; figures (PNG) and numbers (JSON) go to
``--out``. Progress goes to stderr, tables to stdout. See
:mod:`pyrhonn.reproduce` for what is run and how it is aligned.

Every file is replaced whole, and ``--out`` holds a file ``INCOMPLETE``
from the start of the run until ``summary.json`` is in place
(:mod:`pyrhonn.atomic`): an interrupted run leaves whole files and the
marker saying the folder may mix this run's outputs with an earlier one's.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from typing import Any
from pathlib import Path

from .options import options_named, real_option
from .. import atomic
from .. import reproduce as rp

EXAMPLE_CHOICES = (*rp.EXAMPLES, "all")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "reproduce",
        help="reproduce the paper's simulation tables (plant -> identifier -> metrics, figures)",
        description="Run the paper's examples through the C identifier and print, for every state, the "
                    "paper's RMSE and absolute deviation, ours and the ratio. Writes PNG figures and JSON "
                    "numbers into --out.",
    )
    p.add_argument("example", metavar="EXAMPLE",
                   help="example1, example2, example3 or all")
    p.add_argument("--dt", metavar="SECONDS",
                   help="example1 only: sampling period 0.2 or 0.02 (default: both)")
    p.add_argument("--seed", metavar="N", default="0",
                   help="seed of the measurement model (used with --noise; default 0)")
    p.add_argument("--noise", metavar="FRACTION", default="0",
                   help="measurement noise std as a fraction of each state's std (default 0: the paper's "
                        "noise-free scenario)")
    p.add_argument("--out", metavar="DIR", default="reproduce-out",
                   help="output folder for PNG and JSON (default ./reproduce-out)")
    p.add_argument("--dtype", metavar="DTYPE", default="float64",
                   help="float64 (default) or float32: which build of the C core runs")
    p.add_argument("--config", metavar="FILE",
                   help="identifier config file (or shipped config name) to run instead of the shipped "
                        "configs; needs a single example")
    p.add_argument("--horizon", metavar="SECONDS",
                   help="simulated time (default: example1 100 s, example2 15 s, example3 5 s)")
    p.add_argument("--no-horizon-study", action="store_true",
                   help="skip example1's horizon study (" + ", ".join(f"{h:g}" for h in rp.HORIZONS) + " s)")
    p.add_argument("--no-hold-mask", action="store_true",
                   help="feed held (not updated) samples to the identifier as if they were fresh")
    p.add_argument("--json", action="store_true", help="print the results as JSON instead of tables")
    p.set_defaults(func=run)


def _parse(args: argparse.Namespace) -> dict[str, object]:
    if args.example not in EXAMPLE_CHOICES:
        raise ValueError(f"unknown example {args.example!r}; expected one of {', '.join(EXAMPLE_CHOICES)}")
    dt = None
    if args.dt is not None:
        dt = real_option("--dt", args.dt, positive=True)
        if args.example != "example1":
            raise ValueError(f"--dt: only example1 has a choice of sampling period (0.2 or 0.02 s); "
                             f"{args.example} runs at the paper's period")
        if not any(abs(dt - p) <= 1e-12 for p in rp.EXAMPLE1_PERIODS):
            raise ValueError(f"--dt: example1 was run at 0.2 s and 0.02 s in the paper; got {args.dt!r}")
    if args.dtype not in ("float64", "float32"):
        raise ValueError(f"--dtype: expected float64 or float32, got {args.dtype!r}")
    try:
        seed = int(args.seed)
    except ValueError:
        raise ValueError(f"--seed: expected a non-negative integer, got {args.seed!r}") from None
    if seed < 0:
        raise ValueError(f"--seed: expected a non-negative integer, got {args.seed!r}")
    noise = real_option("--noise", args.noise, nonnegative=True)
    horizon = None if args.horizon is None else real_option("--horizon", args.horizon, positive=True)
    identifiers = None
    if args.config is not None:
        if args.example == "all":
            raise ValueError("--config: a config file fits one example; name example1, example2 or example3")
        identifiers = (rp.identifier_from_file(args.config),)
        rp.check_identifiers(args.example, identifiers)
    return {"dt": dt, "seed": seed, "noise": noise, "horizon": horizon, "identifiers": identifiers}


def run(args: argparse.Namespace) -> int:
    opts = _parse(args)
    keys = rp.scenario_keys(args.example, opts["dt"])  # type: ignore[arg-type]
    out = rp.check_output_dir(args.out)  # fail before any long run
    with atomic.output_folder(out, "pyrhonn reproduce"):  # marked INCOMPLETE until summary.json is in place
        return _run(args, opts, keys, out)


def _run(args: argparse.Namespace, opts: dict[str, Any], keys: tuple[str, ...], out: Path) -> int:
    start = time.perf_counter()
    results = []
    for i, key in enumerate(keys, 1):
        def progress(message: str, _key: str = key, _i: int = i) -> None:
            print(f"pyrhonn reproduce: [{_i}/{len(keys)}] {_key}: {message} "
                  f"({time.perf_counter() - start:.1f} s)", file=sys.stderr, flush=True)

        with options_named(horizon="--horizon"):
            result = rp.run_scenario(
                key, dtype=args.dtype, seed=opts["seed"], noise=opts["noise"], horizon=opts["horizon"],
                identifiers=opts["identifiers"], mask_holds=not args.no_hold_mask,
                horizons=() if args.no_horizon_study else None, progress=progress)
        progress("writing figures and JSON")
        files = rp.write_outputs(result, out)
        results.append((result, files))
        if not args.json:
            print(rp.format_table(result))
            study = rp.format_horizon_study(result)
            if study:
                print()
                print(study)
            print(f"wrote {len(files)} files to {out}/ ({key}.json, {key}-*.png)")
            print()
    total = time.perf_counter() - start
    options = {"example": args.example, "dt": opts["dt"], "seed": opts["seed"], "noise": opts["noise"],
               "horizon": opts["horizon"], "dtype": args.dtype, "config": args.config, "out": str(out),
               "horizon_study": not args.no_horizon_study, "hold_mask": not args.no_hold_mask}
    summary = {"options": options, "seconds": total,
               "scenarios": {r.scenario.key: [str(p.name) for p in f] for r, f in results},
               "targets_missed": [dict(t, scenario=r.scenario.key) for r, _ in results
                                  for t in r.targets() if not t["met"]]}
    atomic.write_text(out / "summary.json", json.dumps(summary, indent=2) + "\n")
    if args.json:
        print(json.dumps({"seconds": total, "results": [r.to_dict() for r, _ in results]}, indent=2,
                         allow_nan=False))
    else:
        print(f"done in {total:.1f} s; summary in {out}/summary.json")
    return 0
