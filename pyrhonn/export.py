"""Export an identifier as C headers that firmware builds with.

``export_header(ident, "tuned.h", name="tuned")`` writes two files:

``tuned.h``
    ``static const rhonn_config tuned`` (w0 = the trained weights, P0 = the
    trained covariances), with ``#error`` checks: capacities too small for
    it, the other precision, a ``rhonn.h`` whose configuration layout is not
    the one written. Start firmware with ``rhonn_init(&net, &tuned, NULL)``.
``tuned_capacity.h``
    the smallest capacities that hold the identifier (``RHONN_MAX_STATES``,
    ... ``RHONN_MAX_ENTRIES``), usable as ``RHONN_USER_CAPACITY``, and
    ``sizeof(rhonn_t)`` with them, measured by compiling ``rhonn.h`` with
    them when the export runs (when a C compiler and the core's headers are
    at hand; the header says so when not).

The headers compile as C99 and as C++11 or later, without warnings under
``-Wall -Wextra -pedantic``: the initialisers are positional (C++ has no
array designators), every field written. Values are exact: C and C++17 read
hexadecimal floating literals, the exact bits; C++11 and C++14, which have
none, read decimal literals with the shortest digits that convert back to
the same bits (the compiler's conversion is correctly rounded in GCC, Clang
and MSVC; ``tests/test_export.py`` checks the round trip bit for bit).

Warm start: ``export_header(ident, "tuned.h", name="tuned",
warm_start=(X, U, valid))``, with the samples the identifier last stepped
on, writes instead ``tuned`` as the identifier's own configuration (its w0
and P0, what ``rhonn_reset`` and ``reset_after`` return to) and
``static const rhonn_warm_state tuned_warm``: the running state. Firmware
that starts with ``rhonn_warm_start(&net, &tuned, &tuned_warm, NULL)``
(``csrc/include/rhonn_warm.h``) continues the run bit for bit: the same
predictions, weights and covariances as the Python identifier stepping on
(the health counters and the step count start from zero; see rhonn_warm.h).
The last D + 1 of those samples (D the deepest delay) must be measured (no
dropout), and the identifier must have stepped since it was built, reset or
restarted.

Names: ``export_header(..., signals=Signals(states, inputs, units, bus, dbc))``
also writes, in the header, which state and input each index is: a comment
table (index, name, unit, the DBC signal it comes from), ``NAME_N_STATES`` /
``NAME_N_INPUTS``, one index macro per name (``NAME_STATE_Q_M 0``) and
initialiser macros of the names and units in order
(``static const char *const names[] = NAME_STATE_NAMES;``), and the DBC
file the bus signals are in, when given.
"""
from __future__ import annotations

import dataclasses
import os
import re
import shutil
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Mapping, Sequence

import numpy as np

from . import atomic
from .config import FactorKind, IdentifierConfig
from .identifier import Identifier
from .version import __version__

__all__ = ["Signals", "export_header", "header_config", "header_text", "capacity_text", "capacity_path",
           "min_capacities",
           "measure_rhonn_t_size", "LAYOUT_VERSION"]

#: The rhonn.h API version (RHONN_VERSION_MAJOR, _MINOR) whose rhonn_config and
#: rhonn_warm_state field order the positional initialisers follow.
LAYOUT_VERSION = (1, 4)

_IDENT = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")
#: C99's keywords (6.4.1): a name the compiler would refuse
_C_KEYWORDS = frozenset("""auto break case char const continue default do double else enum extern float for goto
    if inline int long register restrict return short signed sizeof static struct switch typedef union unsigned
    void volatile while _Bool _Complex _Imaginary""".split())
#: C++'s keywords beyond C99's: the header is C++ too
_CXX_KEYWORDS = frozenset("""alignas alignof and and_eq asm bitand bitor bool catch char16_t char32_t char8_t class
    compl concept consteval constexpr constinit const_cast co_await co_return co_yield decltype delete dynamic_cast
    explicit export false friend mutable namespace new noexcept not not_eq nullptr operator or or_eq private
    protected public reinterpret_cast requires static_assert static_cast template this thread_local throw true try
    typeid typename using virtual wchar_t xor xor_eq""".split())

#: C and C++17 read hexadecimal floating literals; C++11 and C++14 do not.
_HEX_FLOATS = "#if !defined(__cplusplus) || __cplusplus >= 201703L"

