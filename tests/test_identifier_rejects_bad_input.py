"""Every bad input through the Python API: a ValueError naming the field, the
identifier's state unchanged, and no crash."""
from __future__ import annotations

import re

import numpy as np
import pytest

from pyrhonn import (Factor, Identifier, IdentifierConfig, IdentifierError, NeuronConfig,
                     capacities, terms)


def make(dtype: str = "float64", **kw) -> IdentifierConfig:
    base = dict(p0=10.0, q=1e-3, r=0.1, beta=0.8)
    base.update(kw)
    return IdentifierConfig.uniform(terms.first_order(3, 2) + terms.delayed_taps(0, [2]) + terms.bias(),
                                    n_states=3, n_inputs=2, dtype=dtype, **base)


def warmed(dtype: str = "float64") -> tuple[Identifier, np.ndarray, np.ndarray]:
    ident = Identifier(make(dtype))
    t = np.arange(50)[:, None] * 0.1
    X = np.hstack([np.sin(t), np.cos(t), np.sin(2 * t)]).astype(dtype)
    U = np.hstack([np.sin(0.3 * t), np.cos(0.7 * t)]).astype(dtype)
    ident.run(X, U)
    return ident, X, U


def snapshot(ident: Identifier) -> tuple:
    return (tuple(w.tobytes() for w in ident.weights), tuple(p.tobytes() for p in ident.covariances),
            ident.prediction.tobytes(), ident.steps, tuple(z.tobytes() for z in ident.regressors))


BAD_STEP_ARGS = [
    ("x", dict(x=[0.1, 0.2, 0.3])),                                 # a list, not an array
    ("x", dict(x=np.zeros(3, dtype=np.float32))),                   # wrong dtype
    ("x", dict(x=np.zeros(4))),                                     # wrong shape
    ("x", dict(x=np.zeros((3, 1)))),
    ("x[1]", dict(x=np.array([0.0, np.nan, 0.0]))),                 # NaN in a measured state
    ("x[2]", dict(x=np.array([0.0, 0.0, np.inf]))),
    ("u", dict(u=np.zeros(3))),
    ("u", dict(u=np.zeros(2, dtype=np.int64))),
    ("u", dict(u=None)),
    ("u[0]", dict(u=np.array([np.nan, 0.0]))),
    ("valid", dict(valid=np.ones(3, dtype=np.uint8))),              # not bool
    ("valid", dict(valid=np.ones(2, dtype=bool))),
]


@pytest.mark.parametrize("field,override", BAD_STEP_ARGS, ids=[f"{f}-{i}" for i, (f, _) in enumerate(BAD_STEP_ARGS)])
def test_bad_step_argument_is_named_and_changes_nothing(field: str, override: dict) -> None:
    ident, X, U = warmed()
    twin, _, _ = warmed()
    before = snapshot(ident)
    args = dict(x=X[7].copy(), u=U[7].copy(), valid=None)
    args.update(override)
    with pytest.raises(ValueError, match="^" + re.escape(field) + "[: ]"):
        ident.step(args["x"], args["u"], args["valid"])
    assert snapshot(ident) == before
    # and it carries on exactly like a twin that never saw the bad call
    np.testing.assert_array_equal(ident.run(X, U), twin.run(X, U))


def test_nan_in_a_dropped_measurement_is_accepted() -> None:
    ident, X, U = warmed()
    x = X[3].copy()
    x[1] = np.nan
    out = ident.step(x, U[3], np.array([True, False, True]))
    assert np.all(np.isfinite(out))


@pytest.mark.parametrize("field,mutate", [
    ("X", lambda X, U, V: (X.astype(np.float32), U, V)),
    ("X", lambda X, U, V: (X[:, :2], U, V)),
    ("X", lambda X, U, V: (X.tolist(), U, V)),
    ("U", lambda X, U, V: (X, U[:-1], V)),
    ("U", lambda X, U, V: (X, None, V)),
    ("valid", lambda X, U, V: (X, U, V.astype(np.int8))),
    ("valid", lambda X, U, V: (X, U, V[:, :1])),
    (r"X\[17, 2\]", lambda X, U, V: (np.where(np.arange(X.shape[0])[:, None] * [0, 0, 1] == 17, np.nan, X), U, V)),
    (r"U\[5, 1\]", lambda X, U, V: (X, np.where(np.arange(U.shape[0])[:, None] * [0, 1] == 5, np.inf, U), V)),
])
def test_bad_run_argument_is_named_and_applies_nothing(field: str, mutate) -> None:
    ident, X, U = warmed()
    before = snapshot(ident)
    V = np.ones(X.shape, dtype=bool)
    Xb, Ub, Vb = mutate(X.copy(), U.copy(), V)
    with pytest.raises(ValueError, match=rf"^{field}"):
        ident.run(Xb, Ub, Vb)
    assert snapshot(ident) == before


