"""Identifier config files: the ``pyrhonn-config`` TOML format, version 1.

A config file describes one :class:`~pyrhonn.config.IdentifierConfig` plus
what a person needs to use and review it: the names of the states and inputs
(the column names ``pyrhonn identify`` reads from a CSV file), a free-text
description and, per neuron, why it uses the terms it uses. Files are read
with the standard library's ``tomllib`` (UTF-8, a leading byte-order mark
allowed; at most 1 MiB, a regular file) and written with ``tomli_w``.

Example (every key that is not marked required is optional)::

    format = "pyrhonn-config"          # required, exactly this
    version = 1                        # required; a newer version is refused
    n_states = 4                       # required, 1..255
    n_inputs = 1                       # required, 0..255
    dtype = "float64"                  # "float64" (default) or "float32"
    state_names = ["x1", "x2", "x3", "x4"]   # default x1..xn
    input_names = ["u1"]               # default u1..um
    x0 = [0.0, 0.0, 0.0, 0.0]          # xhat(0); default zeros
    description = "why these terms"    # free text, shown by `pyrhonn show-config`

    [defaults]                         # every neuron inherits these ...
    activation = "bipolar"             # "bipolar" (eq. 19) or "logistic" (eq. 6)
    beta = 0.01                        # > 0
    p0 = 1e8                           # > 0: scalar (times I), list (diagonal) or
                                       # list of lists (full symmetric positive definite matrix)
    q = 5e5                            # >= 0: scalar (times I) or list (diagonal)
    r = 1e4                            # > 0
    eta = 1.0                          # > 0
    covariance = "ud"                  # optional: "full" (default, eq. 7 as written) or "ud"
                                       # (P = U D U^T factors, definite through rounding)
    forgetting = 0.999                 # optional: lambda in (0, 1], default 1 (no forgetting)
    p_trace_max = 4e8                  # optional: ceiling on trace P, >= trace P0; default none
    reset_after = 3                    # optional: 0..65535; reset P to P0 at the N-th refused
                                       # update in a row (default 0: never)
    gate = 9.0                         # optional: >= 0; skip an update whose e^2/s exceeds it
                                       # (an outlier; default 0: off)
    skip_refused = true                # optional: a refused update skips this neuron only, the
                                       # step goes on (default false: the step is refused)
    wait_for_history = true            # optional: learn only once every delayed tap reads a
                                       # measured sample (default false: from the second sample)

    [[neurons]]                        # required: exactly n_states tables, in state order
    terms = ["S(x1)", "S(x1)*S(x2)", "S(x1(k-1))^2", "x3", "u1", "1"]   # required, non-empty
    why = "own state, its chain partner, ..."   # free text
    beta = 0.02                        # ... unless the neuron sets its own:
                                       # activation, beta, p0, q, r, eta, and w0
                                       # (w0: list of L_i initial weights, default zeros)

    [bus]                              # optional: where `pyrhonn identify --can-log` finds each state
    sample_period = 0.01               # and input on a CAN bus (pyrhonn/buslog.py has the rules)
    clock = "Sensors"
    [bus.signals]
    x1 = "Sensors.Position"            # "Message.Signal" of the DBC, for every state and input

Rules
-----
- **Keys.** Unknown keys are errors (a misspelt ``bta`` must not silently
  fall back to a default), at the top level, in ``[defaults]`` and in each
  ``[[neurons]]`` table. ``w0``, ``terms`` and ``why`` are per neuron only.
  A tuning key set neither in the neuron nor in ``[defaults]`` takes the
  :class:`~pyrhonn.config.NeuronConfig` default (logistic, beta = 1, p0 = 1,
  q = 0, r = 1, eta = 1); files written by :func:`dumps` always set all six.
  The covariance form, windup, gate and refusal keys (``covariance``, ``forgetting``,
  ``p_trace_max``, ``reset_after``, ``gate``, ``skip_refused``, ``wait_for_history``) are off by default, so eq. 7 stays exact,
  and :func:`dumps` writes them only where they are set.
- **Numbers.** A real may be written as a TOML integer or float (``eta = 1``);
  booleans, strings and non-finite values (``inf``, ``nan``) are errors.
  A ``p0`` or ``q`` list applies per term, so it must have L_i entries for
  every neuron that uses it (also when it comes from ``[defaults]``).
- **Terms** (eq. 4) are strings: a product of factors joined by ``*``
  (spaces and tabs allowed around ``*``, nowhere else). A factor is
  ``S(xJ)``, ``S(xJ(k-D))``, ``xJ``, ``xJ(k-D)``, ``uJ``, ``uJ(k-D)`` or ``1``,
  each optionally followed by ``^P``: ``S`` is the neuron's activation, ``xJ``
  the J-th state, ``uJ`` the J-th input, ``(k-D)`` a delay of D >= 1 samples
  (on an input: its dead time),
  ``P`` >= 1 a power. J is **1-based** (as in the paper and as
  :class:`~pyrhonn.config.Factor` prints), J, D, P are written without
  leading zeros (``x01`` is an error), ``(k-0)`` is written as no delay.
  J refers to the position of the state or input, never
  to its name: with ``state_names = ["theta", "omega"]``, ``S(x2)`` is
  S(omega). ``S(x1)^2*u1`` is S(x_1(k))^2 u_1(k). One neuron may not list
  the same product twice (``S(x1)*u1`` and ``u1*S(x1)``, ``S(x1)^2`` and
  ``S(x1)*S(x1)``, ``u1`` and ``u1*1``): that would be two weights on one
  regressor, a typo more often than a choice.
- **Names** (``state_names``, ``input_names``) are CSV column names: ASCII
  identifiers (``[A-Za-z_][A-Za-z0-9_]*``), unique across states and inputs,
  not ``t`` (the time column of ``pyrhonn identify``), and not of the form
  ``xJ`` / ``uJ`` unless that is the entry's own position (a state named
  ``x2`` in position 1 would read as the term variable x2).
- **Paths.** Every error is a ``ValueError`` whose message is
  ``<file>: <key path>: <what is wrong>``; key paths are TOML paths with
  **0-based** array indices, e.g.
  ``cfg.toml: neurons[2].terms[1]: 'S(x9)': state index 9 out of range 1..4``
  (the third neuron's second term).
- **Versions.** ``version`` is an integer; this module reads version 1 and
  refuses newer versions with a message asking for a newer pyrhonn. Any
  change that an older reader would misread bumps the version.

The shipped configs live in ``pyrhonn/configs/<name>.toml`` (package data);
:func:`shipped_names`, :func:`load_shipped` and :func:`load_named` read them
and ``pyrhonn show-config NAME`` prints them.
"""
from __future__ import annotations

