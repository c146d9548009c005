"""The pyrhonn-config TOML format: term strings, loading, saving, every
rejected input (named by file and key), and the shipped configs."""
from __future__ import annotations

import io
import re

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pyrhonn import Activation, Factor, FactorKind, IdentifierConfig, NeuronConfig, presets
from pyrhonn.configfile import (ConfigFile, dump_config, dumps, format_term, load_config, load_named,
                                load_shipped, loads, parse_term, save_config, shipped_names, shipped_text)
from strategies import configs

SPEC_EXAMPLE = '''\
format = "pyrhonn-config"
version = 1
n_states = 4
n_inputs = 1
dtype = "float64"                 # optional, default float64
state_names = ["x1","x2","x3","x4"]  # optional, default x1..xn
input_names = ["u1"]              # optional, default u1..um
x0 = [0.0, 0.0, 0.0, 0.0]         # optional
description = "..."               # optional free text
[defaults]                        # optional
activation = "bipolar"            # or "logistic"
beta = 0.01
p0 = 1e8                          # scalar, list (diagonal) or list of lists (full symmetric)
q = 5e5                           # scalar or list
r = 1e4
eta = 1.0
[[neurons]]
terms = ["S(x1)", "S(x1)*S(x2)", "S(x1(k-1))^2", "x3", "u1", "1"]
[[neurons]]
terms = ["S(x2)", "u1"]
why = "second neuron"
[[neurons]]
terms = ["S(x3)", "S(x1)"]
beta = 0.5
[[neurons]]
terms = ["S(x4) * S(x3)", "x4(k-2)", "u1^2"]
activation = "logistic"
p0 = [1.0, 2.0, 3.0]
q = [0.0, 0.1, 0.2]
r = 2
eta = 0.5
w0 = [0.1, -0.2, 0.3]
'''


# -- term strings ---------------------------------------------------------------------------------

@pytest.mark.parametrize("text, term", [
    ("S(x1)", (Factor.s(0),)),
    ("S(x2(k-3))^2", (Factor.s(1, delay=3, power=2),)),
    ("x3", (Factor.x(2),)),
    ("x1(k-1)", (Factor.x(0, delay=1),)),
    ("u2^3", (Factor.u(1, 3),)),
    ("u2(k-3)", (Factor.u(1, delay=3),)),
    ("u1(k-12)^2*S(x1)", (Factor.u(0, 2, delay=12), Factor.s(0))),
    ("1", (Factor.one(),)),
    ("1^2", (Factor(FactorKind.ONE, 0, 0, 2),)),
    ("S(x1)*S(x2)", (Factor.s(0), Factor.s(1))),
    ("S(x1) *\tu1 * x12(k-10)^4", (Factor.s(0), Factor.u(0), Factor.x(11, delay=10, power=4))),
])
def test_parse_term_reads_each_factor_form(text: str, term: tuple) -> None:
    assert parse_term(text) == term