LiteralFormat = Callable[[float], str]
WarmSamples = tuple[np.ndarray, np.ndarray | None, np.ndarray | None]


def _hex_literal(dtype: str) -> LiteralFormat:
    """Exact: the C99 / C++17 hexadecimal form of the value's bits."""
    if dtype == "float32":
        return lambda v: f"{float(np.float32(v)).hex()}f"
    return lambda v: float(v).hex()


def _decimal_literal(dtype: str) -> LiteralFormat:
    """The shortest decimal that converts back to the same float32 / float64
    (a correctly rounded conversion gives the exact bits)."""
    if dtype == "float32":
        return lambda v: np.format_float_scientific(np.float32(v), unique=True, trim="-") + "f"
    return lambda v: repr(float(v))


def _check_name(name: object) -> str:
    if not isinstance(name, str) or not _IDENT.match(name):
        raise ValueError(f"name: expected a C identifier, got {name!r}")
    if name in _C_KEYWORDS or name in _CXX_KEYWORDS:
        raise ValueError(f"name: {name!r} is a C keyword" if name in _C_KEYWORDS else
                         f"name: {name!r} is a C++ keyword (the header compiles as C++ too)")
    if name.startswith(("rhonn_", "RHONN_")) and name != "rhonn_exported":
        # the core's namespace: rhonn_init, rhonn_config, RHONN_OK ... would clash at compile or link time
        raise ValueError(f"name: {name!r} is in the core's rhonn_ namespace; choose another prefix")
    if name.startswith("__") or (name.startswith("_") and name[1:2].isupper()):
        raise ValueError(f"name: {name!r} is reserved to the C implementation (7.1.3)")
    return name


@dataclass(frozen=True)
class Signals:
    """What each state and input of an exported identifier is: ``states`` and ``inputs`` the names in
    order, ``units`` a unit per name (any may be missing), ``bus`` a "Message.Signal" per name (any may
    be missing) and ``dbc`` the DBC file's name those signals are in."""

    states: Sequence[str]
    inputs: Sequence[str]
    units: Mapping[str, str] = dataclasses.field(default_factory=dict)
    bus: Mapping[str, str] = dataclasses.field(default_factory=dict)
    dbc: str | None = None

    def check(self, cfg: IdentifierConfig) -> None:
        if len(self.states) != cfg.n_states or len(self.inputs) != cfg.n_inputs:
            raise ValueError(f"signals: {len(self.states)} state and {len(self.inputs)} input names for an "
                             f"identifier of {cfg.n_states} states and {cfg.n_inputs} inputs")
        names = list(self.states) + list(self.inputs)
        for name in names:
            if not isinstance(name, str) or not name:
                raise ValueError(f"signals: expected non-empty names, got {name!r}")
        for what, table in (("units", self.units), ("bus", self.bus)):
            for key, value in table.items():
                if key not in names:
                    raise ValueError(f"signals.{what}: {key!r} is not a state or input ({', '.join(names)})")
                if not isinstance(value, str):
                    raise ValueError(f"signals.{what}.{key}: expected a string, got {type(value).__name__}")
        macros = [_macro_part(n) for n in names]
        for kind, part in (("STATE", macros[:len(self.states)]), ("INPUT", macros[len(self.states):])):
            twice = sorted({m for m in part if part.count(m) > 1})
            if twice:
                raise ValueError(f"signals: names that give the same macro NAME_{kind}_{twice[0]}: "
                                 f"{', '.join(n for n, m in zip(names, macros) if m == twice[0])}")


def _macro_part(name: str) -> str:
    """A name as part of a C macro name: upper case, other characters as underscores."""
    part = re.sub(r"[^A-Za-z0-9]", "_", name).upper()
    return part if not part[:1].isdigit() else f"_{part}"


def _c_string(text: str) -> str:
    """A C string literal of ``text``: printable ASCII as is, everything else as octal escapes of its UTF-8."""
    out = []
    for byte in text.encode("utf-8"):
        c = chr(byte)
        out.append(f"\\{c}" if c in "\\\"" else c if 32 <= byte < 127 and c != "?" else f"\\{byte:03o}")
    return '"' + "".join(out) + '"'