import difflib
import re
import tomllib
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any, BinaryIO, Mapping

import numpy as np
import tomli_w

from .buslog import BusMap
from .config import DTYPES, Activation, CovarianceForm, Factor, FactorKind, IdentifierConfig, NeuronConfig, Term
from .validation import check_int, check_real, decode_text, fail, read_file

__all__ = [
    "FORMAT",
    "VERSION",
    "ConfigFile",
    "dump_config",
    "dumps",
    "format_factor",
    "format_term",
    "is_path",
    "load_config",
    "load_named",
    "load_shipped",
    "loads",
    "parse_term",
    "read_named",
    "save_config",
    "shipped_names",
    "shipped_text",
]

FORMAT = "pyrhonn-config"
VERSION = 1
MAX_FILE_BYTES = 1 << 20  #: a config file is a few kB; a larger one is not a config (or /dev/zero)

TUNING_KEYS = ("activation", "beta", "p0", "q", "r", "eta")
#: Covariance form and windup protection: optional, written by dumps only when not the default.
PROTECTION_KEYS = ("covariance", "forgetting", "p_trace_max", "reset_after", "gate", "skip_refused",
                   "wait_for_history")

_TOP_KEYS = ("format", "version", "n_states", "n_inputs", "dtype", "state_names", "input_names", "x0",
             "description", "defaults", "neurons", "bus")
_NEURON_KEYS = ("terms", *TUNING_KEYS, *PROTECTION_KEYS, "w0", "why")
_NEURON_DEFAULTS: dict[str, Any] = {"activation": Activation.LOGISTIC.value, "beta": 1.0, "p0": 1.0, "q": 0.0,
                                    "r": 1.0, "eta": 1.0}
_NAME_RE = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")
_VARIABLE_RE = re.compile(r"([xu])([0-9]+)\Z")
RESERVED_NAMES = ("t",)
_SHIPPED_NAME_RE = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]*\Z")