def test_numerical_failure_mid_run_rolls_the_whole_run_back() -> None:
    cfg = IdentifierConfig.uniform(((Factor.x(0, power=8),), (Factor.one(),)), n_states=1, n_inputs=0,
                                   p0=1.0, q=0.0, r=1.0, w0=np.array([1.0, 0.0]))
    ident = Identifier(cfg)
    ident.run(np.full((5, 1), 0.5))
    before = snapshot(ident)
    X = np.full((20, 1), 0.5)
    X[12, 0] = 1e50  # x^8 overflows: the prediction cannot be finite
    with pytest.raises(IdentifierError, match=r"neurons\[0\].*at sample 12 \(nothing applied\)") as info:
        ident.run(X)
    assert info.value.status == "RHONN_E_DIVERGED"
    assert snapshot(ident) == before


def _indefinite() -> np.ndarray:
    P = np.eye(7)
    P[0, 1:] = P[1:, 0] = -40.0  # positive diagonal, symmetric, smallest eigenvalue -97
    return P


def test_set_covariance_refuses_an_indefinite_matrix_and_keeps_state() -> None:
    ident, X, U = warmed()
    before = snapshot(ident)
    with pytest.raises(ValueError, match=r"^P: not positive semi-definite \(smallest eigenvalue -97\)"):
        ident.set_covariance(0, _indefinite())
    assert snapshot(ident) == before


def test_the_core_itself_refuses_an_indefinite_covariance_and_keeps_state() -> None:
    ident, X, U = warmed()
    # past the Python check, through the C API itself: the core factorises P (U D U^T) and
    # refuses it unless every pivot is positive at working precision
    before = snapshot(ident)
    packed = np.ascontiguousarray(_indefinite()[np.triu_indices(7)])
    for setter in (ident._lib.rhonn_set_covariance, ident._lib.rhonn_set_factors):
        assert setter(ident._net, 0, ident._ffi.from_buffer("double[]", packed), packed.size) \
            == ident._lib.RHONN_E_VALUE
    assert snapshot(ident) == before
    ident.step(X[3], U[3])


@pytest.mark.parametrize("kwargs,field", [
    (dict(neurons=()), "neurons"),
    (dict(n_states=0), "n_states"),
    (dict(n_states=True), "n_states"),
    (dict(dtype="float16"), "dtype"),
    (dict(dtype=np.dtype("float32")), r"dtype: expected one of \('float64', 'float32'\) as a str, got"),
    (dict(x0=np.zeros(2)), "x0"),
    (dict(x0=np.array([0.0, np.nan, 0.0])), r"x0\[1\]"),
])
def test_invalid_identifier_config_names_the_field(kwargs: dict, field: str) -> None:
    cfg = make()
    data = dict(n_states=cfg.n_states, n_inputs=cfg.n_inputs, neurons=cfg.neurons, dtype=cfg.dtype, x0=None)
    data.update(kwargs)
    with pytest.raises(ValueError, match=rf"^{field}"):
        IdentifierConfig(**data)


@pytest.mark.parametrize("kwargs,field", [
    (dict(terms=()), "terms"),
    (dict(terms=((),)), r"terms\[0\]"),
    (dict(terms=(("S1",),)), r"terms\[0\]\[0\]"),
    (dict(beta=0.0), "beta"),
    (dict(beta=float("nan")), "beta"),
    (dict(r=-1.0), "r"),
    (dict(eta=0), "eta"),
    (dict(p0=np.array([1.0, 0.0])), r"p0\[1\]"),
    (dict(p0=np.array([[1.0, 2.0], [3.0, 1.0]])), "p0"),
    (dict(p0=np.array([[1.0, 2.0], [2.0, 1.0]])), r"p0: matrix must be positive definite"),
    (dict(beta=10**400), "beta: out of the float64 range"),
    (dict(terms=((Factor.s(0),), (Factor.one(), Factor.s(0)))), r"terms\[1\]: the same product as terms\[0\]"),
    (dict(p0=np.ones(3)), "p0"),
    (dict(q=np.array([1.0, -1.0])), r"q\[1\]"),
    (dict(w0=np.ones(5)), "w0"),
    (dict(activation="tanh"), "activation"),
])
def test_invalid_neuron_config_names_the_field(kwargs: dict, field: str) -> None:
    base = dict(terms=((Factor.s(0),), (Factor.one(),)))
    base.update(kwargs)
    with pytest.raises(ValueError, match=rf"^{field}"):
        NeuronConfig(**base)