@pytest.mark.parametrize("text, message", [
    ("", "empty term"),
    ("S(x1)**2", "empty factor (powers are written ^P)"),
    ("S(x" + "1" * 5000 + ")", "'S(x1111111111111111111111111111111111111'... (5004 characters): state index of 5000 "
                              "digits out of range"),
    ("u" + "9" * 30, "input index of 30 digits out of range"),
    ("S(x1)*", "empty factor"),
    (" S(x1)", "leading or trailing whitespace"),
    ("S(x1) ", "leading or trailing whitespace"),
    ("S( x1)", "'S( x1)': whitespace inside a factor"),
    ("s(x1)", "'s(x1)': expected S(xJ)"),
    ("S(x1", "'S(x1': expected S(xJ)"),
    ("x1)", "'x1)': expected S(xJ)"),
    ("y1", "'y1': expected S(xJ)"),
    ("x", "'x': expected S(xJ)"),
    ("x0", "'x0': state index 0 out of range 1..255"),
    ("x01", "'x01': state index 01 is written with a leading zero"),
    ("x1(k-0)", "'x1(k-0)': delay 0 out of range 1..254"),
    ("x1(k+1)", "'x1(k+1)': expected S(xJ)"),
    ("x1(k-255)", "delay 255 out of range 1..254"),
    ("x1^0", "'x1^0': power 0 out of range 1..255"),
    ("x1^256", "power 256 out of range"),
    ("x1^-1", "expected S(xJ)"),
    ("u1(k-0)", "'u1(k-0)': delay 0 out of range 1..254"),
    ("S(u1)", "'S(u1)': S(...) applies to states only"),
    ("x256", "state index 256 out of range 1..255"),
    ("x\u0661", "expected S(xJ)"),          # a non-ASCII digit
    ("2", "expected S(xJ)"),
    ("S(x1)^2^2", "expected S(xJ)"),
])
def test_parse_term_rejects_malformed_text_quoting_it(text: str, message: str) -> None:
    with pytest.raises(ValueError, match=re.escape(message)):
        parse_term(text)


def test_parse_term_checks_indices_against_the_identifier() -> None:
    with pytest.raises(ValueError, match=re.escape("'S(x9)': state index 9 out of range 1..4")):
        parse_term("S(x1)*S(x9)", n_states=4, n_inputs=1)
    with pytest.raises(ValueError, match=re.escape("'u2': input index 2 out of range 1..1")):
        parse_term("u2", n_states=4, n_inputs=1)
    with pytest.raises(ValueError, match="has no inputs"):
        parse_term("u1", n_states=4, n_inputs=0)
    with pytest.raises(ValueError, match="expected a term string"):
        parse_term(3)  # type: ignore[arg-type]


@st.composite
def any_factor(draw: st.DrawFn) -> Factor:
    kind = draw(st.sampled_from(list(FactorKind)))
    power = draw(st.integers(1, 255))
    if kind is FactorKind.ONE:
        return Factor(kind, 0, 0, power)
    if kind is FactorKind.U:
        return Factor.u(draw(st.integers(0, 254)), power)
    return Factor(kind, draw(st.integers(0, 254)), draw(st.integers(0, 254)), power)


any_term = st.lists(any_factor(), min_size=1, max_size=6).map(tuple)


@given(any_term, st.lists(st.sampled_from(["", " ", "\t", "  "]), min_size=12, max_size=12))
def test_format_term_round_trips_through_parse_term(term: tuple, spaces: list[str]) -> None:
    text = format_term(term)
    assert parse_term(text) == term
    assert format_term(parse_term(text)) == text
    spaced = "*".join(f"{spaces[2 * i] if i else ''}{part}{spaces[2 * i + 1] if i < len(term) - 1 else ''}"
                      for i, part in enumerate(text.split("*")))
    assert parse_term(spaced) == term


@given(st.text(alphabet="Sxuk()-^*0123456789 \t", max_size=24))
def test_parse_term_on_arbitrary_text_returns_a_term_or_raises_value_error(text: str) -> None:
    try:
        term = parse_term(text)
    except ValueError:
        return
    assert parse_term(format_term(term)) == term


def test_format_term_prints_factors_like_factor_str() -> None:
    term = (Factor.s(0, delay=2, power=3), Factor.x(1), Factor.u(0), Factor.one())
    assert format_term(term) == "*".join(str(f) for f in term) == "S(x1(k-2))^3*x2*u1*1"
    assert NeuronConfig(terms=(term,)).describe() == [format_term(term)]


# -- loading --------------------------------------------------------------------------------------