# One factor: optional S( ... ), a variable x/u with an index, an optional (k-D), the closing
# parenthesis iff S( opened one, or the constant 1; then an optional ^P. Digits are ASCII only.
_FACTOR_RE = re.compile(
    r"(?:(?P<s>S\()?(?P<var>[xu])(?P<index>[0-9]+)(?:\(k-(?P<delay>[0-9]+)\))?(?(s)\))|(?P<one>1))"
    r"(?:\^(?P<power>[0-9]+))?\Z"
)
_SPACE = " \t"


# -- terms -------------------------------------------------------------------------------------


def _number(text: str, what: str, lo: int, hi: int) -> int:
    """A decimal integer field of a factor, without leading zeros, in lo..hi."""
    if len(text) > 1 and text[0] == "0":
        raise ValueError(f"{what} {text} is written with a leading zero")
    if len(text) > 3:  # beyond any limit here (255): not worth converting, nor echoing in full
        raise ValueError(f"{what} of {len(text)} digits out of range {lo}..{hi}")
    value = int(text)
    if not lo <= value <= hi:
        raise ValueError(f"{what} {value} out of range {lo}..{hi}")
    return value


def _parse_factor(text: str, n_states: int | None, n_inputs: int | None) -> Factor:
    """One factor; ValueError with the bare reason (the caller adds the quoted text)."""
    if any(c.isspace() for c in text):
        raise ValueError("whitespace inside a factor (only around '*' is allowed)")
    m = _FACTOR_RE.match(text)
    if m is None:
        raise ValueError("expected S(xJ), S(xJ(k-D)), xJ, xJ(k-D), uJ, uJ(k-D) or 1, optionally followed by ^P")
    power = 1 if m["power"] is None else _number(m["power"], "power", 1, 255)
    if m["one"] is not None:
        return Factor(FactorKind.ONE, 0, 0, power)
    if m["var"] == "u":
        if m["s"] is not None:
            raise ValueError("S(...) applies to states only; write an input as uJ")
        hi = 255 if n_inputs is None else n_inputs
        if hi == 0:
            raise ValueError(f"input u{m['index']} but the identifier has no inputs (n_inputs = 0)")
        j = _number(m["index"], "input index", 1, hi)
        delay = 0 if m["delay"] is None else _number(m["delay"], "delay", 1, 254)
        return Factor(FactorKind.U, j - 1, delay, power)
    hi = 255 if n_states is None else n_states
    j = _number(m["index"], "state index", 1, hi)
    delay = 0 if m["delay"] is None else _number(m["delay"], "delay", 1, 254)
    return Factor(FactorKind.S if m["s"] is not None else FactorKind.X, j - 1, delay, power)


def parse_term(text: str, n_states: int | None = None, n_inputs: int | None = None) -> Term:
    """Parse one term string (see the module docs) into a tuple of Factor.

    ``n_states`` / ``n_inputs``, when given, bound the 1-based indices;
    otherwise only the format's limits (1..255) apply. Raises ``ValueError``
    quoting the offending factor (or the whole term for a structural
    defect), e.g. ``'S(x9)': state index 9 out of range 1..4``.
    """
    if not isinstance(text, str):
        raise ValueError(f"expected a term string such as 'S(x1)*u1', got {type(text).__name__} {text!r}")
    if text == "":
        raise ValueError("'': empty term (a constant term is written '1')")
    parts = text.split("*")
    factors: list[Factor] = []
    for p, part in enumerate(parts):
        core = part.strip(_SPACE)
        if not core:
            hint = " (powers are written ^P)" if "**" in text.replace(" ", "").replace("\t", "") else ""
            raise ValueError(f"{text!r}: empty factor{hint}")
        if (p == 0 and part[0] in _SPACE) or (p == len(parts) - 1 and part[-1] in _SPACE):
            raise ValueError(f"{text!r}: leading or trailing whitespace (only around '*' is allowed)")
        try:
            factors.append(_parse_factor(core, n_states, n_inputs))
        except ValueError as exc:
            shown = repr(core) if len(core) <= 60 else f"{core[:40]!r}... ({len(core)} characters)"
            raise ValueError(f"{shown}: {exc}") from None
    return tuple(factors)


