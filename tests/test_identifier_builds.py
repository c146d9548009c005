"""The two builds of the core per precision (pyrhonn._build: a small one with
the firmware default capacities, a large one for structure search): an
identifier runs on the smallest that holds its config, and which one runs
changes no bit of any result. Also what run() and step() rely on to be cheap:
the rollback checkpoint leaves out only what running never writes, and
step()'s fast path takes exactly the arguments the checked path takes."""
from __future__ import annotations

import dataclasses
import gc
import weakref
from contextlib import contextmanager
from typing import Iterator

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from pyrhonn import CovarianceForm, Factor, Identifier, IdentifierConfig, IdentifierError, terms
from pyrhonn import identifier as identifier_module
from pyrhonn.cli import main
from pyrhonn.configfile import load_shipped

from strategies import configs, trajectory

SMALL = {"float64": identifier_module._rhonn_small_f64, "float32": identifier_module._rhonn_small_f32}
LARGE = {"float64": identifier_module._rhonn_f64, "float32": identifier_module._rhonn_f32}


@contextmanager
def only_the_large_build(dtype: str) -> Iterator[None]:
    """Identifiers made inside run on the large build, whatever their size."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setitem(identifier_module._BUILDS, dtype, (LARGE[dtype],))
        yield


def state_of(ident: Identifier) -> dict[str, object]:
    """Everything observable of an identifier's state, as exact bytes."""
    return {
        "weights": [w.tobytes() for w in ident.weights],
        "covariances": [p.tobytes() for p in ident.covariances],
        "factors": [ident._stored_covariance(i).tobytes() for i in range(ident.n_states)],
        "regressors": [z.tobytes() for z in ident.regressors],
        "prediction": ident.prediction.tobytes(),
        "history": {k: v.tobytes() for k, v in ident._history().items()},
        "healths": ident.healths,
        "steps": ident.steps,
    }


def drive(ident: Identifier, X: np.ndarray, U: np.ndarray, valid: np.ndarray) -> list[object]:
    """A run, then steps with learning toggled and a restart; every result or
    error status (with its sample) in order."""
    cfg = ident.config
    u_of = (lambda k: U[k]) if cfg.n_inputs else (lambda k: None)
    half = X.shape[0] // 2
    outcomes: list[object] = []
    try:
        outcomes.append(ident.run(X[:half], U[:half] if cfg.n_inputs else None, valid[:half]).tobytes())
    except IdentifierError as exc:
        outcomes.append((exc.status, exc.sample))
    for k in range(half, X.shape[0]):
        if k % 37 == 0:
            ident.learning = not ident.learning
        if k % 101 == 0:
            ident.restart()
        try:
            outcomes.append(ident.step(X[k], u_of(k), valid[k]).tobytes())
        except IdentifierError as exc:
            outcomes.append((exc.status, k))
    return outcomes


@st.composite
def configs_with_forms(draw: st.DrawFn, dtype: str) -> IdentifierConfig:
    """strategies.configs with each neuron's covariance form and forgetting drawn too."""
    cfg = draw(configs(dtype))
    neurons = tuple(dataclasses.replace(nr, covariance=draw(st.sampled_from(list(CovarianceForm))),
                                        forgetting=draw(st.sampled_from([1.0, 0.999])))
                    for nr in cfg.neurons)
    return cfg.replace(neurons=neurons)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data(), dtype=st.sampled_from(["float64", "float32"]), seed=st.integers(0, 2**32 - 1),
       dropout=st.sampled_from([0.0, 0.2]))
def test_small_and_large_builds_agree_bit_for_bit(data: st.DataObject, dtype: str, seed: int,
                                                  dropout: float) -> None:
    cfg = data.draw(configs_with_forms(dtype))
    X, U, valid = trajectory(seed, 600, cfg.n_states, cfg.n_inputs, dropout, dtype)
    small = Identifier(cfg)
    with only_the_large_build(dtype):
        large = Identifier(cfg)
    assert small._build is SMALL[dtype] and large._build is LARGE[dtype]
    assert drive(small, X, U, valid) == drive(large, X, U, valid)
    assert state_of(small) == state_of(large)


