"""Identifier.run steps an identifier whose neurons share their size and
covariance form with the neurons side by side in the vector lanes
(``rhonn_run_wide``; the extension's AVX-512 or AVX2 copy where the CPU has
one). Each lane does a neuron's scalar operations, so the result is bit for
bit that of stepping the same identifier sample by sample (``rhonn_step``):
predictions, weights, covariances, proofs, health, history, and where a run
stops. Identifier decides by rhonn_wide_pays whether the lanes would be
faster; these tests put every identifier into them. So does Identifier.step
(``rhonn_wide_step``), which keeps the neurons lent to the lanes from one
step to the next and gives them back before any other call; stepped there,
an identifier is bit for bit one stepped by ``rhonn_step``."""
from __future__ import annotations

import dataclasses
import platform
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from source_scripts import load_script  # noqa: E402
from hypothesis import HealthCheck, given, settings, strategies as st

from pyrhonn import CovarianceForm, Factor, Identifier, IdentifierConfig, IdentifierError, NeuronConfig
from pyrhonn.population import run_identifiers
from pyrhonn.simulation import simulate

from strategies import trajectory
from test_identifier_builds import state_of


def uniform_config(n: int, dtype: str, form: CovarianceForm, forgetting: list[float],
                   ceiling: list[bool], reset_after: list[int], seed: int) -> IdentifierConfig:
    """n states, 2 inputs, every neuron 6 terms (its own S(x) round the
    states, a bilinear term, an input, x_i), tuned apart per neuron."""
    rng = np.random.default_rng(seed)
    neurons = []
    for i in range(n):
        terms = [(Factor.s((i + j) % n),) for j in range(min(n, 3))]
        terms.append((Factor.s(i), Factor.s((i + 1) % n)))
        terms.append((Factor.u(i % 2),))
        terms.append((Factor.x(i),))
        while len(terms) < 6:
            terms.append((Factor.u((i + 1) % 2, delay=len(terms) - 5),))
        p0 = float(rng.uniform(1.0, 20.0))
        neurons.append(NeuronConfig(
            terms=tuple(terms), covariance=form, p0=p0, q=float(rng.uniform(1e-4, 1e-2)),
            r=float(rng.uniform(1e-3, 1e-1)), eta=float(rng.uniform(0.3, 1.0)),
            forgetting=forgetting[i], p_trace_max=6 * p0 * 1.5 if ceiling[i] else None,
            reset_after=reset_after[i]))
    return IdentifierConfig(n_states=n, n_inputs=2, neurons=tuple(neurons), dtype=dtype)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(n=st.integers(2, 8), dtype=st.sampled_from(["float64", "float32"]),
       form=st.sampled_from([CovarianceForm.FULL, CovarianceForm.UD]), seed=st.integers(0, 2**16),
       data=st.data())
def test_a_run_in_lanes_equals_the_same_steps_bit_for_bit(n: int, dtype: str, form: CovarianceForm, seed: int,
                                                          data: st.DataObject) -> None:
    forgetting = data.draw(st.lists(st.sampled_from([1.0, 1.0, 0.97, 0.2]), min_size=n, max_size=n))
    ceiling = data.draw(st.lists(st.booleans(), min_size=n, max_size=n))
    reset_after = data.draw(st.lists(st.sampled_from([0, 0, 1, 3]), min_size=n, max_size=n))
    cfg = uniform_config(n, dtype, form, forgetting, ceiling, reset_after, seed)
    X, U, valid = trajectory(seed, 160, n, 2, dropout=data.draw(st.sampled_from([0.0, 0.1])), dtype=dtype)
    lanes, steps = Identifier(cfg), Identifier(cfg)
    lanes._wide = True  # in the lanes even where the scalar run would be faster
    steps._wide = False  # its steps in rhonn_step
    try:
        out = lanes.run(X, U, valid)
        error = None
    except IdentifierError as exc:
        out, error = None, exc
    stepped = []
    for k in range(X.shape[0]):
        try:
            stepped.append(steps.step(X[k], U[k], valid[k]))
        except IdentifierError as exc:
            # the run stops at the same sample for the same reason, and puts
            # everything back as it was before the run
            assert error is not None and (error.status, error.sample) == (exc.status, k)
            steps = Identifier(cfg)
            steps._wide = False
            break
    else:
        assert error is None
        assert out is not None and out.tobytes() == np.array(stepped).tobytes()
    assert state_of(lanes) == state_of(steps)
    proofs = [bool(lanes._net.cert[i][lanes._net.bank[i]]) for i in range(n)]
    assert proofs == [bool(steps._net.cert[i][steps._net.bank[i]]) for i in range(n)]