def format_factor(factor: Factor) -> str:
    """The canonical text of one factor: ``S(x2(k-3))^2``, ``u1``, ``1``.

    Equal to ``str(factor)`` except that a constant with a power other than
    1 is written ``1^P`` (so that every factor round-trips through
    :func:`parse_term`).
    """
    if not isinstance(factor, Factor):
        raise ValueError(f"expected a Factor, got {type(factor).__name__}")
    if factor.kind is FactorKind.ONE:
        return "1" if factor.power == 1 else f"1^{factor.power}"
    return str(factor)


def format_term(term: Term) -> str:
    """The canonical text of a term: its factors joined by ``*`` (no spaces);
    ``parse_term(format_term(t)) == t`` for every valid term."""
    if not isinstance(term, tuple) or not term:
        raise ValueError(f"expected a non-empty tuple of Factor, got {term!r}")
    return "*".join(format_factor(f) for f in term)


# -- the file object ------------------------------------------------------------------------------


def _default_names(prefix: str, count: int) -> tuple[str, ...]:
    return tuple(f"{prefix}{j + 1}" for j in range(count))


def _check_names(state_names: object, input_names: object, n: int, m: int) -> None:
    """Names: tuples of valid, unique, unreserved identifiers of the right lengths."""
    seen: dict[str, str] = {}
    for key, names, count, var in (("state_names", state_names, n, "x"), ("input_names", input_names, m, "u")):
        if not isinstance(names, tuple):
            raise fail(key, f"expected a tuple of str, got {type(names).__name__}")
        if len(names) != count:
            raise fail(key, f"expected {count} names (one per {'state' if var == 'x' else 'input'}), "
                            f"got {len(names)}")
        for j, name in enumerate(names):
            path = f"{key}[{j}]"
            if not isinstance(name, str):
                raise fail(path, f"expected a string, got {type(name).__name__} {name!r}")
            if not _NAME_RE.match(name):
                raise fail(path, f"{name!r} is not a valid name (letters, digits and _, not starting with a digit)")
            if name in RESERVED_NAMES:
                raise fail(path, f"{name!r} is reserved for the time column")
            if name in seen:
                raise fail(path, f"duplicate name {name!r} (also {seen[name]})")
            if _VARIABLE_RE.match(name) and name != f"{var}{j + 1}":
                raise fail(path, f"{name!r} would be confused with the term variable {name} "
                                 f"(terms refer to positions; this entry is {var}{j + 1})")
            seen[name] = path


@dataclass(frozen=True)
class ConfigFile:
    """An identifier config as stored in a file.

    Attributes
    ----------
    config:
        The validated :class:`~pyrhonn.config.IdentifierConfig`.
    state_names, input_names:
        n and m names (the CSV column names of ``pyrhonn identify``).
    description:
        Free text about the whole config ("" when none).
    why:
        Per neuron, free text on why it uses its terms; n entries ("" when
        none). An empty tuple is accepted and means "no texts".
    bus:
        Where each state and input is on a CAN bus (the ``[bus]`` table,
        :class:`pyrhonn.buslog.BusMap`), or None.
    """

    config: IdentifierConfig
    state_names: tuple[str, ...]
    input_names: tuple[str, ...]
    description: str = ""
    why: tuple[str, ...] = ()
    bus: BusMap | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.config, IdentifierConfig):
            raise fail("config", f"expected an IdentifierConfig, got {type(self.config).__name__}")
        n, m = self.config.n_states, self.config.n_inputs
        _check_names(self.state_names, self.input_names, n, m)
        if not isinstance(self.description, str):
            raise fail("description", f"expected a string, got {type(self.description).__name__}")
        if not isinstance(self.why, tuple):
            raise fail("why", f"expected a tuple of str, got {type(self.why).__name__}")
        if self.why == ():
            object.__setattr__(self, "why", ("",) * n)
        if len(self.why) != n:
            raise fail("why", f"expected {n} texts (one per neuron), got {len(self.why)}")
        for i, text in enumerate(self.why):
            if not isinstance(text, str):
                raise fail(f"neurons[{i}].why", f"expected a string, got {type(text).__name__}")
        if self.bus is not None:
            if not isinstance(self.bus, BusMap):
                raise fail("bus", f"expected a BusMap, got {type(self.bus).__name__}")
            names = (*self.state_names, *self.input_names)
            for key, table in (("signals", self.bus.signals), ("valid", self.bus.valid)):
                for name in table:
                    if name not in names:
                        raise fail(f"bus.{key}.{name}", f"not one of the config's states and inputs "
                                                        f"({', '.join(names)})")

    @classmethod
    def from_config(
        cls,
        config: IdentifierConfig,
        *,
        state_names: tuple[str, ...] | None = None,
        input_names: tuple[str, ...] | None = None,
        description: str = "",
        why: tuple[str, ...] = (),
    ) -> ConfigFile:
        """Wrap a config, with default names x1..xn and u1..um unless given."""
        if not isinstance(config, IdentifierConfig):
            raise fail("config", f"expected an IdentifierConfig, got {type(config).__name__}")
        return cls(
            config=config,
            state_names=_default_names("x", config.n_states) if state_names is None else state_names,
            input_names=_default_names("u", config.n_inputs) if input_names is None else input_names,
            description=description,
            why=why,
        )

    @property
    def term_strings(self) -> tuple[tuple[str, ...], ...]:
        """Every neuron's terms in the canonical text form."""
        return tuple(tuple(format_term(t) for t in nr.terms) for nr in self.config.neurons)