def test_an_identifier_runs_on_the_smallest_build_that_holds_its_config() -> None:
    example1 = load_shipped("example1").config
    lim = load_shipped("firmware-lim").config
    for cfg in (example1, example1.replace(dtype="float32"), lim):
        assert Identifier(cfg)._build is SMALL[cfg.dtype]
    small_caps = identifier_module.build_capacities(SMALL["float64"])
    deep = IdentifierConfig.uniform(((Factor.s(0, delay=small_caps["RHONN_MAX_DELAY"] + 1),),), n_states=1,
                                    n_inputs=0)
    many = IdentifierConfig.uniform(tuple((Factor.x(0, power=p),) for p in range(1, 9))
                                    + tuple((Factor.s(0, power=p),) for p in range(1, 9)) + ((Factor.one(),),),
                                    n_states=1, n_inputs=0)
    assert many.neurons[0].n_terms == small_caps["RHONN_MAX_TERMS"] + 1
    for cfg in (deep, many):
        ident = Identifier(cfg)
        assert ident._build is LARGE["float64"]
        assert ident._ffi.sizeof("rhonn_t") > 20 * SMALL["float64"].ffi.sizeof("rhonn_t")
        ident.run(np.linspace(-1.0, 1.0, 40)[:, None])  # and it runs there


def test_info_lists_both_builds_of_each_precision(capsys: pytest.CaptureFixture[str]) -> None:
    import json

    assert main(["info", "--json"]) == 0
    builds = {b["module"]: b for b in json.loads(capsys.readouterr().out)["builds"]}
    assert set(builds) == {m.__name__ for m in (*SMALL.values(), *LARGE.values())}
    for dtype in ("float64", "float32"):
        small, large = builds[SMALL[dtype].__name__], builds[LARGE[dtype].__name__]
        assert small["dtype"] == large["dtype"] == dtype
        assert small["sizeof_rhonn_t"] < large["sizeof_rhonn_t"]
        assert small["unrolled_kernels"]
        assert all(small["capacities"][k] <= large["capacities"][k] for k in small["capacities"])


@pytest.mark.parametrize("large", [False, True], ids=["small build", "large build"])
def test_running_never_writes_the_part_of_the_struct_the_checkpoint_leaves_out(large: bool) -> None:
    # The rollback of run() saves rhonn_t from n_groups on: the configuration before it is
    # written by rhonn_init alone. Steps, runs, failures, restarts and learning switches
    # must leave it as it was, byte for byte.
    cfg = load_shipped("example1").config
    if large:
        with only_the_large_build("float64"):
            ident = Identifier(cfg)
    else:
        ident = Identifier(cfg)
    head = ident._mutable[0]
    before = bytes(ident._ffi.buffer(ident._net))[:head]
    X, U, valid = trajectory(3, 400, 4, 1, 0.2)
    drive(ident, X, U, valid)
    ident.set_weights(0, np.full(cfg.neurons[0].n_terms, 1e308))  # the next prediction overflows
    with pytest.raises(IdentifierError, match=r"^neurons\[0\]: weights or prediction would not be finite"):
        ident.run(X, U, valid)
    assert bytes(ident._ffi.buffer(ident._net))[:head] == before


def test_a_failing_run_puts_back_every_byte_of_the_state() -> None:
    cfg = IdentifierConfig.uniform(((Factor.x(0, power=8),), (Factor.one(),)), n_states=1, n_inputs=0,
                                   p0=1.0, q=0.0, r=1.0, w0=np.array([1.0, 0.0]))
    ident = Identifier(cfg)
    ident.run(np.full((5, 1), 0.5))
    before = bytes(ident._ffi.buffer(ident._net))
    X = np.full((20, 1), 0.5)
    X[12, 0] = 1e50
    with pytest.raises(IdentifierError, match="at sample 12"):
        ident.run(X)
    assert bytes(ident._ffi.buffer(ident._net)) == before


def _lanes_config() -> IdentifierConfig:
    """6 states, 2 inputs, every neuron 8 terms in the full form: an
    identifier whose steps can run in the vector lanes."""
    per = [terms.first_order(6) + ((Factor.s(i), Factor.s((i + 1) % 6)),) + terms.inputs([i % 2])
           for i in range(6)]
    return IdentifierConfig.uniform(per, n_states=6, n_inputs=2, beta=1.0, p0=10.0, q=1e-3, r=1e-2)