def test_the_documented_example_loads_with_defaults_and_overrides() -> None:
    cf = loads(SPEC_EXAMPLE, "cfg.toml")
    cfg = cf.config
    assert (cfg.n_states, cfg.n_inputs, cfg.dtype) == (4, 1, "float64")
    assert cf.state_names == ("x1", "x2", "x3", "x4") and cf.input_names == ("u1",)
    assert cf.description == "..." and cf.why == ("", "second neuron", "", "")
    n0, n1, n2, n3 = cfg.neurons
    assert n0.terms == ((Factor.s(0),), (Factor.s(0), Factor.s(1)), (Factor.s(0, delay=1, power=2),),
                        (Factor.x(2),), (Factor.u(0),), (Factor.one(),))
    assert (n0.activation, n0.beta, n0.p0, n0.q, n0.r, n0.eta) == (Activation.BIPOLAR, 0.01, 1e8, 5e5, 1e4, 1.0)
    assert n0.w0 is None and np.array_equal(cfg.x0, np.zeros(4))
    assert n2.beta == 0.5 and n2.activation is Activation.BIPOLAR     # one override, the rest inherited
    assert n3.activation is Activation.LOGISTIC and n3.r == 2.0 and n3.eta == 0.5
    assert np.array_equal(n3.p0, [1.0, 2.0, 3.0]) and np.array_equal(n3.q, [0.0, 0.1, 0.2])
    assert np.array_equal(n3.w0, [0.1, -0.2, 0.3])
    assert n3.terms[0] == (Factor.s(3), Factor.s(2)) and n3.terms[1] == (Factor.x(3, delay=2),)


def test_optional_keys_take_their_documented_defaults() -> None:
    cf = loads('format = "pyrhonn-config"\nversion = 1\nn_states = 2\nn_inputs = 1\n'
               '[[neurons]]\nterms = ["S(x1)"]\n[[neurons]]\nterms = ["u1", "1"]\n')
    assert cf.config.dtype == "float64" and cf.config.x0 is None
    assert cf.state_names == ("x1", "x2") and cf.input_names == ("u1",)
    assert cf.description == "" and cf.why == ("", "")
    assert cf.config.neurons[1] == NeuronConfig(terms=((Factor.u(0),), (Factor.one(),)))


def test_a_full_symmetric_p0_matrix_is_read_and_written() -> None:
    text = SPEC_EXAMPLE.replace("p0 = [1.0, 2.0, 3.0]", "p0 = [[2.0, 0.5, 0.0], [0.5, 2, 0.1], [0.0, 0.1, 3.0]]")
    cf = loads(text)
    assert cf.config.neurons[3].p0.shape == (3, 3)
    assert loads(dumps(cf)) == cf