# -- reading --------------------------------------------------------------------------------------


def _check_keys(path: str, table: Mapping[str, Any], allowed: tuple[str, ...]) -> None:
    for key in table:
        if key not in allowed:
            close = difflib.get_close_matches(key, allowed, n=1)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            where = f"{path}.{key}" if path else key
            raise fail(where, f"unknown key{hint} (allowed here: {', '.join(allowed)})")


def _table(path: str, value: object) -> Mapping[str, Any]:
    if not isinstance(value, dict):
        raise fail(path, f"expected a table, got {_toml_type(value)}")
    return value


def _toml_type(value: object) -> str:
    if isinstance(value, bool):
        return f"a boolean ({str(value).lower()})"
    if isinstance(value, dict):
        return "a table"
    if isinstance(value, list):
        return "an array"
    if isinstance(value, str):
        return f"a string ({value!r})"
    if isinstance(value, (int, float)):
        return f"a number ({value!r})"
    return f"a {type(value).__name__} ({value!r})"


def _string(path: str, value: object) -> str:
    if not isinstance(value, str):
        raise fail(path, f"expected a string, got {_toml_type(value)}")
    return value


def _real_vector(path: str, value: object, *, nonnegative: bool = False, positive: bool = False) -> np.ndarray:
    """A TOML array of real numbers as a float64 vector (checked entry by entry)."""
    if not isinstance(value, list):
        raise fail(path, f"expected an array of numbers, got {_toml_type(value)}")
    if not value:
        raise fail(path, "expected a non-empty array of numbers")
    out = [check_real(f"{path}[{k}]", v, positive=positive, nonnegative=nonnegative) for k, v in enumerate(value)]
    return np.array(out, dtype=np.float64)


def _real_matrix(path: str, value: list[Any]) -> np.ndarray:
    rows = [_real_vector(f"{path}[{r}]", row) for r, row in enumerate(value)]
    for r, row in enumerate(rows):
        if row.shape != rows[0].shape:
            raise fail(f"{path}[{r}]", f"expected {rows[0].shape[0]} entries like row 0, got {row.shape[0]}")
    return np.array(rows, dtype=np.float64)


def _tuning_value(path: str, key: str, value: object) -> Any:
    """A tuning value from the file, type-checked (shapes are checked per neuron)."""
    if key == "activation":
        allowed = [a.value for a in Activation]
        if not isinstance(value, str) or value not in allowed:
            raise fail(path, f"expected one of {allowed}, got {_toml_type(value)}")
        return Activation(value)
    if key in ("beta", "r", "eta"):
        return check_real(path, value, positive=True)
    if key == "p0":
        if isinstance(value, list):
            if value and all(isinstance(row, list) for row in value):
                return _real_matrix(path, value)
            if any(isinstance(row, list) for row in value):
                raise fail(path, "expected an array of numbers or an array of arrays, not a mix")
            return _real_vector(path, value, positive=True)
        return check_real(path, value, positive=True)
    if key == "q":
        if isinstance(value, list):
            return _real_vector(path, value, nonnegative=True)
        return check_real(path, value, nonnegative=True)
    if key == "covariance":
        allowed = [c.value for c in CovarianceForm]
        if not isinstance(value, str) or value not in allowed:
            raise fail(path, f"expected one of {allowed}, got {_toml_type(value)}")
        return CovarianceForm(value)
    if key in ("forgetting", "p_trace_max"):
        return check_real(path, value, positive=True)
    if key == "reset_after":
        return check_int(path, value, 0, 65535)
    if key == "gate":
        return check_real(path, value, nonnegative=True)
    if key in ("skip_refused", "wait_for_history"):
        if not isinstance(value, bool):
            raise fail(path, f"expected true or false, got {_toml_type(value)}")
        return value
    raise AssertionError(key)  # pragma: no cover


