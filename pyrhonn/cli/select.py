"""``pyrhonn select``: choose the identifier's terms and delays from data.

``pyrhonn select data.csv --states x1,x2 [--inputs u1] --out cfg.toml
[--max-delay D] [--delay-step S] [--degree G] [--factors S,x,u,1]
[--activation bipolar,logistic] [--beta 0.5,1,2] [--criterion ebic|bic|aic|holdout]
[--holdout F] [--max-terms L] [--p0 V] [--q V] [--r V] [--dtype float64|float32]
[--report FILE] [--json FILE] [--valid-suffix _valid]``

Reads the data file of ``pyrhonn identify`` (:mod:`pyrhonn.datafile`), with
the columns named by ``--states`` and ``--inputs``; runs
:func:`pyrhonn.structure.select`; writes the config (``--out``, the TOML
format of :mod:`pyrhonn.configfile`, which ``identify``, ``tune`` and
``export`` read) and prints the report: per neuron the terms in the order
chosen with their error reduction ratios, and the estimated delay of each
state; then the selected model checked on the same data with its
least-squares weights frozen: one step ahead and in free run (the network
fed its own predictions from the first sample its taps can read on), RMSE
and RRSE per state (:mod:`pyrhonn.simulation`). Every file is replaced whole
(:mod:`pyrhonn.atomic`).
"""
from __future__ import annotations

import argparse
import json
from contextlib import contextmanager
from typing import Iterator

import numpy as np

from .. import atomic
from ..config import DTYPES, Activation, Factor, IdentifierConfig
from ..configfile import ConfigFile, dumps
from ..datafile import Data, check_suffix, read_data
from ..identifier import Identifier
from ..metrics import json_value
from ..simulation import Scores, scores, simulate
from ..structure import FACTOR_NAMES, CandidateSpace, Criterion, Selection, select
from .options import real_option

__all__ = ["register", "run"]

_OPTIONS = {"max_delay": "--max-delay", "delay_step": "--delay-step", "degree": "--degree",
            "factors": "--factors", "input_max_delay": "--input-max-delay", "max_terms": "--max-terms",
            "holdout": "--holdout", "betas": "--beta", "activations": "--activation", "n_states": "--states", "n_inputs": "--inputs", "state_names": "--states",
            "input_names": "--inputs", "p0": "--p0", "q": "--q", "r": "--r"}


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "select", help="choose the identifier's terms and delays from data (forward orthogonal least squares)",
        description="Select each neuron's high-order terms and delays from a CSV file of states and inputs by "
                    "forward orthogonal least squares (error reduction ratio) on the one-step targets, and "
                    "write an identifier config that identify, tune and export accept.")
    p.add_argument("data", metavar="DATA.csv", help="the measurements (the format of pyrhonn identify)")
    p.add_argument("--states", required=True, metavar="NAMES", help="comma-separated state columns, in order")
    p.add_argument("--inputs", default="", metavar="NAMES", help="comma-separated input columns (default: none)")
    p.add_argument("--out", required=True, metavar="CFG.toml", help="the config file to write")
    p.add_argument("--max-delay", default="0", metavar="D", help="deepest state tap x(k-D) (default 0)")
    p.add_argument("--delay-step", default="1", metavar="S", help="state taps every S samples (default 1)")
    p.add_argument("--degree", default="2", metavar="G", help="products of up to G factors (default 2)")
    p.add_argument("--factors", default="S,u,1", metavar="KINDS",
                   help="factor kinds among S (activation of a state), x (raw state), u (input), 1 (bias); "
                        "default S,u,1")
    p.add_argument("--input-max-delay", default="0", metavar="D",
                   help="input taps u(k-D) (default 0; needs a core that reads delayed inputs)")
    p.add_argument("--activation", default="bipolar,logistic", metavar="NAMES",
                   help="activations searched (default bipolar,logistic)")
    p.add_argument("--beta", default="1", metavar="VALUES", help="slopes of S searched (default 1)")
    p.add_argument("--criterion", default="ebic", choices=[c.value for c in Criterion],
                   help="stopping rule: extended BIC (default), BIC, AIC, or the error on held-out rows")
    p.add_argument("--holdout", default="0.2", metavar="F",
                   help="with --criterion holdout, the last fraction F of the rows is held out (default 0.2)")
    p.add_argument("--max-terms", default="16", metavar="L", help="at most L terms per neuron (default 16)")
    p.add_argument("--p0", metavar="V", help="P0 of every neuron (default: from its fit)")
    p.add_argument("--q", metavar="V", help="Q of every neuron (default: from its fit)")
    p.add_argument("--r", metavar="V", help="R of every neuron (default: its residual variance)")
    p.add_argument("--dtype", choices=DTYPES, default="float64", help="dtype written to the config")
    p.add_argument("--report", metavar="FILE", help="also write the report (text) to FILE")
    p.add_argument("--json", metavar="FILE", help="also write the selection as JSON to FILE")
    p.add_argument("--valid-suffix", default="_valid", metavar="SUFFIX",
                   help="validity columns are named <state><SUFFIX> (default: _valid)")
    p.set_defaults(func=run)