E = "cfg.toml: "
BAD_FILES = [
    # (replace this, with this, expected message start)
    ("version = 1", "version = 1\nversion = 2", E + "not valid TOML: Cannot overwrite a value"),
    ("[defaults]", "[defaults", E + "not valid TOML"),
    ('format = "pyrhonn-config"\n', "", E + "format: missing"),
    ('format = "pyrhonn-config"', 'format = "pyrhonn-state"', E + "format: expected \"pyrhonn-config\""),
    ("version = 1", "", E + "version: missing"),
    ("version = 1", "version = 2", E + "version: 2 is newer than this pyrhonn reads (version 1); upgrade pyrhonn"),
    ("version = 1", "version = 0", E + "version: 0 is not a valid version"),
    ("version = 1", 'version = "1"', E + "version: expected an integer"),
    ("n_inputs = 1", "n_inputs = 1\nn_input = 1", E + "n_input: unknown key; did you mean 'n_inputs'?"),
    ("n_states = 4\n", "", E + "n_states: missing"),
    ("n_states = 4", "n_states = 4.0", E + "n_states: expected an integer"),
    ("n_states = 4", "n_states = true", E + "n_states: expected an integer"),
    ("n_states = 4", "n_states = 0", E + "n_states: 0 out of range 1..255"),
    ("n_states = 4", "n_states = 3", E + "state_names: expected 3 names"),
    ('dtype = "float64"', 'dtype = "float16"', E + "dtype: expected one of ['float64', 'float32']"),
    ('["x1","x2","x3","x4"]', '["x1","x2","x2","x4"]', E + "state_names[2]: duplicate name 'x2' (also state_names[1])"),
    ('input_names = ["u1"]', 'input_names = ["u2"]', E + "input_names[0]: 'u2' would be confused with the term "
                                                         "variable u2 (terms refer to positions; this entry is u1)"),
    ('input_names = ["u1"]', 'input_names = ["x1"]', E + "input_names[0]: duplicate name 'x1' (also state_names[0])"),
    ('["x1","x2","x3","x4"]', '["a","b","c","a"]', E + "state_names[3]: duplicate name 'a'"),
    ('["x1","x2","x3","x4"]', '["a","b","c","t"]', E + "state_names[3]: 't' is reserved for the time column"),
    ('["x1","x2","x3","x4"]', '["a","b","c","1d"]', E + "state_names[3]: '1d' is not a valid name"),
    ('["x1","x2","x3","x4"]', '["a","b","c","d e"]', E + "state_names[3]: 'd e' is not a valid name"),
    ('["x1","x2","x3","x4"]', '["a","b","c",4]', E + "state_names[3]: expected a string, got a number"),
    ('["x1","x2","x3","x4"]', '"x1"', E + "state_names: expected an array of strings"),
    ('input_names = ["u1"]', 'input_names = []', E + "input_names: expected 1 names"),
    ("x0 = [0.0, 0.0, 0.0, 0.0]", "x0 = [0.0, 0.0, 0.0]", E + "x0: expected 4 numbers"),
    ("x0 = [0.0, 0.0, 0.0, 0.0]", 'x0 = [0.0, "0", 0.0, 0.0]', E + "x0[1]: expected a real number, got str"),
    ("x0 = [0.0, 0.0, 0.0, 0.0]", "x0 = [0.0, true, 0.0, 0.0]", E + "x0[1]: expected a real number, got bool"),
    ("x0 = [0.0, 0.0, 0.0, 0.0]", "x0 = [0.0, nan, 0.0, 0.0]", E + "x0[1]: must be finite"),
    ('description = "..."', "description = 3", E + "description: expected a string, got a number"),
    ("[defaults]", "[defaults]\nw0 = 1.0", E + "defaults.w0: unknown key (allowed here: activation, beta"),
    ('activation = "bipolar"', 'activation = "tanh"', E + "defaults.activation: expected one of ['logistic', 'bipolar']"),
    ("beta = 0.01", "beta = 0", E + "defaults.beta: must be > 0"),
    ("beta = 0.01", "beta = -inf", E + "defaults.beta: must be finite"),
    ("beta = 0.01", "beta = false", E + "defaults.beta: expected a real number, got bool"),
    ("p0 = 1e8", "p0 = 0.0", E + "defaults.p0: must be > 0"),
    ("p0 = 1e8", "p0 = [1.0, 2.0]", E + "defaults.p0: expected shape (6,), got (2,) (inherited by neurons[0], "
                                        "which has 6 terms)"),
    ("p0 = 1e8", "p0 = [1.0, -2.0]", E + "defaults.p0[1]: must be > 0"),
    ("p0 = 1e8", "p0 = []", E + "defaults.p0: expected a non-empty array"),
    ("q = 5e5", "q = -1.0", E + "defaults.q: must be >= 0"),
    ("q = 5e5", 'q = "big"', E + "defaults.q: expected a real number, got str"),
    ("r = 1e4", "r = 0", E + "defaults.r: must be > 0"),
    ("eta = 1.0", "eta = -1", E + "defaults.eta: must be > 0"),
    ('["S(x3)", "S(x1)"]', '["S(x3)", "S(x9)"]', E + "neurons[2].terms[1]: 'S(x9)': state index 9 out of range 1..4"),
    ('["S(x3)", "S(x1)"]', '["S(x3)", "S(x1)*u2"]', E + "neurons[2].terms[1]: 'u2': input index 2 out of range 1..1"),
    ('["S(x3)", "S(x1)"]', '["S(x3)", "S(x1)**2"]', E + "neurons[2].terms[1]: 'S(x1)**2': empty factor"),
    ('["S(x3)", "S(x1)"]', '["S(x3)", 1]', E + "neurons[2].terms[1]: expected a term string"),
    ('["S(x3)", "S(x1)"]', "[]", E + "neurons[2].terms: expected at least one term"),
    ('["S(x3)", "S(x1)"]', '"S(x3)"', E + "neurons[2].terms: expected an array of term strings"),
    ('terms = ["S(x2)", "u1"]', 'term = ["S(x2)", "u1"]', E + "neurons[1].term: unknown key; did you mean 'terms'?"),
    ('terms = ["S(x2)", "u1"]\n', "", E + "neurons[1].terms: missing"),
    ('why = "second neuron"', "why = 2", E + "neurons[1].why: expected a string"),
    ("beta = 0.5", "beta = -0.5", E + "neurons[2].beta: must be > 0"),
    ("p0 = [1.0, 2.0, 3.0]", "p0 = [1.0, 2.0]", E + "neurons[3].p0: expected shape (3,), got (2,)"),
    ("p0 = [1.0, 2.0, 3.0]", "p0 = [[1.0, 2.0], [2.0]]", E + "neurons[3].p0[1]: expected 2 entries like row 0"),
    ("p0 = [1.0, 2.0, 3.0]", "p0 = [1.0, [2.0]]", E + "neurons[3].p0: expected an array of numbers or an array"),
    ("p0 = [1.0, 2.0, 3.0]", "p0 = [[1.0, 0.5, 0], [0, 1.0, 0], [0, 0, 1.0]]", E + "neurons[3].p0: matrix must be "
                                                                                   "symmetric"),
    ("p0 = [1.0, 2.0, 3.0]", "p0 = [[1, 0, 0], [0, 0, 0], [0, 0, 1]]", E + "neurons[3].p0[1][1]: diagonal entries"),
    ("p0 = [1.0, 2.0, 3.0]", "p0 = [[1, 2, 0], [2, 1, 0], [0, 0, 1]]", E + "neurons[3].p0: matrix must be "
                                                                          "positive definite (smallest eigenvalue -1)"),
    ("beta = 0.01", "beta = 1" + "0" * 400, E + "defaults.beta: out of the float64 range"),
    ("x0 = [0.0, 0.0, 0.0, 0.0]", "x0 = [0.0, -1" + "0" * 400 + ", 0.0, 0.0]", E + "x0[1]: out of the float64 range"),
    ('["S(x3)", "S(x1)"]', '["S(x3)", "S(x1)", "S(x3)*1"]', E + "neurons[2].terms[2]: the same product as terms[0]"),
    ('["S(x2)", "u1"]', '["S(x2)*u1", "u1*S(x2)"]', E + "neurons[1].terms[1]: the same product as terms[0]"),
    ('["S(x2)", "u1"]', '["S(x2)^2", "S(x2)*S(x2)"]', E + "neurons[1].terms[1]: the same product as terms[0]"),
    ("q = [0.0, 0.1, 0.2]", "q = [0.0, -0.1, 0.2]", E + "neurons[3].q[1]: must be >= 0"),
    ("w0 = [0.1, -0.2, 0.3]", "w0 = [0.1, -0.2]", E + "neurons[3].w0: expected shape (3,), got (2,)"),
    ("w0 = [0.1, -0.2, 0.3]", "w0 = 0.1", E + "neurons[3].w0: expected an array of numbers"),
    ('activation = "logistic"', "activation = 1", E + "neurons[3].activation: expected one of"),
    ("[[neurons]]\nterms = [\"S(x2)\", \"u1\"]\nwhy = \"second neuron\"\n", "", E + "neurons: expected 4 [[neurons]] "
                                                                                  "tables (one per state"),
]