@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_a_run_in_lanes_continues_from_steps_and_from_another_run(dtype: str) -> None:
    cfg = uniform_config(6, dtype, CovarianceForm.FULL, [1.0] * 6, [False] * 6, [0] * 6, 7)
    X, U, valid = trajectory(3, 300, 6, 2, dropout=0.05, dtype=dtype)
    a, b = Identifier(cfg), Identifier(cfg)
    a._wide, b._wide = True, False
    for k in range(10):
        a.step(X[k], U[k], valid[k])
        b.step(X[k], U[k], valid[k])
    first = a.run(X[10:150], U[10:150], valid[10:150])
    second = a.run(X[150:], U[150:], valid[150:])
    expected = [b.step(X[k], U[k], valid[k]) for k in range(10, 300)]
    assert np.concatenate([first, second]).tobytes() == np.array(expected).tobytes()
    assert state_of(a) == state_of(b)


def test_run_goes_into_the_lanes_where_the_core_says_they_pay() -> None:
    six = uniform_config(6, "float64", CovarianceForm.FULL, [1.0] * 6, [False] * 6, [0] * 6, 1)
    assert Identifier(six)._wide is bool(Identifier(six)._lib.rhonn_wide_pays(Identifier(six)._net))
    mixed = six.replace(neurons=six.neurons[:5] + (dataclasses.replace(six.neurons[5], terms=six.neurons[5].terms[:4],
                                                                       p0=1.0, q=1e-3),))
    assert Identifier(mixed)._wide is False  # sizes differ: never


def test_the_side_by_side_bench_runs_and_its_identifiers_are_valid(capsys: pytest.CaptureFixture[str]) -> None:
    from pathlib import Path

    bench = load_script(Path(__file__).resolve().parent.parent / "bench" / "bench_wide.py", "bench_wide")
    assert bench.main(["--quick"]) == 0
    lines = capsys.readouterr().out.splitlines()
    # a table for run() and one for step(); no timing asserted
    assert len([line for line in lines if line.startswith(("float64", "float32"))]) == 8


def _pair(cfg: IdentifierConfig) -> tuple[Identifier, Identifier]:
    """An identifier stepping in the lanes and its twin stepping in rhonn_step."""
    lanes, single = Identifier(cfg), Identifier(cfg)
    lanes._wide, single._wide = True, False
    return lanes, single


def _lent(ident: Identifier) -> bool:
    cells = dict(zip(ident.step.__code__.co_freevars, ident.step.__closure__ or ()))
    call = cells["call"].cell_contents
    return call.work != ident._ffi.NULL and call.work.holder == call.net


_CALLS = ["weights", "covariances", "healths", "regressors", "prediction", "steps", "set_weights", "learning",
          "run", "reset", "restart", "history"]


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(n=st.integers(2, 8), dtype=st.sampled_from(["float64", "float32"]),
       form=st.sampled_from([CovarianceForm.FULL, CovarianceForm.UD]), seed=st.integers(0, 2**16),
       data=st.data())