def _names(doc: Mapping[str, Any], key: str, count: int, prefix: str) -> tuple[str, ...]:
    if key not in doc:
        return _default_names(prefix, count)
    raw = doc[key]
    if not isinstance(raw, list):
        raise fail(key, f"expected an array of strings, got {_toml_type(raw)}")
    return tuple(_string(f"{key}[{j}]", v) for j, v in enumerate(raw))


def _neuron(i: int, raw: object, defaults: Mapping[str, Any], n: int, m: int) -> tuple[NeuronConfig, str]:
    path = f"neurons[{i}]"
    table = _table(path, raw)
    _check_keys(path, table, _NEURON_KEYS)
    if "terms" not in table:
        raise fail(f"{path}.terms", "missing (a non-empty array of term strings, e.g. [\"S(x1)\", \"u1\"])")
    raw_terms = table["terms"]
    if not isinstance(raw_terms, list):
        raise fail(f"{path}.terms", f"expected an array of term strings, got {_toml_type(raw_terms)}")
    if not raw_terms:
        raise fail(f"{path}.terms", "expected at least one term")
    terms = []
    for t, text in enumerate(raw_terms):
        try:
            terms.append(parse_term(text, n, m))
        except ValueError as exc:
            raise fail(f"{path}.terms[{t}]", str(exc)) from None
    L = len(terms)
    values: dict[str, Any] = {}
    origin: dict[str, str] = {}
    for key in TUNING_KEYS + PROTECTION_KEYS:
        if key in table:
            values[key] = _tuning_value(f"{path}.{key}", key, table[key])
            origin[key] = f"{path}.{key}"
        elif key in defaults:
            values[key], origin[key] = defaults[key], f"defaults.{key}"
        elif key in _NEURON_DEFAULTS:  # the protection keys default in NeuronConfig itself (off)
            values[key] = _tuning_value(key, key, _NEURON_DEFAULTS[key])
            origin[key] = f"{path}.{key}"
    if "w0" in table:
        values["w0"] = _real_vector(f"{path}.w0", table["w0"])
        origin["w0"] = f"{path}.w0"
    why = _string(f"{path}.why", table["why"]) if "why" in table else ""
    try:
        neuron = NeuronConfig(terms=tuple(terms), **values)
    except ValueError as exc:
        message = str(exc)
        field, _, rest = message.partition(":")
        key = field.split("[", 1)[0]
        if key in origin:
            where = origin[key] + field[len(key):]
            note = f" (inherited by {path}, which has {L} terms)" if origin[key].startswith("defaults.") else ""
            raise fail(where, rest.strip() + note) from None
        if key == "terms":  # a term index: neurons[i].terms[t]
            raise fail(f"{path}.{field}", rest.strip()) from None
        raise fail(path, message) from None
    return neuron, why