def _comment(text: str) -> str:
    """``text`` safe inside a C comment (no comment end, ASCII only)."""
    return text.replace("*/", "* /").encode("ascii", "backslashreplace").decode("ascii")


def _names_block(sig: Signals, name: str) -> list[str]:
    """The comment table and macros naming each state and input (see the module docs)."""
    prefix = name.upper()
    lines = [f"/* What {name}'s vectors hold, in order: x(k) the states, u(k) the inputs."]
    if sig.dbc:
        lines.append(f" * Bus signals as in the DBC {_comment(sig.dbc)}.")
    for kind, names in (("state", sig.states), ("input", sig.inputs)):
        lines.append(f" * {kind}s:" + ("" if names else " none"))
        for i, n in enumerate(names):
            unit = f" [{sig.units[n]}]" if sig.units.get(n) else ""
            bus = f"  {sig.bus[n]}" if n in sig.bus else ""
            lines.append(_comment(f" *   {i}: {n}{unit}{bus}"))
    lines.append(" */")
    for kind, names in (("STATE", sig.states), ("INPUT", sig.inputs)):
        lines.append(f"#define {prefix}_N_{kind}S {len(names)}")
        for i, n in enumerate(names):
            unit = f" [{sig.units[n]}]" if sig.units.get(n) else ""
            lines.append(f"#define {prefix}_{kind}_{_macro_part(n)} {i} /* {_comment(n + unit)} */")
        if names:
            lines.append(f"#define {prefix}_{kind}_NAMES {{ {', '.join(_c_string(n) for n in names)} }}")
            lines.append(f"#define {prefix}_{kind}_UNITS {{ "
                         f"{', '.join(_c_string(sig.units.get(n, '')) for n in names)} }}")
    return lines + [""]


def _config_of(source: object) -> IdentifierConfig:
    if isinstance(source, Identifier):
        return source.as_config()
    if isinstance(source, IdentifierConfig):
        return source
    raise ValueError(f"source: expected an Identifier or IdentifierConfig, got {type(source).__name__}")


# -- capacities ------------------------------------------------------------------------------------


def _distinct_entries(cfg: IdentifierConfig) -> int:
    """Distinct factor values the core's rhonn_init compiles the terms into
    (RHONN_MAX_ENTRIES): kind, index, delay and power, and for S factors the
    neuron's activation and beta (at the working precision)."""
    def beta(b: float) -> float:
        return float(np.float32(b)) if cfg.dtype == "float32" else float(b)

    seen = set()
    for nr in cfg.neurons:
        group = (nr.activation.code, beta(nr.beta))
        for term in nr.terms:
            for f in term:
                seen.add((int(f.kind), f.index, f.delay, f.power, group if f.kind is FactorKind.S else None))
    return len(seen)


def min_capacities(source: Identifier | IdentifierConfig) -> dict[str, int]:
    """The smallest RHONN_MAX_* capacities that hold the identifier, in the
    order rhonn_capacity.h declares them."""
    cfg = _config_of(source)
    factors = [f for nr in cfg.neurons for t in nr.terms for f in t]
    return {
        "RHONN_MAX_STATES": cfg.n_states,
        "RHONN_MAX_INPUTS": max(cfg.n_inputs, 1),
        "RHONN_MAX_TERMS": max(nr.n_terms for nr in cfg.neurons),
        "RHONN_MAX_FACTORS": max(len(t) for nr in cfg.neurons for t in nr.terms),
        "RHONN_MAX_DELAY": cfg.max_delay,
        "RHONN_MAX_POWER": max(f.power for f in factors),
        "RHONN_MAX_ENTRIES": _distinct_entries(cfg),
    }


def capacity_path(header: str | Path) -> Path:
    """Where :func:`export_header` writes the capacity header of ``header``:
    beside it, ``<stem>_capacity.h``."""
    header = Path(header)
    return header.with_name(f"{header.stem}_capacity.h")