@pytest.mark.parametrize("old, new, message", BAD_FILES, ids=[m[len(E):][:40] for _, _, m in BAD_FILES])
def test_bad_config_is_rejected_naming_file_and_key(old: str, new: str, message: str) -> None:
    assert old in SPEC_EXAMPLE
    with pytest.raises(ValueError) as info:
        loads(SPEC_EXAMPLE.replace(old, new, 1), source="cfg.toml")
    assert str(info.value).startswith(message), str(info.value)


@pytest.mark.parametrize("text, message", [
    ("neurons = 3", "neurons: expected an array of tables ([[neurons]]), got a number"),
    ("[neurons]\nterms = ['S(x1)']", "neurons: expected an array of tables ([[neurons]]), got a table"),
    ("neurons = [1, 2, 3, 4]", "neurons[0]: expected a table, got a number"),
    ("defaults = 1\n[[neurons]]\nterms = ['1']", "defaults: expected a table"),
])
def test_misshapen_tables_are_rejected(text: str, message: str) -> None:
    head = 'format = "pyrhonn-config"\nversion = 1\nn_states = 4\nn_inputs = 1\n'
    with pytest.raises(ValueError, match=re.escape("cfg.toml: " + message)):
        loads(head + text, source="cfg.toml")


def test_arrays_nested_too_deeply_for_the_parser_are_a_clear_error() -> None:
    with pytest.raises(ValueError, match=re.escape("cfg.toml: not a pyrhonn config: arrays or tables nested too "
                                                   "deeply")):
        loads("a = " + "[" * 5000 + "]" * 5000, source="cfg.toml")


