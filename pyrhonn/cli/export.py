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

from ..config import DTYPES
from ..configfile import load_named
from ..datafile import check_suffix, read_data
from ..dbc import export_dbc
from ..export import capacity_path, export_header
from ..identifier import Identifier, IdentifierError
from .options import row_range

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
    p.add_argument("--dbc", metavar="FILE.dbc",
                   help="with --data: also write the identifier's CAN FD protocol (Measurement, Estimate, "
                        "Control, Diagnostics, ...), each signal scaled from the data's range (pyrhonn.dbc)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    out = Path(args.out)
    if not args.out.strip() or out.suffix != ".h":
        raise ValueError(f"--out {args.out!r}: expected a header file name ending in .h")
    name = args.name if args.name is not None else out.stem
    if args.warm_start and args.data is None:
        raise ValueError("--warm-start: needs --data (the recording whose running state is exported)")
    if args.fit_rows is not None and args.data is None:
        raise ValueError("--fit-rows: needs --data (the recording whose rows are learnt)")
    if args.dbc is not None and args.data is None:
        raise ValueError("--dbc: needs --data (each signal is scaled from the data's range)")
    cf = load_named(args.config)
    cfg = cf.config if args.dtype in (None, cf.config.dtype) else cf.config.replace(dtype=args.dtype)
    try:
        ident = Identifier(cfg)
    except ValueError as exc:
        raise ValueError(f"{args.config}: {exc}") from None
    trained, scaled = "", []
    if args.data is not None:
        check_suffix(args.valid_suffix)
        data = read_data(args.data, cf, valid_suffix=args.valid_suffix, config_source=args.config)
        a, b = row_range("--fit-rows", args.fit_rows, data.n_samples)
        X, U = data.in_dtype(cfg.dtype, cf.state_names, cf.input_names, args.data)
        if args.dbc is not None:   # first: a data file it cannot scale stops the export before the headers
            scaled = export_dbc(args.dbc, cf, X, U, data.valid, name=name)
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
            export_header(ident, out, name, warm_start=warm)
        except ValueError as exc:
            raise ValueError(f"--warm-start: {exc}" if args.warm_start else str(exc)) from None
    else:
        export_header(cfg, out, name)
    print(f"exported {args.config} as {name} ({cfg.dtype}){trained}"
          + (", with its running state" if args.warm_start else ""))
    print(f"wrote {out}, {capacity_path(out)}" + (f", {args.dbc}:\n" + "\n".join(scaled) if scaled else ""))
    return 0
