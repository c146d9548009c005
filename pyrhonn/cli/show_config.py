"""``pyrhonn show-config``: print a shipped identifier config or a config file.

``pyrhonn show-config example1`` prints the shipped ``pyrhonn/configs/example1.toml``;
``pyrhonn show-config my/cfg.toml`` prints a file (an argument ending in
``.toml`` or containing ``/`` is a path, anything else a shipped name). The
output is the TOML text as stored, then a summary: the states and inputs,
and per neuron its terms as products, its tuning and why it uses them.
``--list`` lists the shipped configs.
"""
from __future__ import annotations

import argparse
import textwrap

import numpy as np

from ..config import Factor, FactorKind, NeuronConfig
from ..configfile import ConfigFile, format_factor, load_shipped, loads, read_named, shipped_names


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "show-config", help="print a shipped identifier config or a config file, with a summary",
        description="Print an identifier config (a shipped one by name, or a .toml file by path) and a "
                    "readable summary: per neuron its terms, tuning and why it uses them.")
    p.add_argument("name", nargs="?", metavar="NAME_OR_PATH",
                   help="a shipped config name (see --list) or a path ending in .toml or containing '/'")
    p.add_argument("--list", action="store_true", help="list the shipped configs and exit")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if args.list:
        if args.name is not None:
            raise ValueError("give either NAME_OR_PATH or --list, not both")
        for name in shipped_names():
            print(f"{name:16} {_headline(load_shipped(name).description)}".rstrip())
        return 0
    if args.name is None:
        raise ValueError("give a config name or path (NAME_OR_PATH), or --list to list the shipped configs")
    source, text = read_named(args.name)
    cf = loads(text, source=source)
    print(text.rstrip("\n"))
    print()
    print(summary(cf, source))
    return 0


def _headline(description: str, width: int = 90) -> str:
    """The start of a description on one line, cut at a word to ``width`` characters."""
    text = " ".join(description.split())
    return text if len(text) <= width else textwrap.shorten(text, width=width, placeholder=" ...")


def _named(factor: Factor, cf: ConfigFile) -> str:
    """A factor with the state/input names instead of xJ/uJ."""
    if factor.kind is FactorKind.ONE:
        return format_factor(factor)
    name = (cf.input_names if factor.kind is FactorKind.U else cf.state_names)[factor.index]
    text = f"{name}(k-{factor.delay})" if factor.delay else name
    if factor.kind is FactorKind.S:
        text = f"S({text})"
    return text if factor.power == 1 else f"{text}^{factor.power}"


def _matrix_text(name: str, value: float | np.ndarray, L: int) -> str:
    if isinstance(value, np.ndarray):
        if value.ndim == 1:
            return f"{name} = diag(" + ", ".join(f"{v:g}" for v in value) + ")"
        return f"{name} = full {L}x{L} matrix (diagonal " + ", ".join(f"{v:g}" for v in np.diag(value)) + ")"
    return f"{name} = {value:g} I"


def _tuning(nr: NeuronConfig) -> str:
    parts = [f"{nr.activation.value} S, beta = {nr.beta:g}", _matrix_text("P0", nr.p0, nr.n_terms),
             _matrix_text("Q", nr.q, nr.n_terms), f"R = {nr.r:g}", f"eta = {nr.eta:g}"]
    parts.append("w0 = 0" if nr.w0 is None else "w0 = (" + ", ".join(f"{v:g}" for v in nr.w0) + ")")
    return ", ".join(parts)


def summary(cf: ConfigFile, source: str) -> str:
    """The readable summary printed after the TOML text."""
    cfg = cf.config
    n, m = cfg.n_states, cfg.n_inputs
    wrap = textwrap.TextWrapper(width=96, initial_indent="  ", subsequent_indent="  ")
    out = [f"Summary of {source}", "=" * (11 + len(source))]
    out.append(f"{n} state{'s' if n != 1 else ''}: " + ", ".join(
        f"x{j + 1} = {name}" for j, name in enumerate(cf.state_names)))
    out.append(f"{m} input{'s' if m != 1 else ''}: " + (", ".join(
        f"u{j + 1} = {name}" for j, name in enumerate(cf.input_names)) or "none"))
    x0 = "0" if cfg.x0 is None else "(" + ", ".join(f"{v:g}" for v in cfg.x0) + ")"
    out.append(f"dtype {cfg.dtype}, x0 = {x0}, deepest delay {cfg.max_delay} sample"
               f"{'s' if cfg.max_delay != 1 else ''}")
    if cf.description.strip():
        out.append("")
        for para in cf.description.strip().split("\n\n"):
            out.extend(wrap.wrap(" ".join(para.split())))
    for i, nr in enumerate(cfg.neurons):
        out.append("")
        named = "" if cf.state_names[i] == f"x{i + 1}" else f" ({cf.state_names[i]})"
        out.append(f"neuron {i + 1}: x{i + 1}(k+1){named} = w{i + 1}' z{i + 1}, "
                   f"{nr.n_terms} term{'s' if nr.n_terms != 1 else ''}")
        out.append(f"  tuning: {_tuning(nr)}")
        texts = [" * ".join(format_factor(f) for f in term) for term in nr.terms]
        width = max(len(text) for text in texts)
        for t, (term, text) in enumerate(zip(nr.terms, texts)):
            line = f"  z{i + 1}[{t + 1}] = {text}"
            with_names = " * ".join(_named(f, cf) for f in term)
            if with_names != text:
                line = f"{line}{' ' * (width - len(text))}   = {with_names}"
            out.append(line)
        if cf.why[i].strip():
            out.extend(textwrap.wrap(" ".join(cf.why[i].split()), width=96, initial_indent="  why: ",
                                     subsequent_indent="       "))
    return "\n".join(out)