def _warm(lanes: bool = False, twin: bool = False) -> tuple[Identifier, np.ndarray, np.ndarray, np.ndarray]:
    """An identifier after a run of 30 samples: the firmware's LIM (its
    neurons differ in size: steps in rhonn_step), or with ``lanes`` one whose
    steps run in the vector lanes (rhonn_wide_step) -- as ``twin``, the same
    identifier stepping in rhonn_step."""
    X, U, valid = trajectory(5, 60, 6, 2, 0.2)
    if lanes:
        ident = Identifier(_lanes_config())
        ident._wide = not twin
    else:
        ident = Identifier(load_shipped("firmware-lim").config.replace(dtype="float64"))
    ident.run(X[:30], U[:30], valid[:30])
    return ident, X, U, valid


#: Where the step-row tests run: rhonn_step, and steps lent to the vector lanes.
STEPPING = pytest.mark.parametrize("lanes", [False, True], ids=["rhonn_step", "lanes"])


@STEPPING
def test_step_takes_strided_and_odd_dtype_arguments_as_the_contiguous_ones(lanes: bool) -> None:
    ident, X, U, valid = _warm(lanes)
    twin, _, _, _ = _warm(lanes, twin=True)
    f8 = np.dtype(np.float64, metadata={"unit": "V"})  # equal to float64, another dtype object
    assert f8 == np.float64 and f8 is not np.dtype(np.float64)
    for k in range(30, 60):
        x, u, v = X[k], U[k], valid[k]
        wide_u = np.repeat(u, 2)[::2]
        wide_v = np.repeat(v, 2)[::2]
        measured = np.where(v, x, 0.0)
        got, want = [(ident.step(np.asarray(x, dtype=f8), u, v), twin.step(x, u, v)),
                     (ident.step(x, wide_u, v), twin.step(x, u, v)),
                     (ident.step(x, u, wide_v), twin.step(x, u, v)),
                     (ident.step(measured, wide_u), twin.step(measured, u))][k % 4]
        np.testing.assert_array_equal(got, want)
    assert state_of(ident) == state_of(twin)


@STEPPING
def test_the_class_step_method_steps_as_the_identifier_s_own_fast_step(lanes: bool) -> None:
    ident, X, U, valid = _warm(lanes)
    twin, _, _, _ = _warm(lanes, twin=True)
    assert ident.step is not Identifier.step and ident.step.__doc__ == Identifier.step.__doc__
    for k in range(30, 60):
        np.testing.assert_array_equal(Identifier.step(ident, X[k], U[k], valid[k]), twin.step(X[k], U[k], valid[k]))
    assert state_of(ident) == state_of(twin)


def test_a_subclass_that_overrides_step_keeps_its_own() -> None:
    class Counting(Identifier):
        calls = 0

        def step(self, x, u=None, valid=None):  # type: ignore[no-untyped-def]
            Counting.calls += 1
            return super().step(x, u, valid)

    ident = Counting(load_shipped("firmware-lim").config.replace(dtype="float64"))
    X, U, valid = trajectory(5, 3, 6, 2)
    for k in range(3):
        ident.step(X[k], U[k], valid[k])
    assert Counting.calls == 3 and ident.steps == 3


@STEPPING
def test_a_dropped_identifier_is_freed_at_once_though_its_step_is_bound(lanes: bool) -> None:
    ident, X, U, valid = _warm(lanes)
    ref = weakref.ref(ident)
    gc.disable()
    try:
        del ident
        assert ref() is None  # no reference cycle through the bound step
    finally:
        gc.enable()


