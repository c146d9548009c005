"""``pyrhonn export``: write an identifier config as the C headers firmware builds with.

``pyrhonn export --config CFG --out tuned.h [--name tuned] [--dtype float32|float64]
[--data DATA.csv [--fit-rows A:B] [--valid-suffix _valid] [--warm-start]]``

Writes ``tuned.h`` (``static const rhonn_config tuned``) and ``tuned_capacity.h``
(the smallest capacities that hold it, with ``sizeof(rhonn_t)``): see
:mod:`pyrhonn.export`. ``--name`` defaults to the output file's stem.

- Without ``--data`` the config is exported as it is (its w0 and P0).
- With ``--data`` the identifier first learns online over the recording
  (the format of ``pyrhonn identify``), and the trained weights and
  covariances become the exported w0 and P0: the firmware starts where the
  recording left the identifier, its history empty. ``--fit-rows A:B``
  learns samples A..B-1 only (the rest of the recording stays for
  validation).
- ``--warm-start`` (with ``--data``) exports the running state too
  (``tuned_warm`` for ``rhonn_warm_start``): the firmware continues the run
  bit for bit; the recording's last D + 1 samples must all be measured.

The firmware is float32: ``--dtype float32`` (default: the config's) exports
for it, and an identifier trained with ``--data`` then runs in float32 too.
Each file is replaced whole.
"""
from __future__ import annotations

import argparse
from pathlib import Path

from ..buslog import load_dbc
from ..config import DTYPES
from ..configfile import ConfigFile, load_named
from ..datafile import check_suffix, read_data
from ..export import Signals, capacity_path, export_header
from ..identifier import Identifier, IdentifierError
from .options import name_units, row_range

__all__ = ["register", "run"]


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "export", help="write a config (optionally trained on a recording) as C headers for firmware",
        description="Write an identifier config as the C header firmware builds with (static const rhonn_config) "
                    "and its capacity header; with --data, trained online on a recording first.")
    p.add_argument("--config", required=True, metavar="CFG",
                   help="identifier config: a .toml file (pyrhonn select, tune) or a shipped config name")
    p.add_argument("--out", required=True, metavar="NAME.h", help="the header to write (NAME_capacity.h beside it)")
    p.add_argument("--name", metavar="IDENT", help="C name of the config (default: the output file's stem)")
    p.add_argument("--dtype", choices=DTYPES, help="precision of the firmware (default: the config's dtype)")
    p.add_argument("--data", metavar="DATA.csv", help="learn online over this recording first; export the trained "
                                                       "weights and covariances")
    p.add_argument("--fit-rows", metavar="A:B",
                   help="with --data: learn samples A..B-1 only (0-based; A or B may be left out)")
    p.add_argument("--valid-suffix", default="_valid", metavar="SUFFIX",
                   help="validity columns of --data are named <state><SUFFIX> (default: _valid)")
    p.add_argument("--warm-start", action="store_true",
                   help="with --data: also export the running state, for rhonn_warm_start")
    p.add_argument("--units", type=name_units, default={}, metavar="NAME=UNIT[,NAME=UNIT...]",
                   help="units of the states and inputs, written beside their names in the header (over the "
                        "DBC's units)")
    p.add_argument("--dbc", metavar="FILE",
                   help="the DBC the config's [bus] signals are in: the header names it and each state's and "
                        "input's signal, and takes their units from it")
    p.set_defaults(func=run)


def _signals(args: argparse.Namespace, cf: ConfigFile) -> Signals:
    """The names, units and bus signals the header lists (--units, --dbc with the config's [bus] table)."""
    names = list(cf.state_names) + list(cf.input_names)
    units: dict[str, str] = {}
    bus: dict[str, str] = {}
    dbc = None
    if args.dbc is not None:
        db = load_dbc(args.dbc)
        if cf.bus is None or not cf.bus.signals:
            raise ValueError(f"--dbc {args.dbc}: {args.config} has no [bus.signals] table saying which signal each "
                             "state and input is")
        for key, ref in cf.bus.signals.items():
            try:
                sig = db.get_message_by_name(ref.message).get_signal_by_name(ref.signal)
            except KeyError:
                raise ValueError(f"{args.config}: bus.signals.{key}: {ref} is not in --dbc {args.dbc}") from None
            bus[key] = str(ref)
            if sig.unit:
                units[key] = str(sig.unit)
        dbc = Path(args.dbc).name
    for key, unit in args.units.items():
        if key not in names:
            raise ValueError(f"--units: {key!r} is not a state or input of {args.config} ({', '.join(names)})")
        units[key] = unit
    return Signals(states=list(cf.state_names), inputs=list(cf.input_names), units=units, bus=bus, dbc=dbc)


def run(args: argparse.Namespace) -> int:
    out = Path(args.out)
    if not args.out.strip() or out.suffix != ".h":
        raise ValueError(f"--out {args.out!r}: expected a header file name ending in .h")
    name = args.name if args.name is not None else out.stem
    if args.warm_start and args.data is None:
        raise ValueError("--warm-start: needs --data (the recording whose running state is exported)")
    if args.fit_rows is not None and args.data is None:
        raise ValueError("--fit-rows: needs --data (the recording whose rows are learnt)")
    cf = load_named(args.config)
    signals = _signals(args, cf)
    cfg = cf.config if args.dtype in (None, cf.config.dtype) else cf.config.replace(dtype=args.dtype)
    try:
        ident = Identifier(cfg)
    except ValueError as exc:
        raise ValueError(f"{args.config}: {exc}") from None
    trained = ""
    if args.data is not None:
        check_suffix(args.valid_suffix)
        data = read_data(args.data, cf, valid_suffix=args.valid_suffix, config_source=args.config)
        a, b = row_range("--fit-rows", args.fit_rows, data.n_samples)
        X, U = data.in_dtype(cfg.dtype, cf.state_names, cf.input_names, args.data)
        X, U, valid = X[a:b], U[a:b], data.valid[a:b]
        try:
            ident.run(X, U if cfg.n_inputs else None, valid)
        except IdentifierError as exc:
            raise ValueError(f"{args.data}: the identifier stopped: {exc}") from None
        rows = f"samples {a}..{b - 1} of {data.n_samples}" if (a, b) != (0, data.n_samples) else \
            f"{data.n_samples} samples"
        trained = f", trained online on {args.data} ({rows})"
        warm = (X, U if cfg.n_inputs else None, valid) if args.warm_start else None
        try:
            export_header(ident, out, name, warm_start=warm, signals=signals)
        except ValueError as exc:
            raise ValueError(f"--warm-start: {exc}" if args.warm_start else str(exc)) from None
    else:
        export_header(cfg, out, name, signals=signals)
    print(f"exported {args.config} as {name} ({cfg.dtype}){trained}"
          + (", with its running state" if args.warm_start else ""))
    print(f"wrote {out}, {capacity_path(out)}")
    return 0