def capacity_text(source: Identifier | IdentifierConfig, name: str, rhonn_t_size: int | str | None = None,
                  file_name: str | None = None) -> str:
    """The capacity header: the smallest capacities for ``source`` as
    ``#define``s, and ``sizeof(rhonn_t)`` with them (``rhonn_t_size``: the
    measured size, or why it was not measured). ``file_name``: the header's
    own name, for the usage line (default ``<name>_capacity.h``)."""
    name = _check_name(name)
    cfg = _config_of(source)
    caps = min_capacities(cfg)
    guard = f"{name.upper()}_RHONN_CAPACITY_H"
    if isinstance(rhonn_t_size, int):
        build = f"{cfg.dtype}, RHONN_SINGLE" if cfg.dtype == "float32" else cfg.dtype
        size = [f"/* sizeof(rhonn_t) = {rhonn_t_size} bytes with these capacities ({build}),",
                " * measured when exported by compiling rhonn.h with them (host C compiler). Targets that",
                " * align double to 8 bytes (x86-64, AArch64, Arm EABI: Cortex-M) lay rhonn_t out alike. */"]
    else:
        size = [f"/* sizeof(rhonn_t) with these capacities: not measured at export ({rhonn_t_size or 'not asked'});",
                " * print it from a build that uses this header. */"]
    width = max(len(k) for k in caps)
    return "\n".join([
        f"/* Generated by pyrhonn {__version__}: the smallest capacities that hold identifier {name!r}. */",
        "/* Do not edit: export again from Python (pyrhonn.export.export_header). Use it as",
        f' * -DRHONN_USER_CAPACITY=\'"{file_name or name + "_capacity.h"}"\' in every',
        " * translation unit that includes rhonn.h, and the core's own. */",
        *size,
        f"#ifndef {guard}",
        f"#define {guard}",
        "",
        *(f"#define {k:<{width}} {v}" for k, v in caps.items()),
        "",
        f"#endif /* {guard} */",
        "",
    ])


def _default_include_dir() -> Path | None:
    """The core's headers: the source tree's csrc/include, else the copy an
    installed pyrhonn ships (pyrhonn/core_include, see setup.py)."""
    for here in (Path(__file__).resolve().parent.parent / "csrc" / "include",
                 Path(__file__).resolve().parent / "core_include"):
        if (here / "rhonn.h").is_file():
            return here
    return None


def measure_rhonn_t_size(capacity_header: str, dtype: str, *, include_dir: str | Path | None = None,
                         compiler: str | None = None) -> int:
    """``sizeof(rhonn_t)`` with ``capacity_header`` (its text) as
    RHONN_USER_CAPACITY, from a program compiled with ``compiler`` (default:
    ``$CC``, else ``cc``) against the core's headers in ``include_dir``
    (default: the source tree's ``csrc/include``) and run. Raises
    ``ValueError`` naming what is missing or what failed."""
    if dtype not in ("float32", "float64"):
        raise ValueError(f"dtype: expected 'float32' or 'float64', got {dtype!r}")
    inc = Path(include_dir) if include_dir is not None else _default_include_dir()
    if inc is None or not (inc / "rhonn.h").is_file():
        raise ValueError("include_dir: the core's rhonn.h is not there (pass the folder that holds rhonn.h)")
    cc = compiler or os.environ.get("CC") or "cc"
    if shutil.which(cc.split()[0]) is None:
        raise ValueError(f"compiler: {cc!r} not found")
    with tempfile.TemporaryDirectory(prefix="pyrhonn-size-") as tmp:
        t = Path(tmp)
        (t / "capacity.h").write_text(capacity_header)
        (t / "probe.c").write_text(
            '#include <stdio.h>\n#include "rhonn.h"\n'
            'int main(void) { printf("%lu\\n", (unsigned long)sizeof(rhonn_t)); return 0; }\n')
        flags = ["-DRHONN_SINGLE"] if dtype == "float32" else []
        build = subprocess.run([*cc.split(), "-std=c99", *flags, '-DRHONN_USER_CAPACITY="capacity.h"',
                                f"-I{t}", f"-I{inc}", str(t / "probe.c"), "-o", str(t / "probe")],
                               capture_output=True, text=True)
        if build.returncode != 0:
            raise ValueError(f"compiler: {cc} failed on rhonn.h: {build.stderr.strip()[:400]}")
        run = subprocess.run([str(t / "probe")], capture_output=True, text=True)
        if run.returncode != 0 or not run.stdout.strip().isdigit():
            raise ValueError(f"compiler: the size probe built by {cc} did not run")
        return int(run.stdout)


# -- the configuration header ----------------------------------------------------------------------


