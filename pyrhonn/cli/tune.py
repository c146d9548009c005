"""``pyrhonn tune``: search P0, Q, R, eta and beta of a config on held-out data.

    pyrhonn tune --example example1 --dt 0.2 --config example1 --out tuned.toml --trials 60
    pyrhonn tune --data run.csv --config base.toml --out tuned.toml --study tune.log --n-jobs 2

The trajectory is either one of the paper's examples, simulated by
:mod:`pyrhonn.plants` (``--example``; ``--dt`` for example1: 0.2 s by
default; ``--horizon``: the plant's default), or the user's CSV file
(``--data``, read exactly as ``pyrhonn identify`` reads it, with the columns
named by the config). The base config (``--config``: a .toml file or a
shipped config name) gives the terms and the starting tuning.

The first ``--train-fraction`` of the samples trains, the rest is held out;
the objective is the mean over states of the held-out one-step-ahead RMSE
divided by the state's standard deviation over the held-out part, with
learning on throughout (see :mod:`pyrhonn.tuning` for the exact definition).
For an example, the reference is the plant's true state at every held-out
sample (hold windows included, as ``pyrhonn reproduce`` scores); for a data
file, the measurements at the valid held-out samples.

``--folds K`` scores blocked cross-validation instead: the held-out part is
cut into K contiguous folds; fold f learns from sample 0 on and is scored on
its own block, and a trial's score is the mean over the folds
(:func:`pyrhonn.tuning.fold_bounds`).

``--validate VAL.csv`` (repeatable) and ``--fit-rows A:B`` keep the data
that learn and the data that judge apart, as in ``pyrhonn select``: trials
learn on rows A..B-1 of ``--data`` only and are scored on the validation
recordings (or, without ``--validate``, on the rows outside A..B-1), each
its own experiment, with the weights frozen (:mod:`pyrhonn.tuning_validation`).
``--objective one-step|free-run|k-step:H|mix`` chooses the score
(default one-step); ``--json`` writes the result with the rows that learnt
and those that validated.

``--structure`` also searches the selection settings of ``pyrhonn select``
(``--max-delay``, ``--degree``, ``--max-terms``, each ``LOW:HIGH`` or one
value): every trial selects the terms on the training part (of each fold)
and tunes factors of the selected P0, Q, R, eta and beta.

``--study`` keeps the optuna study: a file (``.log``: an optuna journal
file, recommended; ``.db``: SQLite, slower per trial) or a database URL
(``postgresql://user@host/db``, ``sqlite:///path``) that workers on several
machines share. ``--trials N`` is the number of trials the study holds when
the command ends, counting those of earlier runs and of every worker sharing
the study: two workers with ``--trials 20`` run 20 together, and running the
same command again with a larger N resumes. ``--batch B`` runs B trials per call of the
C core, laid out across B identifiers of the same structure
(:func:`pyrhonn.population.run_identifiers_outcomes`): each score is exactly
the trial's own, the throughput higher (TPE then proposes B trials at a
time, as with ``--n-jobs B``; with ``--structure`` the B trials of a call
share the selection settings the first of them drew, and tune them B ways). ``--per-neuron`` searches one value per
neuron instead of one shared value; ``--params`` limits the searched
parameters; ``--range NAME=LOW:HIGH`` (repeatable) replaces a default range.

Progress goes to stderr. The tuned config (``--out``, a .toml path) keeps
the base config's terms, names and texts, notes the tuning in its
description, and is accepted by ``pyrhonn identify``, ``pyrhonn reproduce
--config`` and :func:`pyrhonn.configfile.load_config`. stdout gets the
base and tuned scores per state and the tuned values. Bad options, files
or studies exit 2 with one line.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import tempfile
import textwrap
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .options import options_named, real_option, row_range
from .. import __version__
from .. import atomic, tuning
from ..metrics import json_value
from ..config import DTYPES, Activation, IdentifierConfig
from ..identifier import Identifier
from ..simulation import scores, simulate
from ..structure import FACTOR_NAMES, Criterion
from ..configfile import ConfigFile, dumps, is_path, load_named
from ..datafile import check_suffix, read_data
from ..experiments import Experiment
from ..refine import DataRange
from ..search import Validation, validate
from ..tuning_objective import TrialFailure
from ..tuning_validation import learnt

EXAMPLES = ("example1", "example2", "example3")
DEFAULT_TRIALS = 50


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "tune", help="search P0, Q, R, eta and beta of a config on held-out data (optuna TPE)",
        description="Search the EKF tuning (P0, Q, R, eta) and the activation slope beta of a base config: "
                    "train on the first part of a trajectory (a paper example or a CSV file), score the "
                    "one-step-ahead RMSE on the rest with learning on, and write the best config as TOML.")
    source = p.add_argument_group("trajectory (one of)")
    source.add_argument("--example", metavar="NAME", help="simulate example1, example2 or example3")
    source.add_argument("--data", metavar="DATA.csv", help="a CSV file as read by pyrhonn identify")
    p.add_argument("--dt", metavar="SECONDS", help="example1 only: sampling period (default 0.2)")
    p.add_argument("--horizon", metavar="SECONDS",
                   help="with --example: simulated time (default: example1 100 s, example2 15 s, example3 5 s)")
    p.add_argument("--valid-suffix", metavar="SUFFIX", default="_valid",
                   help="with --data: validity columns are named <state><SUFFIX> (default _valid)")
    p.add_argument("--config", metavar="BASE", help="base config: a .toml file or a shipped config name")
    p.add_argument("--out", metavar="TUNED.toml", help="where to write the tuned config")
    p.add_argument("--trials", metavar="N", default=str(DEFAULT_TRIALS),
                   help=f"trials the study holds when done, counting earlier runs and every worker sharing "
                        f"--study: two workers with --trials 20 run 20 together (default {DEFAULT_TRIALS})")
    p.add_argument("--n-jobs", metavar="J", default="1", help="trials run in parallel threads (default 1)")
    p.add_argument("--batch", metavar="B", default="1",
                   help="trials per call of the C core, run across B identifiers at once (1..8, default 1; "
                        "with --structure the B trials share the selection settings the first drew)")
    p.add_argument("--study", metavar="FILE|URL",
                   help="optuna study to create, resume or share: a .log (optuna journal file, fast) or .db "
                        "(SQLite) file, or a database URL that workers on several machines share: "
                        "postgresql://user@host/db (needs psycopg) or sqlite:///path")
    p.add_argument("--seed", metavar="S", default="0", help="seed of the TPE sampler (default 0)")
    p.add_argument("--train-fraction", metavar="F",
                   help=f"share of the samples used for training (default {tuning.DEFAULT_TRAIN_FRACTION}; not "
                        "with --validate or --fit-rows)")
    p.add_argument("--validate", action="append", default=[], metavar="VAL.csv",
                   help="with --data: a validation recording (repeatable), its own experiment; trials learn on "
                        "--data only and are scored on these with the weights frozen; nothing learns from them")
    p.add_argument("--fit-rows", metavar="A:B",
                   help="with --data: only samples A..B-1 of it learn; without --validate the samples outside "
                        "them are the validation experiments")
    p.add_argument("--objective", metavar="KIND", default=str(tuning.DEFAULT_OBJECTIVE),
                   help="what a trial is scored on: one-step, free-run (weights frozen after learning), "
                        "k-step:H (H >= 2) or mix (geometric mean of one-step and free-run); default "
                        f"{tuning.DEFAULT_OBJECTIVE}")
    p.add_argument("--json", metavar="FILE.json", help="also write the result as JSON (the rows that learnt and "
                                                        "those that validated, the scores, the trials)")
    p.add_argument("--dtype", metavar="DTYPE", help="float64 or float32: build of the C core to tune for "
                                                    "(default: the config's dtype; written to the output)")
    p.add_argument("--per-neuron", action="store_true", help="one value per neuron instead of one shared value")
    p.add_argument("--params", metavar="LIST", default=",".join(tuning.PARAMETERS),
                   help=f"comma-separated parameters to search (default {','.join(tuning.PARAMETERS)})")
    p.add_argument("--range", metavar="NAME=LOW:HIGH", action="append", default=[],
                   help="absolute log-uniform range of a parameter, e.g. p0=1e4:1e10 (repeatable); with "
                        "--structure a range of factors of the selected value, e.g. p0=0.01:100")
    p.add_argument("--folds", metavar="K",
                   help="blocked cross-validation: cut the held-out part into K contiguous folds; fold f "
                        "learns from sample 0 and is scored on its block; a trial scores the mean over "
                        "folds (default 1: the single split)")
    st = p.add_argument_group("structure search (--structure; off by default)")
    st.add_argument("--structure", action="store_true",
                    help="also search the settings of pyrhonn select: each trial selects the terms on the "
                         "training part (of each fold), then runs the online EKF tuned by factors of the "
                         "selected P0, Q, R, eta, beta; --config then only names the columns and the dtype")
    defaults = tuning.StructureSearch()
    for name, option in _STRUCTURE_OPTIONS.items():
        lo, hi = getattr(defaults, name)
        what = {"max_delay": "deepest state tap x(k-D)", "degree": "products of up to G factors",
                "max_terms": "at most L terms per neuron (the stopping rule picks fewer)"}[name]
        st.add_argument(option, metavar="LOW:HIGH", help=f"{what}, searched in LOW..HIGH, or one value "
                                                         f"(default {lo}:{hi})")
    st.add_argument("--delay-step", metavar="S", help="state taps every S samples (default 1)")
    st.add_argument("--factors", metavar="KINDS",
                    help="factor kinds among S, x, u, 1 (default S,u,1; S,1 without inputs)")
    st.add_argument("--activation", metavar="NAMES", help="activations the selection tries (default "
                                                          "bipolar,logistic)")
    st.add_argument("--criterion", metavar="RULE", help="stopping rule of the selection: ebic (default), bic, "
                                                        "aic or holdout")
    st.add_argument("--holdout", metavar="F", help="with --criterion holdout, the last fraction F of the "
                                                   "training rows scores the path (default 0.2)")
    p.set_defaults(func=run)


_STRUCTURE_OPTIONS = {"max_delay": "--max-delay", "degree": "--degree", "max_terms": "--max-terms"}
_STRUCTURE_FIELDS = {**_STRUCTURE_OPTIONS, "delay_step": "--delay-step", "factors": "--factors",
                     "activations": "--activation", "criterion": "--criterion", "holdout": "--holdout"}


def _int_range(option: str, text: str) -> tuple[int, int]:
    low_text, colon, high_text = text.partition(":")
    try:
        low = int(low_text)
        high = int(high_text) if colon else low
    except ValueError:
        raise ValueError(f"{option}: expected LOW:HIGH or one whole number, got {text!r}") from None
    if low > high:
        raise ValueError(f"{option}: expected LOW <= HIGH, got {text!r}")
    return low, high


def _structure(args: argparse.Namespace, n_inputs: int) -> tuning.StructureSearch | None:
    given = [opt for opt in _STRUCTURE_FIELDS.values()
             if getattr(args, opt.removeprefix("--").replace("-", "_")) is not None]
    if not args.structure:
        if given:
            raise ValueError(f"{given[0]}: only with --structure")
        return None
    kw: dict[str, object] = {}
    for name, option in _STRUCTURE_OPTIONS.items():
        if getattr(args, name) is not None:
            kw[name] = _int_range(option, getattr(args, name))
    if args.delay_step is not None:
        kw["delay_step"] = _int("--delay-step", args.delay_step, 1)
    if args.factors is not None:
        names = tuple(f.strip() for f in args.factors.split(","))
        for f in names:
            if f not in FACTOR_NAMES:
                raise ValueError(f"--factors: {f!r} is not a factor kind; expected some of {', '.join(FACTOR_NAMES)}")
        kw["factors"] = names
    elif n_inputs == 0:
        kw["factors"] = ("S", "1")
    if args.activation is not None:
        acts = []
        for name in args.activation.split(","):
            try:
                acts.append(Activation(name.strip()))
            except ValueError:
                raise ValueError(f"--activation: {name.strip()!r}: expected bipolar or logistic") from None
        kw["activations"] = tuple(acts)
    if args.criterion is not None:
        if args.criterion not in [c.value for c in Criterion]:
            raise ValueError(f"--criterion: expected one of {', '.join(c.value for c in Criterion)}, got "
                             f"{args.criterion!r}")
        kw["criterion"] = Criterion(args.criterion)
    if args.holdout is not None:
        kw["holdout"] = real_option("--holdout", args.holdout)
    try:
        return tuning.StructureSearch(**kw)  # type: ignore[arg-type]
    except ValueError as exc:
        raise _named(exc) from None


def _named(exc: ValueError) -> ValueError:
    """A library error naming a field (``study_path: ...``, ``structure.max_delay: ...``) as its option."""
    field, sep, rest = str(exc).partition(": ")
    key = field.removeprefix("structure.").split(".")[0].split("[")[0]
    option = {"study_path": "--study", "train_fraction": "--train-fraction", "folds": "--folds",
              **_STRUCTURE_FIELDS}.get(key) if sep else None
    return ValueError(f"{option}: {rest}") if option else exc


# -- options -----------------------------------------------------------------------------------------


def _int(option: str, text: str, low: int) -> int:
    try:
        value = int(text)
    except ValueError:
        raise ValueError(f"{option}: expected a whole number, got {text!r}") from None
    if value < low:
        raise ValueError(f"{option}: must be >= {low}, got {value}")
    return value


@dataclass(frozen=True)
class Options:
    trials: int
    n_jobs: int
    batch: int
    seed: int
    train_fraction: float
    params: tuple[str, ...]
    ranges: dict[str, tuple[float, float]]
    dt: float | None
    horizon: float | None
    out: Path
    study: tuning.StudyStorage | None
    folds: int
    objective: tuning.Objective
    json: Path | None


def _check_out(text: str | None) -> Path:
    if not text:
        raise ValueError("--out: missing; give the path of the tuned config file (ending in .toml)")
    out = Path(text)
    if out.suffix != ".toml":
        raise ValueError(f"--out: {text!r} must end in .toml (so that --config reads it as a file)")
    if out.is_dir():
        raise ValueError(f"--out: {text!r} is a directory")
    folder = out.parent
    if not folder.is_dir():
        raise ValueError(f"--out: folder {str(folder)!r} does not exist")
    try:  # a real write: permission bits alone do not say it (e.g. as root, or a read-only mount)
        with tempfile.NamedTemporaryFile(dir=folder, prefix=".pyrhonn-tune-", suffix=".tmp"):
            pass
    except OSError as exc:
        raise ValueError(f"--out: cannot write in folder {str(folder)!r} ({exc.strerror or exc})") from None
    if out.exists() and not os.access(out, os.W_OK):
        raise ValueError(f"--out: {text!r} is not writable")
    return out


def _parse(args: argparse.Namespace) -> Options:
    if (args.example is None) == (args.data is None):
        raise ValueError("give the trajectory as either --example NAME or --data FILE.csv (exactly one)")
    if args.example is not None and args.example not in EXAMPLES:
        raise ValueError(f"--example: unknown example {args.example!r}; expected one of {', '.join(EXAMPLES)}")
    if args.config is None:
        raise ValueError("--config: missing; give the base config (a .toml file or a shipped name such as "
                         "example1)")
    dt = horizon = None
    if args.dt is not None:
        if args.example != "example1":
            raise ValueError("--dt: only example1 has a choice of sampling period; example2 runs at 0.01 s, "
                             "example3 at 0.0001 s, and a data file at its own rate")
        dt = real_option("--dt", args.dt)
        if not dt > 0:
            raise ValueError(f"--dt: must be > 0, got {args.dt!r}")
    if args.horizon is not None:
        if args.example is None:
            raise ValueError("--horizon: only with --example (a data file has its own length)")
        horizon = real_option("--horizon", args.horizon)
        if not horizon > 0:
            raise ValueError(f"--horizon: must be > 0, got {args.horizon!r}")
    if args.data is not None and not Path(args.data).is_file():
        raise ValueError(f"--data: no such file: {args.data!r}")
    if args.example is not None and args.valid_suffix != "_valid":
        raise ValueError("--valid-suffix: only with --data")
    if is_path(args.config) and not Path(args.config).is_file():
        raise ValueError(f"--config: no such file: {args.config!r}")
    kept_apart = bool(args.validate) or args.fit_rows is not None
    for option, given in (("--validate", bool(args.validate)), ("--fit-rows", args.fit_rows is not None)):
        if given and args.data is None:
            raise ValueError(f"{option}: only with --data (the recording that learns)")
    for path in args.validate:
        if not Path(path).is_file():
            raise ValueError(f"--validate: no such file: {path!r}")
    for option, value in (("--train-fraction", args.train_fraction), ("--folds", args.folds)):
        if kept_apart and value is not None:
            raise ValueError(f"{option}: not with --validate or --fit-rows (the validation experiments are the "
                             "held-out data)")
    try:
        objective = tuning.Objective.parse(args.objective)
    except ValueError as exc:
        raise ValueError(f"--objective: {str(exc).partition(': ')[2]}") from None
    if objective.frozen and args.structure:
        raise ValueError(f"--objective: {objective}: --structure scores one step ahead only")
    json_out = None
    if args.json is not None:
        json_out = Path(args.json)
        if json_out.suffix != ".json" or not json_out.parent.is_dir():
            raise ValueError(f"--json: {args.json!r} must end in .json, in an existing folder")
    fraction = real_option("--train-fraction", args.train_fraction or str(tuning.DEFAULT_TRAIN_FRACTION))
    if not 0.0 < fraction < 1.0:
        raise ValueError(f"--train-fraction: must be between 0 and 1 (exclusive), got {args.train_fraction!r}")
    trials = _int("--trials", args.trials, 1)
    n_jobs = _int("--n-jobs", args.n_jobs, 1)
    from ..population import max_population

    batch = _int("--batch", args.batch, 1)
    if batch > max_population():
        raise ValueError(f"--batch: at most {max_population()} (RHONN_MAX_POPULATION), got {batch}")
    seed = _int("--seed", args.seed, 0)
    if seed >= 2**32:
        raise ValueError(f"--seed: must be < 2**32, got {seed}")
    if args.dtype is not None and args.dtype not in DTYPES:
        raise ValueError(f"--dtype: expected one of {', '.join(DTYPES)}, got {args.dtype!r}")
    params = tuple(p.strip() for p in args.params.split(","))
    for p in params:
        if p not in tuning.PARAMETERS:
            raise ValueError(f"--params: unknown parameter {p!r}; expected a comma-separated list of "
                             f"{', '.join(tuning.PARAMETERS)}")
    if len(set(params)) != len(params):
        raise ValueError(f"--params: {args.params!r} names a parameter twice")
    ranges: dict[str, tuple[float, float]] = {}
    for text in args.range:
        name, eq, span = text.partition("=")
        low_text, colon, high_text = span.partition(":")
        if not eq or not colon:
            raise ValueError(f"--range: expected NAME=LOW:HIGH (e.g. p0=1e4:1e10), got {text!r}")
        name = name.strip()
        if name not in tuning.PARAMETERS:
            raise ValueError(f"--range: unknown parameter {name!r}; expected one of {', '.join(tuning.PARAMETERS)}")
        if name not in params:
            raise ValueError(f"--range: {name} is not searched (--params {args.params})")
        if name in ranges:
            raise ValueError(f"--range: {name} given twice")
        low, high = real_option(f"--range {name}", low_text), real_option(f"--range {name}", high_text)
        if not 0 < low < high:
            raise ValueError(f"--range: {text!r}: expected 0 < LOW < HIGH")
        ranges[name] = (low, high)
    out = _check_out(args.out)
    folds = _int("--folds", args.folds or "1", 1)
    if objective.frozen and folds > 1:
        raise ValueError(f"--objective: {objective} scores the held-out part with the weights frozen at the "
                         "split: only with --folds 1")
    study = None
    if args.study is not None:
        try:
            study = tuning.check_study(args.study)
        except ValueError as exc:
            raise _named(exc) from None
        if study.path is not None and study.path.resolve() == out.resolve():
            raise ValueError("--study and --out name the same file")
    if is_path(args.config) and Path(args.config).resolve() == out.resolve():
        raise ValueError("--out: would overwrite the base config --config; write the tuned config elsewhere")
    if json_out is not None and json_out.resolve() == out.resolve():
        raise ValueError("--json and --out name the same file")
    return Options(trials, n_jobs, batch, seed, fraction, params, ranges, dt, horizon, out, study, folds, objective,
                   json_out)


# -- the trajectory -------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Trajectory:
    label: str
    X: np.ndarray
    U: np.ndarray
    valid: np.ndarray
    truth: np.ndarray | None
    name: str = "data"
    first: int = 0  #: the file's sample at row 0 (--fit-rows)
    validation: tuple[Experiment, ...] = ()


def _example(name: str, dt: float | None, horizon: float | None, cf: ConfigFile, config_source: str) -> Trajectory:
    from ..plants import lim, oscillator, robot

    kwargs: dict[str, Any] = {} if horizon is None else {"horizon": horizon}
    with options_named(horizon="--horizon", dt="--dt"):
        if name == "example1":
            traj = oscillator.simulate(dt=0.2 if dt is None else dt, **kwargs)
        elif name == "example2":
            traj = robot.simulate(**kwargs)
        else:
            traj = lim.simulate(**kwargs)
    cfg = cf.config
    if (cfg.n_states, cfg.n_inputs) != (traj.n_states, traj.n_inputs):
        raise ValueError(f"--config {config_source}: has {cfg.n_states} states and {cfg.n_inputs} inputs, but "
                         f"{name}'s plant has {traj.n_states} ({', '.join(traj.state_names)}) and "
                         f"{traj.n_inputs} ({', '.join(traj.input_names)})")
    label = f"{name} (dt {traj.dt:g} s, {traj.t[-1]:g} s, {traj.n_samples} samples)"
    return Trajectory(label, traj.X_meas, traj.U, traj.valid, traj.X)


def _data(path: str, cf: ConfigFile, config_source: str, valid_suffix: str) -> Trajectory:
    try:
        suffix = check_suffix(valid_suffix)
    except ValueError as exc:
        raise ValueError(f"--valid-suffix: {exc}") from None
    data = read_data(path, cf, valid_suffix=suffix, config_source=config_source)
    return Trajectory(f"{path} ({data.n_samples} samples)", data.X, data.U, data.valid, None, name=path)


def _kept_apart(traj: Trajectory, args: argparse.Namespace, cf: ConfigFile, config_source: str) -> Trajectory:
    """The trajectory cut to ``--fit-rows``, with the ``--validate`` recordings (or, without them, the
    samples outside the fitting rows) as validation experiments."""
    T = traj.X.shape[0]
    a, b = row_range("--fit-rows", args.fit_rows, T)
    whole = Experiment(traj.X, traj.U, traj.valid, name=traj.name)
    validation: list[Experiment] = []
    if not args.validate:
        validation = [whole.cut(s, e) for s, e in ((0, a), (b, T)) if e - s >= 2]
        if not validation:
            raise ValueError(f"--fit-rows: {args.fit_rows} leaves no samples of {traj.name} to validate; give "
                             "--validate VAL.csv")
    for path in args.validate:
        data = read_data(path, cf, valid_suffix=check_suffix(args.valid_suffix), config_source=config_source)
        validation.append(Experiment(data.X, data.U, data.valid, name=path))
    fit = whole.cut(a, b) if (a, b) != (0, T) else whole
    return Trajectory(f"{traj.name} rows {a}..{b - 1} ({b - a} samples)", fit.X, fit.U, fit.valid, None,
                      name=traj.name, first=a, validation=tuple(validation))


# -- output ------------------------------------------------------------------------------------------------


def _what(result: tuning.TuneResult) -> str:
    names = ", ".join(dict.fromkeys(d.param for d in result.space))
    what = f"{names} ({'one value per neuron' if result.per_neuron else 'shared by all neurons'})"
    if result.structure is None:
        return what
    ranges = ", ".join(f"{name.replace('_', ' ')} {lo}..{hi}" for name, lo, hi in result.structure.dimensions())
    return f"the selection's {ranges} and factors of the selected {what}"


def _scheme(split: tuning.Split, objective: str = "one-step", fit_rows: tuple[str, ...] = (),
            validation_rows: tuple[str, ...] = ()) -> str:
    """What is trained and what is scored, in words."""
    if validation_rows:
        return (f"learning on {'; '.join(fit_rows)}, scored {objective} with the weights frozen on the validation "
                f"experiments ({'; '.join(validation_rows)}), each run on its own")
    if objective != "one-step":
        return (f"learning on samples 0..{split.n_train - 1}, then the weights frozen and scored {objective} on "
                f"samples {split.n_train}..{split.n_samples - 1}")
    if len(split.folds) <= 1:
        return (f"learning on samples 0..{split.n_train - 1}, scored one step ahead on samples {split.n_train}.."
                f"{split.n_samples - 1} with learning on")
    return (f"{len(split.folds)} folds, fold f learning from sample 0 and scored one step ahead on its block ("
            + ", ".join(f"{n}..{e - 1}" for n, e in split.folds) + ") with learning on, mean over folds")


def _note(result: tuning.TuneResult, config_source: str, label: str) -> str:
    s = result.split
    base = "diverged" if result.base is None else f"{result.base.value:.6g}"
    tuned = f"{result.best.value:.6g}" if result.best is not None else "n/a"
    structure = ""
    if result.best_structure:
        last = s.folds[-1][0] if s.folds else s.n_train
        structure = (f" Terms selected by pyrhonn select on samples 0..{last - 1} with " + ", ".join(
            f"{k.replace('_', ' ')} {v}" for k, v in result.best_structure.items())
                     + f", criterion {result.structure.criterion.value if result.structure else '?'}.")
    head = (f"Tuned by `pyrhonn tune` (pyrhonn {__version__}) from {config_source} on {label}: "
            f"{_scheme(s, result.objective, result.fit_rows, result.validation_rows)}; searched {_what(result)} with optuna TPE (seed "
            f"{result.seed}), {result.counts.total} trials in the study.{structure} Held-out {result.objective} "
            f"score (mean over states of RMSE / std of the held-out targets, pyrhonn.tuning): base {base}, ")
    text = head + (f"tuned {tuned} (trial {result.best_trial})." if result.improved
                   else f"not written: {result.kept_base}." if result.kept_base
                   else "no trial beat it: the tuning is the base config's.")
    return textwrap.fill(text, width=90, break_long_words=False, break_on_hyphens=False)


def _fmt(v: float | None) -> str:
    return f"{'-':>11}" if v is None or not math.isfinite(v) else f"{v:>11.5g}"


def _report(result: tuning.TuneResult, cf: ConfigFile) -> str:
    lines = []
    names = cf.state_names
    width = max(5, *(len(n) for n in names))
    base, best = result.base, result.best
    where = "on the validation experiments, weights frozen" if result.validation_rows else (
        "held-out, learning on" if result.objective == "one-step" else "held-out, weights frozen at the split")
    lines.append(f"{result.objective} RMSE ({where}), and RMSE / std of the held-out targets (the RRSE):")
    lines.append(f"  {'state':<{width}}  {'std':>11}  {'RMSE base':>11}  {'RMSE tuned':>11}  "
                 f"{'norm. base':>11}  {'norm. tuned':>11}")
    for j, name in enumerate(names):
        scored = best or base
        scale = None if scored is None else scored.scale[j]
        lines.append(f"  {name:<{width}}  {_fmt(scale)}  {_fmt(None if base is None else base.rmse[j])}  "
                     f"{_fmt(None if best is None else best.rmse[j])}  "
                     f"{_fmt(None if base is None else base.normalised[j])}  "
                     f"{_fmt(None if best is None else best.normalised[j])}")
    if base is None:
        lines.append(f"score: base config failed ({result.base_failure}); tuned "
                     f"{'-' if best is None else f'{best.value:.6g}'}")
    elif best is not None and result.improved:
        change = 100.0 * (best.value - base.value) / base.value if base.value > 0 else 0.0
        lines.append(f"score (mean normalised RMSE): base {base.value:.6g} -> tuned {best.value:.6g} "
                     f"({change:+.1f} %), trial {result.best_trial}")
    elif result.kept_base:
        lines.append(f"score (mean normalised RMSE): base {base.value:.6g}; not written: {result.kept_base}")
    else:
        lines.append(f"score (mean normalised RMSE): base {base.value:.6g}; no trial beat it, the base "
                     "tuning is written")
    cfg = result.config
    lines.append("tuned values:" if result.improved else "values (base):")
    params = list(dict.fromkeys(d.param for d in result.space))
    if result.per_neuron or result.selection is not None or not _same_in_every_neuron(cfg, params):
        lines.append("  " + f"{'neuron':<{width}}" + "".join(f"  {p:>10}" for p in params))
        for i, nr in enumerate(cfg.neurons):
            lines.append("  " + f"{names[i]:<{width}}" + "".join(f"  {_value(nr, p):>10}" for p in params))
    else:
        lines.append("  " + ", ".join(f"{p} = {_value(cfg.neurons[0], p)}" for p in params) + " (every neuron)")
    if result.selection is not None:
        lines.append("selected structure: " + ", ".join(f"{k.replace('_', ' ')} {v}"
                                                        for k, v in result.best_structure.items()))
        lines.append(result.selection.report(list(cf.state_names)))
    return "\n".join(lines)


def _free_run_report(base: IdentifierConfig, result: tuning.TuneResult, cf: ConfigFile, traj: Any) -> str:
    """The held-out part in free run, for the base and the written config: learnt online up to the
    split, then the weights frozen and the network fed its own predictions (pyrhonn.simulation).
    The search scores one step ahead; this says whether the tuned model also simulates."""
    N = result.split.n_train
    truth = traj.truth if traj.truth is not None else traj.X
    scored = np.zeros(traj.X.shape, dtype=bool)
    scored[N:] = True
    if traj.valid is not None and traj.truth is None:
        scored &= traj.valid
    rows: dict[str, Any] = {}
    for label, cfg in (("base", base), ("tuned", result.config)):
        try:
            X = np.where(np.isfinite(traj.X), traj.X, 0.0).astype(cfg.dtype)
            U = traj.U.astype(cfg.dtype)
            sim = simulate(Identifier(cfg), X, U if cfg.n_inputs else None, traj.valid, free_run_from=N)
            assert sim.free_run is not None
            rows[label] = scores(truth, sim.free_run.astype(np.float64), scored)
        except ValueError as exc:
            rows[label] = str(exc)
    names = cf.state_names
    width = max(5, *(len(n) for n in names))
    lines = [f"held-out free run (weights frozen after sample {N - 1}, the network fed its own predictions):",
             f"  {'state':<{width}}  {'RMSE base':>11}  {'RMSE tuned':>11}  {'RRSE base':>11}  {'RRSE tuned':>11}"]
    for j, name in enumerate(names):
        values = [None if isinstance(rows[k], str) else float(getattr(rows[k], metric)[j])
                  for metric in ("rmse", "rrse") for k in ("base", "tuned")]
        cells = [f"{'diverged':>11}" if v == math.inf else _fmt(v) for v in values]
        lines.append(f"  {name:<{width}}  " + "  ".join(cells))
    for k in ("base", "tuned"):
        if isinstance(rows[k], str):
            lines.append(f"  {k}: could not run: {rows[k]}")
    return "\n".join(lines)


def _validation_report(base: IdentifierConfig, result: tuning.TuneResult, cf: ConfigFile,
                       traj: Trajectory) -> tuple[str, dict[str, object]]:
    """The base and the written config learnt on the fitting rows, then frozen over the validation
    experiments: one-step and free-run RMSE per state (:func:`pyrhonn.search.validate`)."""
    est = [Experiment(np.where(traj.valid, traj.X, np.nan), traj.U, traj.valid, name=traj.name, first=traj.first)]
    data_range = DataRange.of(est)
    names = cf.state_names
    width = max(5, *(len(n) for n in names))
    lines = [f"validation experiments ({'; '.join(result.validation_rows)}), weights learnt on "
             f"{'; '.join(result.fit_rows)} then frozen:",
             f"  {'state':<{width}}  {'one-step base':>13}  {'tuned':>11}  {'free-run base':>13}  {'tuned':>11}"]
    figures: dict[str, object] = {}
    checked: dict[str, Validation] = {}
    for label, cfg in (("base", base), ("tuned", result.config)):
        try:
            checked[label] = validate(learnt(cfg, est), list(traj.validation), data_range)
        except TrialFailure as exc:
            lines.append(f"  {label}: could not run: {exc}")
            figures[label] = {"failure": str(exc)}
            continue
        v = checked[label]
        figures[label] = {
            "free_run_left_range": None if v.left_range is None else {"experiment": v.left_range[0],
                                                                      "sample": v.left_range[1]},
            **{kind: {name: {"rmse": json_value(rmse[j]), "rrse": json_value(rrse[j])} for j, name in enumerate(names)}
               for kind, rmse, rrse in (("one_step", v.one_rmse, v.one_rrse), ("free_run", v.free_rmse, v.free_rrse))}}
    for j, name in enumerate(names):
        cells = []
        for kind in ("one", "free"):
            for label in ("base", "tuned"):
                got = checked.get(label)
                w = 13 if label == "base" else 11
                if got is None:
                    cells.append(f"{'-':>{w}}")
                elif kind == "free" and got.left_range is not None:
                    cells.append(f"{'diverged':>{w}}")
                else:
                    cells.append(f"{float((got.one_rmse if kind == 'one' else got.free_rmse)[j]):>{w}.5g}")
        lines.append(f"  {name:<{width}}  " + "  ".join(cells))
    for label, v in checked.items():
        if v.left_range is not None:
            lines.append(f"  {label}: free run left the data's range at sample {v.left_range[1]} of {v.left_range[0]}")
    return "\n".join(lines), figures


def _same_in_every_neuron(cfg: IdentifierConfig, params: list[str]) -> bool:
    """Whether every neuron holds the same value of each of ``params`` (a base
    config kept as it was may hold its own per neuron, even after a shared search)."""
    first = cfg.neurons[0]
    return all(np.array_equal(np.asarray(getattr(nr, p)), np.asarray(getattr(first, p)))
               for nr in cfg.neurons[1:] for p in params)


def _value(neuron: object, param: str) -> str:
    v = getattr(neuron, param)
    return "array" if isinstance(v, np.ndarray) else f"{float(v):.3g}"


def _at_a_time(opts: Options) -> str:
    """How many trials run at once: ``--n-jobs`` workers, each running ``--batch`` trials per call."""
    if opts.batch == 1:
        return f"{opts.n_jobs} at a time"
    workers = f"{opts.n_jobs} workers" if opts.n_jobs > 1 else "1 worker"
    return f"{opts.n_jobs * opts.batch} at a time ({workers}, {opts.batch} trials per call)"


def run(args: argparse.Namespace) -> int:
    opts = _parse(args)
    cf = load_named(args.config)
    config_source = args.config
    if args.example is not None:
        traj = _example(args.example, opts.dt, opts.horizon, cf, config_source)
    else:
        traj = _data(args.data, cf, config_source, args.valid_suffix)
        if args.validate or args.fit_rows is not None:
            traj = _kept_apart(traj, args, cf, config_source)
    dtype = args.dtype or cf.config.dtype
    base = cf.config if dtype == cf.config.dtype else cf.config.replace(dtype=dtype)
    structure = _structure(args, base.n_inputs)

    import optuna

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    start = time.perf_counter()

    def progress(message: str) -> None:
        print(f"pyrhonn tune: {message} ({time.perf_counter() - start:.1f} s)", file=sys.stderr, flush=True)

    try:
        T = traj.X.shape[0]
        if traj.validation:
            scheme = _scheme(tuning.Split(T, T, ()), str(opts.objective), (traj.label,),
                             tuple(f"{ex.name} rows {ex.rows}" for ex in traj.validation))
        else:
            split = tuning.Split(T, tuning.split_point(T, opts.train_fraction), (),
                                 tuning.fold_bounds(T, tuning.split_point(T, opts.train_fraction), opts.folds))
            scheme = _scheme(split, str(opts.objective))
        progress(f"{traj.label}: {scheme}; until the study holds {opts.trials} trials, {_at_a_time(opts)}"
                 + (f", study {opts.study.shown}" if opts.study is not None else ""))
        result = tuning.tune(
            base, traj.X, traj.U, traj.valid, truth=traj.truth, train_fraction=opts.train_fraction,
            folds=opts.folds, n_trials=opts.trials, n_jobs=opts.n_jobs, batch=opts.batch, seed=opts.seed,
            per_neuron=args.per_neuron,
            params=opts.params, ranges=opts.ranges or None, structure=structure, study_path=args.study,
            progress=progress, objective=opts.objective, validation=list(traj.validation),
            estimation_name=traj.name, estimation_first=traj.first)
    except ValueError as exc:
        raise _named(exc) from None
    note = _note(result, config_source, traj.label)
    own, why = cf.description, cf.why
    if result.selection is not None:  # the terms are the selection's: so are the texts that explain them
        selected = result.selection.config_file(cf.state_names, cf.input_names)
        own, why = selected.description, selected.why
    description = f"{own.rstrip()}\n\n{note}\n" if own.strip() else f"{note}\n"
    tuned = ConfigFile(config=result.config, state_names=cf.state_names, input_names=cf.input_names,
                       description=description, why=why, bus=cf.bus)
    atomic.write_text(opts.out, dumps(tuned))  # replaced whole: an interrupted write leaves the previous file

    c = result.counts
    print(f"tuned {config_source} on {traj.label}, {dtype}")
    print(f"{_scheme(result.split, result.objective, result.fit_rows, result.validation_rows)}; "
          f"searched {_what(result)}")
    print(f"ran {result.new_trials} trials; the study has {c.total}: {c.complete} scored, {c.failed} failed "
          f"(identifier stopped or diverged" + (", or selection refused" if structure else "") + ")"
          + (f", {c.errored} errored" if c.errored else "")
          + (f", {c.running} running or left running" if c.running else ""))
    if len(result.split.folds) > 1 and result.best is not None:
        print("score per fold: " + ", ".join(f"{v:.6g}" for v in result.best.folds))
    print(_report(result, cf))
    frozen: dict[str, object] = {}
    if traj.validation:
        text, frozen = _validation_report(base, result, cf, traj)
        print(text)
    else:
        print(_free_run_report(base, result, cf, traj))
    if opts.json is not None:
        payload = {**result.summary(), "validation_figures": frozen}
        atomic.write_text(opts.json, json.dumps(payload, indent=2) + "\n")
    print(f"wrote {opts.out}" + (f"; study in {opts.study.shown} (a larger --trials resumes it)"
                                 if opts.study else ""))
    return 0