@contextmanager
def _options_named() -> Iterator[None]:
    """Library errors name their fields (``max_delay: ...``, ``state_names[1]: ...``); here
    they name the command-line option instead (``--max-delay: ...``, ``--states: ...``)."""
    try:
        yield
    except ValueError as exc:
        field, sep, rest = str(exc).partition(": ")
        option = _OPTIONS.get(field.split("[", 1)[0]) if sep else None
        if option is None:
            raise
        raise ValueError(f"{option}: {field}: {rest}" if "[" in field else f"{option}: {rest}") from None


def _names(option: str, text: str) -> tuple[str, ...]:
    names = tuple(s.strip() for s in text.split(",")) if text.strip() else ()
    if any(not s for s in names):
        raise ValueError(f"{option}: empty name in {text!r} (comma-separated column names)")
    return names


def _int(option: str, text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise ValueError(f"{option}: expected a whole number, got {text!r}") from None


def _space(args: argparse.Namespace) -> CandidateSpace:
    factors = _names("--factors", args.factors)
    for name in factors:
        if name not in FACTOR_NAMES:
            raise ValueError(f"--factors: {name!r} is not a factor kind; expected some of {', '.join(FACTOR_NAMES)}")
    acts = []
    for name in _names("--activation", args.activation):
        try:
            acts.append(Activation(name))
        except ValueError:
            raise ValueError(f"--activation: {name!r}: expected bipolar or logistic") from None
    betas = tuple(real_option("--beta", b, positive=True) for b in _names("--beta", args.beta))
    if not betas:
        raise ValueError("--beta: expected at least one slope")
    return CandidateSpace(max_delay=_int("--max-delay", args.max_delay), delay_step=_int("--delay-step", args.delay_step),
                          degree=_int("--degree", args.degree), factors=factors,
                          input_max_delay=_int("--input-max-delay", args.input_max_delay),
                          activations=tuple(acts), betas=betas)


def run(args: argparse.Namespace) -> int:
    states, inputs = _names("--states", args.states), _names("--inputs", args.inputs)
    if not states:
        raise ValueError("--states: expected at least one state column")
    try:
        suffix = check_suffix(args.valid_suffix)
    except ValueError as exc:
        raise ValueError(f"--valid-suffix: {exc}") from None
    tuning = {key: None if getattr(args, key) is None else
              real_option(f"--{key}", getattr(args, key), positive=key != "q", nonnegative=key == "q")
              for key in ("p0", "q", "r")}
    with _options_named():
        space = _space(args)
        max_terms = _int("--max-terms", args.max_terms)
        holdout = real_option("--holdout", args.holdout)
        # the names as a config file would hold them (checked there), to read the columns
        probe = IdentifierConfig.uniform(((Factor.one(),),), n_states=len(states), n_inputs=len(inputs))
        names = ConfigFile.from_config(probe, state_names=states, input_names=inputs)
    data = read_data(args.data, names, valid_suffix=suffix, config_source="--states/--inputs")
    with _options_named():
        sel = select(data.X, data.U, data.valid, space=space, criterion=args.criterion, max_terms=max_terms,
                     holdout=holdout, state_names=states, input_names=inputs, first_line=data.lines)
        cf = sel.config_file(states, inputs, dtype=args.dtype, **tuning)
    checked = _validation(cf.config, data, space.window + 1)
    report = sel.report(states) + "\n" + _validation_text(checked, states, space.window + 1)
    atomic.write_text(args.out, dumps(cf))
    if args.report:
        atomic.write_text(args.report, report + "\n")
    if args.json:
        atomic.write_text(args.json, json.dumps({**_as_json(sel, states), "validation": {
            "from_sample": space.window + 1, "weights": "least squares, frozen",
            **{kind: {name: {"rmse": json_value(sc.rmse[j]), "rrse": json_value(sc.rrse[j])}
                      for j, name in enumerate(states)} for kind, sc in checked.items()}}}, indent=2) + "\n")
    print(f"selected from {args.data}: {data.n_samples} samples; wrote {args.out}")
    print(report)
    return 0


def _validation(config: IdentifierConfig, data: Data, start: int) -> dict[str, Scores]:
    """One-step and free-run scores of ``config`` with its weights frozen over the data,
    valid targets from sample ``start`` on (the first whose taps all read measured samples)."""
    ident = Identifier(config)
    ident.learning = False
    X = np.where(data.valid, data.X, 0.0).astype(config.dtype)
    U = data.U.astype(config.dtype)
    start = min(start, data.n_samples - 1)
    sim = simulate(ident, X, U if config.n_inputs else None, data.valid, free_run_from=start)
    assert sim.free_run is not None
    mask = data.valid.copy()
    mask[:start] = False
    return {"one_step": scores(data.X, sim.one_step.astype(np.float64), mask),
            "free_run": scores(data.X, sim.free_run.astype(np.float64), mask)}


def _validation_text(checked: dict[str, Scores], states: tuple[str, ...], start: int) -> str:
    def cell(v: float) -> str:
        return "diverged" if v == np.inf else "-" if np.isnan(v) else f"{v:.4g}"

    width = max(5, *(len(s) for s in states))
    lines = [f"the selected model, least-squares weights frozen, on the same data from sample {start} on:",
             f"  {'state':<{width}}  {'one-step RMSE':>14}  {'RRSE':>9}  {'free-run RMSE':>14}  {'RRSE':>9}"]
    one, free = checked["one_step"], checked["free_run"]
    for j, name in enumerate(states):
        lines.append(f"  {name:<{width}}  {cell(one.rmse[j]):>14}  {cell(one.rrse[j]):>9}  "
                     f"{cell(free.rmse[j]):>14}  {cell(free.rrse[j]):>9}")
    return "\n".join(lines)


def _as_json(sel: Selection, states: tuple[str, ...]) -> dict[str, object]:
    delays = sel.state_delays()
    return {
        "format": "pyrhonn-select",
        "version": 1,
        "criterion": sel.criterion.value,
        "candidates": sel.n_candidates,
        "rows": sel.rows,
        "rows_held_out": sel.rows_held_out,
        "rows_dropped": sel.rows_dropped,
        "seconds": sel.seconds,
        "neurons": [{"state": states[nr.state], "activation": nr.activation.value, "beta": nr.beta,
                     "score": nr.score, "residual_variance": nr.residual_variance,
                     "terms": [{"term": t.text, "err": t.err, "weight": t.weight} for t in nr.terms]}
                    for nr in sel.neurons],
        "state_delays": {states[j]: d for j, d in enumerate(delays)},
    }