def test_a_byte_order_mark_is_read_as_spreadsheets_and_editors_write_it(tmp_path) -> None:
    path = tmp_path / "bom.toml"
    path.write_bytes(b"\xef\xbb\xbf" + SPEC_EXAMPLE.encode())
    assert load_config(path).config == loads(SPEC_EXAMPLE).config
    assert load_named(str(path)).config == loads(SPEC_EXAMPLE).config


def test_devices_pipes_and_oversized_files_are_refused_unread(tmp_path) -> None:
    import os

    with pytest.raises(ValueError, match=re.escape("/dev/zero: not a regular file")):
        load_config("/dev/zero")  # would be read forever
    fifo = tmp_path / "cfg.toml"
    os.mkfifo(fifo)
    with pytest.raises(ValueError, match="cfg.toml: not a regular file"):
        load_named(str(fifo))  # opening it would block until a writer came
    big = tmp_path / "big.toml"
    big.write_bytes(SPEC_EXAMPLE.encode() + b"#" * (1 << 20))
    with pytest.raises(ValueError, match=r"big.toml: larger than 1,048,576 bytes"):
        load_config(big)


def test_load_config_names_the_file(tmp_path) -> None:
    path = tmp_path / "cfg.toml"
    path.write_text(SPEC_EXAMPLE.replace('"S(x1)", "S(x1)"', '"S(x1)", "S(x9)"').replace(
        '["S(x3)", "S(x1)"]', '["S(x3)", "S(x9)"]'))
    with pytest.raises(ValueError, match=re.escape(f"{path}: neurons[2].terms[1]: 'S(x9)': state index 9 "
                                                   "out of range 1..4")):
        load_config(path)
    path.write_bytes(b'format = "pyrhonn-config"\n# caf\xe9\n')
    with pytest.raises(ValueError, match=re.escape(f"{path}: line 2: not UTF-8 text")):
        load_config(path)
    path.write_bytes(b"\x89PNG\r\n\x1a\n")
    with pytest.raises(ValueError, match=re.escape(f"{path}:")):
        load_config(path)
    with pytest.raises(ValueError, match=re.escape(f"{tmp_path / 'missing.toml'}: No such file or directory")):
        load_config(tmp_path / "missing.toml")