@STEPPING
def test_a_step_kept_beyond_its_identifier_says_so_when_it_needs_it(lanes: bool) -> None:
    ident, X, U, valid = _warm(lanes)
    twin, _, _, _ = _warm(lanes, twin=True)
    step = ident.step
    np.testing.assert_array_equal(step(X[30], U[30], valid[30]), twin.step(X[30], U[30], valid[30]))
    del ident
    gc.collect()
    for k in range(31, 41):  # the state it steps (and its lanes) are its own
        np.testing.assert_array_equal(step(X[k], U[k], valid[k]), twin.step(X[k], U[k], valid[k]))
    with pytest.raises(ReferenceError, match="^step: its Identifier no longer exists"):
        step(X[40].astype(np.float32), U[40], valid[40])  # the checked path needs the identifier
    bad = X[41].copy()
    bad[0] = np.nan
    with pytest.raises(ReferenceError, match="^step: its Identifier no longer exists"):
        step(bad, U[41])  # and so does the error of a refused step
    np.testing.assert_array_equal(step(X[41], U[41], valid[41]), twin.step(X[41], U[41], valid[41]))


@STEPPING
def test_each_prediction_step_returns_is_its_own_array_and_keeps_its_values(lanes: bool) -> None:
    ident, X, U, valid = _warm(lanes)
    twin, _, _, _ = _warm(lanes, twin=True)
    rows = identifier_module._STEP_ROWS
    T = 3 * rows + 5  # past the end of several blocks of rows
    Xl, Ul, Vl = (np.resize(a, (T,) + a.shape[1:]) for a in (X, U, valid))
    got = [ident.step(Xl[k], Ul[k], Vl[k]) for k in range(T)]
    want = twin.run(Xl, Ul, Vl)
    np.testing.assert_array_equal(np.stack(got), want)
    assert all(g.flags.writeable and g.flags.c_contiguous and g.shape == (6,) for g in got)
    assert not any(np.shares_memory(a, b) for a, b in zip(got, got[1:]))
    for g in got[::2]:  # a caller writing into one prediction touches no other
        g[:] = np.nan
    np.testing.assert_array_equal(np.stack(got[1::2]), want[1::2])
    np.testing.assert_array_equal(ident.step(X[0], U[0], valid[0]), twin.step(X[0], U[0], valid[0]))


@STEPPING
def test_a_refused_step_takes_no_row_from_the_steps_after_it(lanes: bool) -> None:
    ident, X, U, valid = _warm(lanes)
    twin, _, _, _ = _warm(lanes, twin=True)
    rows = identifier_module._STEP_ROWS
    bad = X[0].copy()
    bad[0] = np.nan
    got, want = [], []
    # refused before the first block exists, at a block's end, and mid-block
    refuse_before = {0, rows, rows + 3}
    for k in range(2 * rows + 2):
        if k in refuse_before:
            with pytest.raises(IdentifierError):
                ident.step(bad, U[0], np.ones(6, dtype=bool))
        x, u, v = X[k % 60], U[k % 60], valid[k % 60]
        got.append(ident.step(x, u, v))
        want.append(twin.step(x, u, v))
    np.testing.assert_array_equal(np.stack(got), np.stack(want))
    assert state_of(ident) == state_of(twin)


@STEPPING
def test_a_step_interrupted_after_its_c_call_leaves_the_later_predictions_right(lanes: bool) -> None:
    # A KeyboardInterrupt can land right after the C call returns, before
    # the prediction is handed out: that step happened (the twin makes it
    # too), and every later step() returns its own prediction.
    ident, X, U, valid = _warm(lanes)
    twin, _, _, _ = _warm(lanes, twin=True)
    cells = dict(zip(ident.step.__code__.co_freevars, ident.step.__closure__))
    c_step = cells["c_step"].cell_contents

    def interrupted(*args: object) -> int:
        row = c_step(*args)
        if row >= 0:  # stepped (not the call that finds no block yet)
            raise KeyboardInterrupt
        return row

    rows = identifier_module._STEP_ROWS
    got, want = [], []
    for k in range(2 * rows + 3):
        x, u, v = X[k % 60], U[k % 60], valid[k % 60]
        if k in (0, 5, rows - 1, rows + 7):
            cells["c_step"].cell_contents = interrupted
            with pytest.raises(KeyboardInterrupt):
                ident.step(x, u, v)
            cells["c_step"].cell_contents = c_step
            twin.step(x, u, v)
            continue
        got.append(ident.step(x, u, v))
        want.append(twin.step(x, u, v))
    np.testing.assert_array_equal(np.stack(got), np.stack(want))
    assert state_of(ident) == state_of(twin)