def test_steps_in_lanes_between_any_other_calls_equal_single_steps_bit_for_bit(
        n: int, dtype: str, form: CovarianceForm, seed: int, data: st.DataObject) -> None:
    forgetting = data.draw(st.lists(st.sampled_from([1.0, 1.0, 0.97, 0.2]), min_size=n, max_size=n))
    reset_after = data.draw(st.lists(st.sampled_from([0, 0, 1, 3]), min_size=n, max_size=n))
    cfg = uniform_config(n, dtype, form, forgetting, [False] * n, reset_after, seed)
    X, U, valid = trajectory(seed, 120, n, 2, dropout=data.draw(st.sampled_from([0.0, 0.1])), dtype=dtype)
    lanes, single = _pair(cfg)
    k = 0
    while k < X.shape[0]:
        burst = data.draw(st.integers(1, 12))  # steps in a row, then another call
        for x, u, v in zip(X[k:k + burst], U[k:k + burst], valid[k:k + burst]):
            outcome = []
            for ident in (lanes, single):
                try:
                    outcome.append(ident.step(x, u, v).tobytes())
                except IdentifierError as exc:  # a refusal: raised alike, and steps go on
                    outcome.append((exc.status, str(exc)))
            assert outcome[0] == outcome[1]
        k += burst
        call = data.draw(st.sampled_from(_CALLS))
        results = []
        for ident in (lanes, single):
            if call == "set_weights":
                ident.set_weights(0, np.full(6, 0.1, dtype=dtype))
                results.append(None)
            elif call == "learning":
                ident.learning = not ident.learning
                results.append(ident.learning)
            elif call == "run":
                try:
                    results.append(ident.run(X[k:k + 5], U[k:k + 5], valid[k:k + 5]).tobytes())
                except IdentifierError as exc:
                    results.append((exc.status, exc.sample))
            elif call in ("reset", "restart"):
                getattr(ident, call)()
                results.append(None)
            elif call == "healths":
                results.append(ident.healths)
            elif call == "history":
                results.append({key: v.tobytes() for key, v in ident._history().items()})
            else:
                value = getattr(ident, call)
                results.append(repr([np.asarray(a).tobytes() for a in value]) if isinstance(value, list)
                               else np.asarray(value).tobytes())
            if call != "steps":  # a field the lanes keep up to date: read as it is
                assert not _lent(ident)  # every other call gives the lanes back first
        assert results[0] == results[1], call
        k += 5 if call == "run" else 0
    assert state_of(lanes) == state_of(single)


@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_a_population_run_and_a_simulation_start_where_steps_in_lanes_left_off(dtype: str) -> None:
    cfg = uniform_config(6, dtype, CovarianceForm.FULL, [1.0] * 6, [False] * 6, [0] * 6, 11)
    X, U, valid = trajectory(4, 200, 6, 2, dropout=0.05, dtype=dtype)
    a, a_twin = _pair(cfg)
    b, b_twin = _pair(cfg)
    for ident in (a, a_twin, b, b_twin):
        for k in range(40):
            ident.step(X[k], U[k], valid[k])
    assert _lent(a) and _lent(b)
    got = run_identifiers([a, b], X[40:120], U[40:120], valid[40:120])
    want = run_identifiers([a_twin, b_twin], X[40:120], U[40:120], valid[40:120])
    assert np.array(got).tobytes() == np.array(want).tobytes()
    for k in range(120, 130):
        assert a.step(X[k], U[k], valid[k]).tobytes() == a_twin.step(X[k], U[k], valid[k]).tobytes()
    assert _lent(a)
    got_sim = simulate(a, X[130:], U[130:], valid[130:], free_run_from=30)
    want_sim = simulate(a_twin, X[130:], U[130:], valid[130:], free_run_from=30)
    assert got_sim.one_step.tobytes() == want_sim.one_step.tobytes()
    assert np.asarray(got_sim.free_run).tobytes() == np.asarray(want_sim.free_run).tobytes()
    assert state_of(a) == state_of(a_twin) and state_of(b) == state_of(b_twin)