def _reals(values: np.ndarray, lit: LiteralFormat) -> str:
    return "{" + ", ".join(lit(float(v)) for v in np.ravel(values)) + "}"


_KIND = {FactorKind.S: "RHONN_FACTOR_S", FactorKind.X: "RHONN_FACTOR_X", FactorKind.U: "RHONN_FACTOR_U",
         FactorKind.ONE: "RHONN_FACTOR_ONE"}


def _config_initializer(cfg: IdentifierConfig, name: str, lit: LiteralFormat) -> list[str]:
    """``static const rhonn_config NAME = {...};``: every field, in rhonn.h's order."""
    lines = [f"static const rhonn_config {name} = {{",
             f"    {cfg.n_states}, /* n_states */",
             f"    {cfg.n_inputs}, /* n_inputs */",
             f"    {_reals(cfg.x0_vector(), lit)}, /* x0 */",
             "    { /* neurons */"]
    for i, nr in enumerate(cfg.neurons):
        P = nr.p0_matrix()
        lines += [
            f"        {{ /* [{i}]: {' + '.join(nr.describe())} */",
            f"            {nr.n_terms}, /* n_terms */",
            f"            {'RHONN_LOGISTIC' if nr.activation.code == 0 else 'RHONN_BIPOLAR'}, /* activation */",
            f"            {lit(nr.beta)}, /* beta */",
            f"            {lit(nr.eta)}, /* eta */",
            f"            {lit(nr.r)}, /* r */",
            f"            {_reals(nr.q_diagonal(), lit)}, /* q */",
            f"            {_reals(nr.w0_vector(), lit)}, /* w0 */",
            f"            {_reals(P[np.triu_indices(nr.n_terms)], lit)}, /* p0 */",
            "            { /* terms: n_factors, {kind, index, delay, power} */",
        ]
        for term in nr.terms:
            factors = ", ".join(f"{{{_KIND[f.kind]}, {f.index}, {f.delay}, {f.power}}}" for f in term)
            lines.append(f"                {{{len(term)}, {{{factors}}}}},")
        lines += [
            "            },",
            f"            {'RHONN_COV_UD' if nr.covariance.code else 'RHONN_COV_FULL'}, /* covariance */",
            f"            {nr.reset_after}, /* reset_after */",
            f"            {lit(nr.forgetting)}, /* forgetting */",
            f"            {lit(0.0 if nr.p_trace_max is None else nr.p_trace_max)}, /* p_trace_max (0: off) */",
            f"            {lit(nr.gate)}, /* gate (0: off) */",
            f"            {int(nr.skip_refused)}, /* skip_refused */",
            f"            {int(nr.wait_for_history)}, /* wait_for_history */",
            "        },",
        ]
    return lines + ["    },", "};"]


@dataclass(frozen=True)
class _WarmState:
    weights: list[np.ndarray]
    factors: list[np.ndarray]
    learning: bool
    X: np.ndarray   # (D + 1, n), oldest first
    U: np.ndarray   # (D + 1, m)


def _warm_initializer(state: _WarmState, name: str, lit: LiteralFormat) -> list[str]:
    """``static const rhonn_warm_state NAME_warm = {...};`` in rhonn_warm.h's order."""
    def rows(arrays: list[np.ndarray], what: str) -> list[str]:
        return [f"    {{ /* {what} */"] + [f"        {_reals(a, lit)}," for a in arrays] + ["    },"]

    m = state.U.shape[1]
    return ([f"static const rhonn_warm_state {name}_warm = {{"]
            + rows(state.weights, "w_i(k)")
            + rows(state.factors, "covariances as stored (rhonn_get_factors)")
            + [f"    {int(state.learning)}, /* learning */",
               f"    {state.X.shape[0]}, /* n_samples: the last D + 1, oldest first */"]
            + rows(list(state.X), "x")
            + rows([u if m else np.zeros(1) for u in state.U], "u" if m else "u (no inputs)")
            + ["};"])


def _both_precisions_of_literal(render: Callable[[LiteralFormat], list[str]], dtype: str) -> list[str]:
    return [_HEX_FLOATS, "/* C, C++17 and later: hexadecimal floating literals, the exact bits */",
            *render(_hex_literal(dtype)),
            "#else",
            "/* C++11 and C++14: the shortest decimal literals that convert back to the same bits */",
            *render(_decimal_literal(dtype)),
            "#endif"]