def _from_document(doc: Mapping[str, Any]) -> ConfigFile:
    if "format" not in doc:
        raise fail("format", f"missing; a pyrhonn config file starts with format = \"{FORMAT}\"")
    if doc["format"] != FORMAT:
        raise fail("format", f"expected \"{FORMAT}\", got {_toml_type(doc['format'])} (not a pyrhonn config file?)")
    if "version" not in doc:
        raise fail("version", f"missing; expected version = {VERSION}")
    version = doc["version"]
    if isinstance(version, bool) or not isinstance(version, int):
        raise fail("version", f"expected an integer, got {_toml_type(version)}")
    if version > VERSION:
        raise fail("version", f"{version} is newer than this pyrhonn reads (version {VERSION}); "
                              "upgrade pyrhonn to read this file")
    if version < 1:
        raise fail("version", f"{version} is not a valid version (versions start at 1)")
    _check_keys("", doc, _TOP_KEYS)
    for key in ("n_states", "n_inputs", "neurons"):
        if key not in doc:
            raise fail(key, "missing")
    n = check_int("n_states", doc["n_states"], 1, 255)
    m = check_int("n_inputs", doc["n_inputs"], 0, 255)
    dtype = doc.get("dtype", "float64")
    if dtype not in DTYPES:
        raise fail("dtype", f"expected one of {list(DTYPES)}, got {_toml_type(dtype)}")
    state_names = _names(doc, "state_names", n, "x")
    input_names = _names(doc, "input_names", m, "u")
    _check_names(state_names, input_names, n, m)
    x0 = None
    if "x0" in doc:
        x0 = _real_vector("x0", doc["x0"])
        if x0.shape != (n,):
            raise fail("x0", f"expected {n} numbers (one per state), got {x0.shape[0]}")
    description = _string("description", doc["description"]) if "description" in doc else ""
    defaults: dict[str, Any] = {}
    if "defaults" in doc:
        table = _table("defaults", doc["defaults"])
        _check_keys("defaults", table, TUNING_KEYS + PROTECTION_KEYS)
        defaults = {key: _tuning_value(f"defaults.{key}", key, v) for key, v in table.items()}
    raw = doc["neurons"]
    if not isinstance(raw, list):
        raise fail("neurons", f"expected an array of tables ([[neurons]]), got {_toml_type(raw)}")
    if len(raw) != n:
        raise fail("neurons", f"expected {n} [[neurons]] tables (one per state, n_states = {n}), got {len(raw)}")
    built = [_neuron(i, nr, defaults, n, m) for i, nr in enumerate(raw)]
    config = IdentifierConfig(n_states=n, n_inputs=m, neurons=tuple(nr for nr, _ in built), dtype=dtype, x0=x0)
    bus = BusMap.from_table(doc["bus"], state_names, input_names) if "bus" in doc else None
    return ConfigFile(config=config, state_names=state_names, input_names=input_names,
                      description=description, why=tuple(w for _, w in built), bus=bus)


def loads(text: str, source: str = "<string>") -> ConfigFile:
    """Parse config-file text; errors are ``ValueError("<source>: <key path>: ...")``."""
    if not isinstance(text, str):
        raise ValueError(f"{source}: expected the file's text as str, got {type(text).__name__}")
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{source}: not valid TOML: {exc}") from None
    except RecursionError:
        raise ValueError(f"{source}: not a pyrhonn config: arrays or tables nested too deeply to parse") from None
    try:
        return _from_document(doc)
    except ValueError as exc:
        raise ValueError(f"{source}: {exc}") from None


def load_config(path: str | Path) -> ConfigFile:
    """Read a config file; every defect raises ``ValueError`` naming the file
    and the key (``OSError`` if it cannot be read)."""
    p = Path(path)
    return loads(decode_text(read_file(p, str(path), limit=MAX_FILE_BYTES), str(path), bom=True), source=str(path))


# -- writing --------------------------------------------------------------------------------------


def _document(cf: ConfigFile) -> dict[str, Any]:
    cfg = cf.config
    doc: dict[str, Any] = {
        "format": FORMAT,
        "version": VERSION,
        "n_states": cfg.n_states,
        "n_inputs": cfg.n_inputs,
        "dtype": cfg.dtype,
        "state_names": list(cf.state_names),
        "input_names": list(cf.input_names),
    }
    if cfg.x0 is not None:
        doc["x0"] = [float(v) for v in cfg.x0]
    if cf.description:
        doc["description"] = cf.description
    dicts = [nr.to_dict() for nr in cfg.neurons]
    # the protection keys are written only where they differ from NeuronConfig's own defaults (off)
    off = NeuronConfig(terms=((Factor.one(),),)).to_dict()
    shared = {key: dicts[0][key] for key in TUNING_KEYS if all(d[key] == dicts[0][key] for d in dicts)}
    shared.update({key: dicts[0][key] for key in PROTECTION_KEYS
                   if dicts[0][key] != off[key] and all(d[key] == dicts[0][key] for d in dicts)})
    if shared:
        doc["defaults"] = shared
    neurons = []
    for i, (nr, d) in enumerate(zip(cfg.neurons, dicts)):
        table: dict[str, Any] = {"terms": [format_term(t) for t in nr.terms]}
        if cf.why[i]:
            table["why"] = cf.why[i]
        for key in TUNING_KEYS:
            if key not in shared:
                table[key] = d[key]
        for key in PROTECTION_KEYS:
            if key not in shared and d[key] != off[key]:
                table[key] = d[key]
        if d["w0"] is not None:
            table["w0"] = d["w0"]
        neurons.append(table)
    doc["neurons"] = neurons
    if cf.bus is not None:
        doc["bus"] = cf.bus.to_table()
    return doc


