"""``pyrhonn export``: write an identifier config as the C headers firmware builds with,
or as a Functional Mock-up Unit for simulation tools.

``pyrhonn export --config CFG --out tuned.h [--name tuned] [--dtype float32|float64]
[--data DATA.csv [--fit-rows A:B] [--valid-suffix _valid] [--warm-start]]``

``pyrhonn export --config CFG --fmu MODEL.fmu [--fmi-version 3|2] [--period T]
[--units NAME=UNIT,...] [--dbc FILE] [--mode observer|simulator] [--name MODEL] [--dtype ...] [--data ...
[--warm-start]]`` writes an FMI co-simulation FMU instead (:mod:`pyrhonn.fmu`):
one communication step of the sample period T (default the config's
``bus.sample_period``) is one identifier step; ``--warm-start`` starts it
from the running state the recording left.

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
from ..dbc import export_dbc
from ..export import Signals, capacity_path, export_header
from ..fmu import MODES, FmuSettings, check_for, export_fmu
from ..identifier import Identifier, IdentifierError
from .options import options_named, real_option, row_range, units_option

__all__ = ["register", "run"]


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "export", help="write a config (optionally trained on a recording) as C headers for firmware, or as an FMU",
        description="Write an identifier config as the C header firmware builds with (static const rhonn_config) "
                    "and its capacity header, or (--fmu) as an FMI co-simulation FMU for simulation tools; with "
                    "--data, trained online on a recording first.")
    p.add_argument("--config", required=True, metavar="CFG",
                   help="identifier config: a .toml file (pyrhonn select, tune) or a shipped config name")
    out = p.add_mutually_exclusive_group(required=True)
    out.add_argument("--out", metavar="NAME.h", help="the header to write (NAME_capacity.h beside it)")
    out.add_argument("--fmu", metavar="MODEL.fmu", help="write a co-simulation FMU instead (see --fmi-version)")
    p.add_argument("--name", metavar="IDENT", help="C name of the config, or the FMU's model identifier (default: "
                                                   "the output file's stem)")
    p.add_argument("--dtype", choices=DTYPES, help="precision of the firmware or FMU (default: the config's dtype)")
    p.add_argument("--data", metavar="DATA.csv", help="learn online over this recording first; export the trained "
                                                       "weights and covariances")
    p.add_argument("--fit-rows", metavar="A:B",
                   help="with --data: learn samples A..B-1 only (0-based; A or B may be left out)")
    p.add_argument("--valid-suffix", default="_valid", metavar="SUFFIX",
                   help="validity columns of --data are named <state><SUFFIX> (default: _valid)")
    p.add_argument("--warm-start", action="store_true",
                   help="with --data: also export the running state, for rhonn_warm_start")
    fmu = p.add_argument_group("FMU (--fmu)")
    fmu.add_argument("--fmi-version", choices=("3", "2"), default="3", help="FMI 3.0 (default) or 2.0 co-simulation")
    fmu.add_argument("--period", metavar="T", help="sample period in s: the FMU's only communication step size "
                                                   "(default: the config's bus.sample_period)")
    fmu.add_argument("--mode", choices=MODES, default="observer",
                     help="start value of the FMU's mode parameter (default: observer)")
    p.add_argument("--units", type=units_option, default={}, metavar="NAME=UNIT[,NAME=UNIT...]",
                   help="units of the states and inputs (over the DBC's): written beside their names in the "
                        "header, and the units of the FMU's variables")
    p.add_argument("--bus-dbc", metavar="FILE",
                   help="the DBC the config's [bus] signals are in: the header names it and each state's and "
                        "input's signal, and takes their units from it (so does the FMU)")
    p.add_argument("--dbc", metavar="FILE.dbc",
                   help="with --data: also write the identifier's CAN FD protocol (Measurement, Estimate, "
                        "Control, Diagnostics, ...), each signal scaled from the data's range (pyrhonn.dbc); "
                        "the header names it")
    p.set_defaults(func=run)


def _fmu_only(args: argparse.Namespace) -> None:
    """The FMU options given without --fmu: a ValueError naming the option."""
    if args.fmu is not None:
        return
    given = [opt for opt, value, default in (("--fmi-version", args.fmi_version, "3"), ("--period", args.period, None),
                                             ("--mode", args.mode, "observer"))
             if value != default]
    if given:
        raise ValueError(f"{given[0]}: only with --fmu")


def _signals(args: argparse.Namespace, cf: ConfigFile) -> Signals:
    """The names, units and bus signals the header lists (--units, --bus-dbc with the config's [bus]
    table; the DBC --dbc writes)."""
    names = list(cf.state_names) + list(cf.input_names)
    units: dict[str, str] = {}
    bus: dict[str, str] = {}
    dbc = None
    if args.bus_dbc is not None:
        db = load_dbc(args.bus_dbc, "--bus-dbc")
        if cf.bus is None or not cf.bus.signals:
            raise ValueError(f"--bus-dbc {args.bus_dbc}: {args.config} has no [bus.signals] table saying which "
                             "signal each state and input is")
        for key, ref in cf.bus.signals.items():
            try:
                sig = db.get_message_by_name(ref.message).get_signal_by_name(ref.signal)
            except KeyError:
                raise ValueError(f"{args.config}: bus.signals.{key}: {ref} is not in --bus-dbc "
                                 f"{args.bus_dbc}") from None
            bus[key] = str(ref)
            if sig.unit:
                units[key] = str(sig.unit)
        dbc = Path(args.bus_dbc).name
    if args.dbc is not None:  # the DBC written beside the header is the one it goes with, its own signals
        dbc, bus = Path(args.dbc).name, {}
    for key, unit in args.units.items():
        if key not in names:
            raise ValueError(f"--units: {key!r} is not a state or input of {args.config} ({', '.join(names)})")
        units[key] = unit
    return Signals(states=list(cf.state_names), inputs=list(cf.input_names), units=units, bus=bus, dbc=dbc)


def run(args: argparse.Namespace) -> int:
    _fmu_only(args)
    out = Path(args.out if args.fmu is None else args.fmu)
    if args.fmu is not None and (not args.fmu.strip() or out.suffix != ".fmu"):
        raise ValueError(f"--fmu {args.fmu!r}: expected a file name ending in .fmu")
    if args.fmu is None and (not args.out.strip() or out.suffix != ".h"):
        raise ValueError(f"--out {args.out!r}: expected a header file name ending in .h")
    name = args.name if args.name is not None else out.stem
    if args.warm_start and args.data is None:
        raise ValueError("--warm-start: needs --data (the recording whose running state is exported)")
    if args.fit_rows is not None and args.data is None:
        raise ValueError("--fit-rows: needs --data (the recording whose rows are learnt)")
    if args.dbc is not None and args.data is None:
        raise ValueError("--dbc: needs --data (each signal is scaled from the data's range)")
    cf = load_named(args.config)
    signals = _signals(args, cf)
    cfg = cf.config if args.dtype in (None, cf.config.dtype) else cf.config.replace(dtype=args.dtype)
    settings = _fmu_settings(args, cf, name, dict(signals.units)) if args.fmu is not None else None
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
        if settings is not None:
            export_fmu(cf, out, settings, source=ident if args.data is not None else cfg, warm_start=warm)
        else:
            export_header(ident if args.data is not None else cfg, out, name, warm_start=warm, signals=signals)
    except ValueError as exc:
        raise ValueError(f"--warm-start: {exc}" if args.warm_start and str(exc).startswith("warm_start") else
                         str(exc)) from None
    with_state = ", with its running state" if args.warm_start else ""
    if settings is not None:
        print(f"exported {args.config} as FMI {settings.fmi_version}.0 co-simulation FMU {name} ({cfg.dtype}, "
              f"period {settings.period!r} s, mode {settings.mode}){trained}{with_state}")
        print(f"wrote {out}" + (f", {args.dbc}:\n" + "\n".join(scaled) if scaled else ""))
    else:
        print(f"exported {args.config} as {name} ({cfg.dtype}){trained}{with_state}")
        print(f"wrote {out}, {capacity_path(out)}" + (f", {args.dbc}:\n" + "\n".join(scaled) if scaled else ""))
    return 0


def _fmu_settings(args: argparse.Namespace, cf: ConfigFile, name: str, units: dict[str, str]) -> FmuSettings:
    """The FMU's settings from the options, checked before anything is trained or written."""
    if args.period is not None:
        period = real_option("--period", args.period, positive=True)
    elif cf.bus is not None and cf.bus.sample_period is not None:
        period = float(cf.bus.sample_period)
    else:
        raise ValueError(f"--period: needed: {args.config} has no bus.sample_period (give the identifier's sample "
                         "period in s)")
    try:
        settings = FmuSettings(period=period, model_identifier=name, fmi_version=int(args.fmi_version),
                               units=units, mode=args.mode)
    except ValueError as exc:
        field, sep, rest = str(exc).partition(": ")
        if field == "name":
            raise ValueError(f"--name {name!r}: the FMU's model identifier must be a C identifier ({rest}); "
                             f"give --name") from None
        raise
    with options_named(units="--units"):
        check_for(cf, settings)
    return settings