def _text(cfg: IdentifierConfig, name: str, warm: _WarmState | None, signals: Signals | None = None) -> str:
    dt = cfg.dtype
    guard = f"{name.upper()}_RHONN_EXPORT_H"
    caps = min_capacities(cfg)
    checks = " || ".join(f"{k} < {v}" for k, v in caps.items() if k != "RHONN_MAX_ENTRIES")
    major, minor = LAYOUT_VERSION
    lines = [
        f"/* Generated by pyrhonn {__version__}: identifier {name!r}, {cfg.n_states} states, {cfg.n_inputs} inputs, {dt}"
        + (", with its running state (warm start). */" if warm else ". */"),
        "/* Do not edit: export again from Python (pyrhonn.export.export_header). C99, C++11 and later. */",
    ]
    if warm:
        lines += [f"/* Start with rhonn_warm_start(&net, &{name}, &{name}_warm, NULL): {name} is the",
                  " * configuration the run started from (its w0 and P0), the state continues the run. */"]
    lines += [
        f"#ifndef {guard}",
        f"#define {guard}",
        "",
        '#include "rhonn_warm.h"' if warm else '#include "rhonn.h"',
        "",
        f"#if RHONN_VERSION_MAJOR != {major} || RHONN_VERSION_MINOR < {minor}",
        f'#error "{name}: exported for the rhonn.h {major}.{minor} configuration layout"',
        "#endif",
        f"#if {checks}",
        f'#error "{name}: the RHONN_MAX_* capacities are too small for this identifier '
        '(see its exported capacity header)"',
        "#endif",
        "#ifdef RHONN_SINGLE" if dt == "float64" else "#ifndef RHONN_SINGLE",
        f'#error "{name} was exported as {dt}: build the core '
        + ("without RHONN_SINGLE" if dt == "float64" else "with RHONN_SINGLE") + '"',
        "#endif",
        "",
    ]
    if signals is not None:
        lines += _names_block(signals, name)

    def render(lit: LiteralFormat) -> list[str]:
        return _config_initializer(cfg, name, lit) + (_warm_initializer(warm, name, lit) if warm else [])

    lines += _both_precisions_of_literal(render, dt)
    lines += ["", f"#endif /* {guard} */", ""]
    return "\n".join(lines)


def header_text(source: Identifier | IdentifierConfig, name: str, signals: Signals | None = None, *,
                warm_start: WarmSamples | None = None) -> str:
    """The header as a string; ``source`` is an Identifier (its current
    weights and covariances become w0 and p0) or a config (exported as is);
    ``signals`` names the states and inputs in it. ``warm_start``: the
    samples (X, U, valid) an Identifier ``source`` last stepped on, to write
    its own configuration and its running state (see the module docs)."""
    name = _check_name(name)
    if signals is not None:
        signals.check(_config_of(source))
    if warm_start is None:
        return _text(_config_of(source), name, None, signals)
    if not isinstance(source, Identifier):
        raise ValueError(f"source: a warm start exports an Identifier's running state, got {type(source).__name__}")
    return _text(source.config, name, _warm_state(source, warm_start), signals)


def header_config(source: Identifier | IdentifierConfig, warm_start: bool) -> IdentifierConfig:
    """The configuration :func:`header_text` writes for ``source``: with a
    warm start the identifier's own (its w0 and P0), else the trained one."""
    return source.config if warm_start and isinstance(source, Identifier) else _config_of(source)


# -- warm start ------------------------------------------------------------------------------------


def _require(a: object, what: str, shape: tuple[int, ...], dtype: np.dtype, *, at_least: bool = False) -> np.ndarray:
    """``a`` as given, or a ValueError naming it: a numpy array of ``dtype``
    and ``shape`` (``shape[0]`` rows or more when ``at_least``)."""
    if not isinstance(a, np.ndarray):
        raise ValueError(f"{what}: expected a numpy array, got {type(a).__name__}")
    if a.dtype != dtype:
        raise ValueError(f"{what}: expected dtype {dtype}, got {a.dtype}")
    rows_ok = a.ndim >= 1 and (a.shape[0] >= shape[0] if at_least else a.shape[0] == shape[0])
    if a.ndim != len(shape) or a.shape[1:] != shape[1:] or not rows_ok:
        want = f"({shape[0]}{' or more' if at_least else ''}, {', '.join(map(str, shape[1:]))})"
        raise ValueError(f"{what}: expected shape {want}, got {a.shape}")
    return a