def test_a_saved_and_loaded_identifier_continues_from_steps_in_lanes(tmp_path: Path) -> None:
    cfg = uniform_config(6, "float64", CovarianceForm.UD, [1.0] * 6, [False] * 6, [0] * 6, 5)
    X, U, valid = trajectory(8, 80, 6, 2, dropout=0.1)
    lanes, single = _pair(cfg)
    for k in range(50):
        lanes.step(X[k], U[k], valid[k])
        single.step(X[k], U[k], valid[k])
    lanes.save(tmp_path / "lanes.npz")
    single.save(tmp_path / "single.npz")
    assert (tmp_path / "lanes.npz").read_bytes() == (tmp_path / "single.npz").read_bytes()
    loaded = Identifier.load(tmp_path / "lanes.npz")
    loaded._wide = True
    for k in range(50, 80):
        assert loaded.step(X[k], U[k], valid[k]).tobytes() == single.step(X[k], U[k], valid[k]).tobytes()


def test_steps_go_into_the_lanes_where_run_does() -> None:
    six = uniform_config(6, "float64", CovarianceForm.FULL, [1.0] * 6, [False] * 6, [0] * 6, 1)
    X, U, valid = trajectory(2, 2, 6, 2)
    ident = Identifier(six)
    ident.step(X[0], U[0], valid[0])
    assert _lent(ident) is ident._wide  # the core's word for this CPU, as for run
    mixed = six.replace(neurons=six.neurons[:5] + (dataclasses.replace(six.neurons[5], terms=six.neurons[5].terms[:4],
                                                                       p0=1.0, q=1e-3),))
    ident, single = _pair(mixed)
    ident._wide = True  # even so, sizes that differ never go into the lanes: rhonn_step
    for k in range(2):
        assert ident.step(X[k], U[k], valid[k]).tobytes() == single.step(X[k], U[k], valid[k]).tobytes()
    assert not _lent(ident)


def _expanded_kernel_attributes(*defines: str) -> set[str]:
    """The attributes the lanes' kernels of csrc/src/rhonn_population.c carry with these -D options,
    from the preprocessed source (no compilation)."""
    cc = shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        pytest.skip("no C compiler (cc) on PATH")
    root = Path(__file__).resolve().parent.parent
    out = subprocess.run([cc, "-E", "-P", "-std=c99", *(f"-D{d}" for d in defines), f"-I{root / 'csrc' / 'include'}",
                          str(root / "csrc" / "src" / "rhonn_population.c")], capture_output=True, text=True, check=True).stdout
    return set(re.findall(r"__attribute__\(\((target(?:_clones)?\([^)]*\))\)\)", out))


@pytest.mark.skipif(platform.machine() != "x86_64", reason="the vector units' builds are x86-64 only")
def test_the_lanes_compile_for_one_vector_unit_alone_when_the_bench_asks() -> None:
    # the extension's build clones them for every unit; bench_wide.py's builds name one, and then only that one
    assert _expanded_kernel_attributes("RHONN_TARGET_CLONES=1", "RHONN_SINGLE") == {
        'target_clones("avx512f", "avx2", "default")'}
    assert _expanded_kernel_attributes("RHONN_TARGET_CLONES=1") == {'target_clones("avx512f", "default")'}
    assert _expanded_kernel_attributes('RHONN_POP_TARGET="avx2"', "RHONN_SINGLE") == {'target("avx2")'}
    assert _expanded_kernel_attributes('RHONN_POP_TARGET="avx512f"') == {'target("avx512f")'}
    assert _expanded_kernel_attributes() == set()  # the default: the compiler's baseline (SSE2)


def test_a_vector_unit_build_is_refused_for_a_unit_it_does_not_know() -> None:
    from pyrhonn import _build

    with pytest.raises(ValueError, match="vector_unit: expected 'avx512f', 'avx2' or 'default', got 'neon'"):
        _build.make_ffi("float32", small=True, vector_unit="neon", module="_x")