# -- writing and round trips -------------------------------------------------------------------------

_names = st.from_regex(r"[A-Za-z_][A-Za-z0-9_]{0,7}", fullmatch=True).filter(
    lambda s: s != "t" and not re.fullmatch(r"[xu][0-9]+", s))
_text = st.text(alphabet=st.characters(blacklist_categories=("Cs",)), max_size=40)


@settings(max_examples=60, deadline=None)
@given(st.one_of(configs(), configs("float32")))
def test_dumps_then_loads_returns_the_same_config(cfg: IdentifierConfig) -> None:
    back = loads(dumps(cfg))
    assert back.config == cfg
    assert back == ConfigFile.from_config(cfg)


@settings(max_examples=40, deadline=None)
@given(configs(), st.data())
def test_names_description_and_why_texts_round_trip(cfg: IdentifierConfig, data: st.DataObject) -> None:
    n, m = cfg.n_states, cfg.n_inputs
    names = data.draw(st.lists(_names, min_size=n + m, max_size=n + m, unique=True))
    cf = ConfigFile(config=cfg, state_names=tuple(names[:n]), input_names=tuple(names[n:]),
                    description=data.draw(_text), why=tuple(data.draw(_text) for _ in range(n)))
    assert loads(dumps(cf)) == cf


def test_save_config_and_dump_config_write_what_load_config_reads(tmp_path) -> None:
    cf = loads(SPEC_EXAMPLE)
    path = tmp_path / "out.toml"
    save_config(cf, path)
    assert load_config(path) == cf
    buf = io.BytesIO()
    dump_config(cf, buf)
    assert buf.getvalue() == path.read_bytes()
    assert loads(buf.getvalue().decode()) == cf


def test_dumps_puts_shared_tuning_in_defaults_and_the_rest_per_neuron() -> None:
    cfg = presets.example1()
    neurons = list(cfg.neurons)
    neurons[2] = NeuronConfig(terms=neurons[2].terms, activation=Activation.BIPOLAR, beta=0.5, p0=1e8, q=5e5,
                              r=1e4, eta=1.0)
    text = dumps(cfg.replace(neurons=tuple(neurons)))
    assert text.startswith("# pyrhonn identifier config")
    defaults = text[text.index("[defaults]"):text.index("[[neurons]]")]
    for line in ('activation = "bipolar"', "p0 = 100000000.0", "q = 500000.0", "r = 10000.0", "eta = 1.0"):
        assert line in defaults
    assert "beta" not in defaults and text.count("beta = ") == 4 and "beta = 0.5" in text
    assert "[defaults]" not in dumps(loads(SPEC_EXAMPLE))  # nothing shared by all four neurons
    with pytest.raises(ValueError, match="expected a ConfigFile or IdentifierConfig"):
        dumps({"n_states": 1})  # type: ignore[arg-type]


def test_config_file_object_validates_its_fields() -> None:
    cfg = presets.example1()
    with pytest.raises(ValueError, match=r"^state_names: expected 4 names"):
        ConfigFile(config=cfg, state_names=("a",), input_names=("u",))
    with pytest.raises(ValueError, match=r"^why: expected 4 texts"):
        ConfigFile.from_config(cfg, why=("a",))
    with pytest.raises(ValueError, match=r"^state_names: expected a tuple"):
        ConfigFile(config=cfg, state_names=["x1", "x2", "x3", "x4"], input_names=("u",))  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"^config: expected an IdentifierConfig"):
        ConfigFile.from_config(cfg.to_dict())  # type: ignore[arg-type]


# -- shipped configs -----------------------------------------------------------------------------------