def _warm_state(ident: Identifier, samples: object) -> _WarmState:
    """The running state of ``ident`` and its last D + 1 samples, checked to be
    the ones that produced its regressors, prediction and history."""
    cfg = ident.config
    n, m, D = cfg.n_states, cfg.n_inputs, cfg.max_delay
    if not isinstance(samples, tuple) or len(samples) != 3:
        raise ValueError("warm_start: expected (X, U, valid), the samples the identifier last stepped on")
    Xa, Ua, Va = samples
    X = _require(Xa, "warm_start X", (D + 1, n), ident.dtype, at_least=True)
    T = X.shape[0]
    if Ua is None and m == 0:
        U = np.zeros((T, 0), dtype=ident.dtype)
    else:
        U = _require(Ua, "warm_start U", (T, m), ident.dtype)
    if Va is not None:
        V = _require(Va, "warm_start valid", (T, n), np.dtype(bool))
        bad = np.argwhere(~V[T - D - 1:])
        if bad.size:
            t, j = (int(v) for v in bad[0])
            raise ValueError(f"warm_start valid[{T - D - 1 + t}, {j}]: a dropout in the last {D + 1} samples; a warm "
                             f"start replays them as measured: export after {D + 1} measured samples")
    if not ident._net.started:
        raise ValueError("warm_start: the identifier has not stepped since it was built, reset or restarted")
    for i, nr in enumerate(cfg.neurons):
        if nr.reset_after and ident.health(i).fail_run:
            raise ValueError(f"warm_start: neuron {i} has {ident.health(i).fail_run} refused updates in a row, "
                             "a count a warm start does not carry (reset_after): export after a committed update")
    Xw, Uw = X[T - D - 1:], U[T - D - 1:]
    weights = ident.weights
    # The firmware's replay, in Python: frozen steps from the restored weights must
    # rebuild the identifier's regressors, prediction and history bit for bit.
    replay = Identifier(cfg)
    replay.learning = False
    for i, w in enumerate(weights):
        replay.set_weights(i, w)
    replay.run(Xw, Uw if m else None)
    same = (all(np.array_equal(a, b) for a, b in zip(replay.regressors, ident.regressors))
            and np.array_equal(replay.prediction, ident.prediction)
            and all(np.array_equal(replay._history()[k], ident._history()[k]) for k in ("x", "u")))
    if not same:
        raise ValueError(f"warm_start: the last {D + 1} rows are not the samples the identifier last stepped on "
                         "(replayed, they give other regressors or another prediction)")
    return _WarmState(weights=weights, factors=[ident._stored_covariance(i) for i in range(n)],
                      learning=ident.learning, X=Xw, U=Uw)


# -- files -----------------------------------------------------------------------------------------


def export_header(source: Identifier | IdentifierConfig, path: str | Path, name: str = "rhonn_exported", *,
                  warm_start: WarmSamples | None = None, include_dir: str | Path | None = None,
                  compiler: str | None = None, signals: Signals | None = None) -> Path:
    """Write the header to ``path`` and the capacity header beside it
    (:func:`capacity_path`), and return ``path``. ``warm_start``: the
    samples (X, U, valid) an Identifier ``source`` last stepped on, to
    export its running state too (see the module docs). ``include_dir`` and
    ``compiler`` serve :func:`measure_rhonn_t_size`; when it cannot measure,
    the capacity header says why. Each file is replaced whole (an
    interrupted export leaves the previous file or none, see
    :mod:`pyrhonn.atomic`). ``signals`` names the states and inputs in the header."""
    path = Path(path)
    text = header_text(source, name, signals, warm_start=warm_start)
    cfg = header_config(source, warm_start is not None)
    caps = capacity_text(cfg, name)
    size: int | str
    try:
        size = measure_rhonn_t_size(caps, cfg.dtype, include_dir=include_dir, compiler=compiler)
    except ValueError as exc:
        size = str(exc)
    atomic.write_text(path, text)
    atomic.write_text(capacity_path(path), capacity_text(cfg, name, size, capacity_path(path).name))
    return path