def _as_file(config: ConfigFile | IdentifierConfig) -> ConfigFile:
    if isinstance(config, ConfigFile):
        return config
    if isinstance(config, IdentifierConfig):
        return ConfigFile.from_config(config)
    raise ValueError(f"config: expected a ConfigFile or IdentifierConfig, got {type(config).__name__}")


def dumps(config: ConfigFile | IdentifierConfig) -> str:
    """The config-file text of ``config`` (an IdentifierConfig gets default
    names). Tuning shared by every neuron goes to ``[defaults]``; floats are
    written exactly, so ``loads(dumps(c))`` equals ``c``."""
    cf = _as_file(config)
    header = f"# pyrhonn identifier config ({FORMAT}, version {VERSION}); see pyrhonn/configfile.py\n"
    return header + tomli_w.dumps(_document(cf), multiline_strings=True)


def dump_config(config: ConfigFile | IdentifierConfig, fp: BinaryIO) -> None:
    """Write the config-file text to a binary file object (UTF-8)."""
    fp.write(dumps(config).encode("utf-8"))


def save_config(config: ConfigFile | IdentifierConfig, path: str | Path) -> None:
    """Write the config file ``path`` (UTF-8), replacing it whole if it exists (pyrhonn.atomic)."""
    from . import atomic

    atomic.write_text(path, dumps(config))


# -- shipped configs --------------------------------------------------------------------------------


def _shipped_dir() -> Any:
    return resources.files("pyrhonn").joinpath("configs")


def shipped_names() -> tuple[str, ...]:
    """Names of the configs shipped in ``pyrhonn/configs`` (sorted)."""
    folder = _shipped_dir()
    if not folder.is_dir():
        return ()
    return tuple(sorted(p.name[: -len(".toml")] for p in folder.iterdir()
                        if p.name.endswith(".toml") and p.is_file()))


def _unknown(name: str) -> ValueError:
    names = shipped_names()
    listing = ", ".join(names) if names else "(none)"
    return ValueError(f"unknown config {name!r}; shipped configs: {listing} "
                      "(a file is given as a path ending in .toml or containing '/')")


def shipped_text(name: str) -> str:
    """The text of the shipped config ``name`` (ValueError listing the names if unknown)."""
    if not isinstance(name, str) or not _SHIPPED_NAME_RE.match(name) or name not in shipped_names():
        raise _unknown(str(name))
    return decode_text(_shipped_dir().joinpath(f"{name}.toml").read_bytes(), f"pyrhonn/configs/{name}.toml")


def load_shipped(name: str) -> ConfigFile:
    """The shipped config ``name``, e.g. ``load_shipped("example1")``."""
    return loads(shipped_text(name), source=f"pyrhonn/configs/{name}.toml")


def is_path(name_or_path: str) -> bool:
    """Whether a command-line argument names a file (ends in ``.toml`` or
    contains a path separator) rather than a shipped config."""
    return name_or_path.endswith(".toml") or "/" in name_or_path or "\\" in name_or_path


def read_named(name_or_path: str) -> tuple[str, str]:
    """``(source, text)`` for a shipped config name or a file path (see :func:`is_path`)."""
    if is_path(name_or_path):
        return name_or_path, decode_text(read_file(name_or_path, name_or_path, limit=MAX_FILE_BYTES), name_or_path,
                                         bom=True)
    return f"pyrhonn/configs/{name_or_path}.toml", shipped_text(name_or_path)


def load_named(name_or_path: str) -> ConfigFile:
    """A shipped config by name, or a config file by path (see :func:`is_path`)."""
    source, text = read_named(name_or_path)
    return loads(text, source=source)