def test_factor_index_out_of_range_names_the_factor() -> None:
    with pytest.raises(ValueError, match=r"^neurons\[1\]\.terms\[3\]\[0\]\.index: state index 3"):
        IdentifierConfig.uniform([terms.first_order(3), terms.first_order(3) + ((Factor.s(3),),),
                                  terms.first_order(3)], n_states=3, n_inputs=0)
    with pytest.raises(ValueError, match=r"^neurons\[0\]\.terms\[0\]\[0\]\.index: input index 2"):
        IdentifierConfig.uniform(((Factor.u(2),),), n_states=1, n_inputs=2)
    with pytest.raises(ValueError, match=r"^delay"):
        Factor(Factor.one().kind, 0, 1, 1)


@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_config_over_compiled_capacity_is_rejected_by_name(dtype: str) -> None:
    caps = capacities(dtype)
    over = caps["RHONN_MAX_TERMS"] + 1
    taps = caps["RHONN_MAX_DELAY"] + 1
    big = tuple((Factor.s(0, delay=k % taps, power=1 + k // taps),) for k in range(over))
    with pytest.raises(ValueError, match=rf"^neurons\[0\]\.terms: {over} exceeds the compiled capacity RHONN_MAX_TERMS"):
        Identifier(IdentifierConfig.uniform(big, n_states=1, n_inputs=0, dtype=dtype))
    n = caps["RHONN_MAX_STATES"] + 1
    with pytest.raises(ValueError, match=rf"^n_states: {n} exceeds"):
        Identifier(IdentifierConfig.uniform(terms.bias(), n_states=n, n_inputs=0, dtype=dtype))
    deep = ((Factor.s(0, delay=caps["RHONN_MAX_DELAY"] + 1),),)
    with pytest.raises(ValueError, match=rf"^neurons\[0\]\.terms\[0\]\[0\]\.delay: {caps['RHONN_MAX_DELAY'] + 1} exceeds"):
        Identifier(IdentifierConfig.uniform(deep, n_states=1, n_inputs=0, dtype=dtype))
    many = ((Factor.s(0),) * (caps["RHONN_MAX_FACTORS"] + 1),)
    with pytest.raises(ValueError, match=rf"factors\): {caps['RHONN_MAX_FACTORS'] + 1} exceeds"):
        Identifier(IdentifierConfig.uniform(many, n_states=1, n_inputs=0, dtype=dtype))
    high = ((Factor.s(0, power=caps["RHONN_MAX_POWER"] + 1),),)
    with pytest.raises(ValueError, match=rf"power: {caps['RHONN_MAX_POWER'] + 1} exceeds"):
        Identifier(IdentifierConfig.uniform(high, n_states=1, n_inputs=0, dtype=dtype))


def test_setters_reject_bad_values_and_keep_state() -> None:
    ident, _, _ = warmed()
    before = snapshot(ident)
    with pytest.raises(ValueError, match=r"^w\[2\]"):
        ident.set_weights(0, np.array([0, 0, np.nan, 0, 0, 0, 0.0]))
    with pytest.raises(ValueError, match=r"^w"):
        ident.set_weights(0, np.zeros(6))
    with pytest.raises(ValueError, match=r"^neuron"):
        ident.set_weights(3, np.zeros(7))
    with pytest.raises(ValueError, match=r"^P: not symmetric"):
        ident.set_covariance(0, np.triu(np.ones((7, 7))))
    with pytest.raises(ValueError, match=r"^P\[3, 3\]"):
        ident.set_covariance(0, np.diag([1, 1, 1, 0, 1, 1, 1.0]))
    with pytest.raises(ValueError, match=r"^learning"):
        ident.learning = 1  # type: ignore[assignment]
    assert snapshot(ident) == before


def test_non_contiguous_arrays_are_accepted_without_changing_results() -> None:
    ident, X, U = warmed()
    twin, _, _ = warmed()
    Xf = np.asfortranarray(X)
    np.testing.assert_array_equal(ident.run(Xf, U[:, ::1]), twin.run(X, U))
    np.testing.assert_array_equal(ident.step(X[::2][3], U[3]), twin.step(X[6], U[3]))
    w = np.linspace(-1.0, 1.0, 14)
    ident.set_weights(0, w[::2])  # a strided view, as step() takes one
    np.testing.assert_array_equal(ident.get_weights(0), w[::2])


@pytest.mark.parametrize("n_states, message", [(2.0, "expected an integer"), (10**30, "out of range 1..255")])
def test_uniform_names_a_state_count_that_is_not_one(n_states: object, message: str) -> None:
    with pytest.raises(ValueError, match=rf"^n_states: .*{message}"):
        IdentifierConfig.uniform(terms.first_order(2), n_states=n_states, n_inputs=0)  # type: ignore[arg-type]


def test_a_singular_covariance_is_refused_because_the_filter_keeps_p_definite() -> None:
    ident, _, _ = warmed()
    before = snapshot(ident)
    P = np.eye(7)
    P[0, 1] = P[1, 0] = 1.0  # singular (eigenvalue 0): the filter could never learn along (1, -1, 0, ...)
    with pytest.raises(IdentifierError, match=r"^P: not positive definite at float64 precision"):
        ident.set_covariance(0, P)
    assert snapshot(ident) == before
    P[0, 1] = P[1, 0] = 0.999  # nearly singular but definite: accepted as given
    ident.set_covariance(0, P)
    np.testing.assert_array_equal(ident.get_covariance(0), P)


def test_float32_identifier_takes_only_float32_arrays() -> None:
    ident, X, U = warmed("float32")
    with pytest.raises(ValueError, match=r"^x: expected dtype float32, got float64"):
        ident.step(X[0].astype(np.float64), U[0])
    assert ident.step(X[0], U[0]).dtype == np.float32


@pytest.mark.parametrize("kwargs, message", [
    (dict(p0=1e308), r"^neurons\[0\]\.p0: rejected by the C core \(1e\+308 is beyond float32's range"),
    (dict(q=1e39), r"^neurons\[0\]\.q: rejected by the C core \(1e\+39 is beyond float32's range"),
    (dict(r=5e-324), r"^neurons\[0\]\.r: rejected by the C core \(4\.94e-324 is below float32's smallest normal"),
])
def test_a_float32_core_says_which_value_does_not_fit_float32(kwargs: dict, message: str) -> None:
    cfg = IdentifierConfig.uniform(terms.first_order(2, 1), n_states=2, n_inputs=1, dtype="float32", **kwargs)
    Identifier(cfg.replace(dtype="float64"))  # fine in float64
    with pytest.raises(ValueError, match=message):
        Identifier(cfg)


@pytest.mark.parametrize("call, message", [
    (lambda: terms.first_order(-1, 1), r"^states: a count must be in 0\.\.255, got -1"),
    (lambda: terms.first_order(2, True), r"^inputs: expected a count or a list of indices, got True"),
    (lambda: terms.inputs(10**9), r"^inputs: a count must be in 0\.\.255"),
    (lambda: terms.pairwise_products([0, -1]), r"^states: expected non-negative integer indices, got -1"),
])
def test_term_builders_refuse_counts_they_would_silently_empty(call, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        call()


@pytest.mark.parametrize("mutate, message", [
    (lambda d: d.update(x0=[None, 0.0, 0.0]), r"^x0\[0\]: expected a real number, got NoneType None"),
    (lambda d: d["neurons"][0].update(p0=["1"] + [1.0] * 6), r"^neurons\[0\]\.p0\[0\]: expected a real number, got str"),
    (lambda d: d["neurons"][1].update(w0=[True] + [0.0] * 6), r"^neurons\[1\]\.w0\[0\]: expected a real number, got bool"),
    (lambda d: d["neurons"][0].update(p0=[[1.0, 0.0], [0.0]]), r"^neurons\[0\]\.p0"),
    (lambda d: d["neurons"][2].update(beta=0.0), r"^neurons\[2\]\.beta: must be > 0"),
    (lambda d: d.update(x0=[10**400, 0.0, 0.0]), r"^x0: out of the float64 range"),
])
def test_from_dict_names_the_field_and_converts_nothing_silently(mutate, message: str) -> None:
    d = make().to_dict()
    mutate(d)
    with pytest.raises(ValueError, match=message):
        IdentifierConfig.from_dict(d)
    assert IdentifierConfig.from_dict(make().to_dict()).to_dict() == make().to_dict()


def _stuck() -> Identifier:
    """An identifier whose stored regressor z(k) = 1e160 makes every next update overflow."""
    ident = Identifier(IdentifierConfig.uniform(((Factor.x(0),),), n_states=1, n_inputs=0))
    ident.learning = False
    ident.step(np.array([0.1]))
    ident.step(np.array([1e160]))  # predicting only: z(k) = 1e160 is stored for the next update
    ident.learning = True
    return ident


def test_a_failure_of_the_stored_state_repeats_until_the_documented_recoveries() -> None:
    ident = _stuck()
    for _ in range(3):  # z^T P z = 1e320 overflows for every new sample: nothing is committed, so it repeats
        with pytest.raises(IdentifierError, match="innovation"):
            ident.step(np.array([0.1]))
    ident.learning = False  # recovery 1: predictions go on from the frozen weights
    ident.step(np.array([0.1]))
    ident.learning = True
    ident.step(np.array([0.1]))  # the stored regressor is ordinary again: learning resumes
    ident = _stuck()
    with pytest.raises(IdentifierError):
        ident.step(np.array([0.1]))
    ident.reset()  # recovery 2
    ident.step(np.array([0.1]))
    ident.step(np.array([0.2]))