def test_example1_is_shipped_and_equals_the_paper_preset() -> None:
    assert "example1" in shipped_names()
    cf = load_shipped("example1")
    per = [((Factor.s(i),), (Factor.s(i), Factor.s(i ^ 1)), (Factor.s(0, delay=1),), (Factor.u(0),))
           for i in range(4)]
    paper = IdentifierConfig.uniform(per, n_states=4, n_inputs=1, activation=Activation.BIPOLAR,
                                     beta=0.01, p0=1e8, q=5e5, r=1e4)
    assert cf.config == paper == presets.example1()
    assert presets.example1("float32") == paper.replace(dtype="float32")
    assert all(cf.why) and cf.description and cf.input_names == ("u",)


@pytest.mark.parametrize("name", shipped_names())
def test_every_shipped_config_loads_and_round_trips(name: str) -> None:
    cf = loads(shipped_text(name), source=name)
    assert loads(dumps(cf)) == cf
    assert load_named(name) == cf


def test_load_named_takes_paths_and_rejects_unknown_names(tmp_path) -> None:
    path = tmp_path / "mine.toml"
    save_config(presets.example1(), path)
    assert load_named(str(path)).config == presets.example1()
    with pytest.raises(ValueError, match=r"unknown config 'nope'; shipped configs: .*example1"):
        load_named("nope")
    with pytest.raises(ValueError, match="unknown config"):
        shipped_text("../config")


def test_covariance_form_and_windup_keys_round_trip_and_default_off() -> None:
    from pyrhonn import CovarianceForm

    text = """format = "pyrhonn-config"
version = 1
n_states = 2
n_inputs = 1
[defaults]
covariance = "ud"
p0 = 2.0
forgetting = 0.99
[[neurons]]
terms = ["S(x1)", "u1"]
p_trace_max = 8.0
reset_after = 3
gate = 9
[[neurons]]
terms = ["x2"]
covariance = "full"
"""
    cf = loads(text)
    a, b = cf.config.neurons
    assert (a.covariance, a.forgetting, a.p_trace_max, a.reset_after, a.gate) == (CovarianceForm.UD, 0.99, 8.0, 3, 9.0)
    assert (b.covariance, b.forgetting, b.p_trace_max, b.reset_after, b.gate) == (CovarianceForm.FULL, 0.99, None, 0,
                                                                                  0.0)
    again = loads(dumps(cf))
    assert again.config == cf.config
    assert "gate = 9.0" in dumps(cf)
    plain = dumps(loads(text.replace('covariance = "ud"\n', "").replace("forgetting = 0.99\n", "")
                        .replace("p_trace_max = 8.0\n", "").replace("reset_after = 3\n", "")
                        .replace('covariance = "full"\n', "").replace("gate = 9\n", "")))
    for key in ("covariance", "forgetting", "p_trace_max", "reset_after", "gate"):
        assert key not in plain  # off: not written, eq. 7 exactly


@pytest.mark.parametrize("line, message", [
    ('covariance = "cholesky"', r"neurons\[0\]\.covariance: expected one of \['full', 'ud'\]"),
    ("forgetting = 0", r"neurons\[0\]\.forgetting: must be > 0"),
    ("forgetting = 1.5", r"neurons\[0\]\.forgetting: lambda must be in \(0, 1\]"),
    ("p_trace_max = 1.0", r"neurons\[0\]\.p_trace_max: 1\.0 is below trace P0 = 2"),
    ("reset_after = -2", r"neurons\[0\]\.reset_after: -2 out of range 0\.\.65535"),
    ("reset_after = 2.5", r"neurons\[0\]\.reset_after: expected an integer"),
    ("gate = -1.0", r"neurons\[0\]\.gate: must be >= 0"),
    ("gate = nan", r"neurons\[0\]\.gate: must be finite"),
    ('gate = "9"', r"neurons\[0\]\.gate: expected a real number"),
])
def test_bad_covariance_and_windup_keys_name_the_key(line: str, message: str) -> None:
    text = f"""format = "pyrhonn-config"
version = 1
n_states = 1
n_inputs = 0
[[neurons]]
terms = ["x1", "1"]
{line}
"""
    with pytest.raises(ValueError, match=message):
        loads(text)
