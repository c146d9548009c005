"""run_population / run_identifiers: a population of one structure over one
trajectory in one C call, each member bit for bit what Identifier.run gives it
alone (predictions, and the state it is left in), in float64 and float32; and
the refusals that name the offending config and field."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from pyrhonn import Activation, Identifier, IdentifierConfig, IdentifierError
from pyrhonn.config import CovarianceForm
from pyrhonn.configfile import load_shipped
from pyrhonn.population import max_population, run_identifiers, run_population, structure_key

DTYPES = ("float64", "float32")


def trajectory(cfg: IdentifierConfig, T: int = 600, dropouts: bool = True, seed: int = 3
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A smooth exciting trajectory of cfg's size; with dropouts, bursts of
    samples in which states 0 and the last are not measured (NaN)."""
    rng = np.random.default_rng(seed)
    n, m = cfg.n_states, cfg.n_inputs
    t = np.arange(T)[:, None] * 0.02
    X = 0.6 * np.sin(t * (0.5 + 0.37 * np.arange(n)) + rng.uniform(0, 3, n)) + 0.05 * rng.standard_normal((T, n))
    U = 0.8 * np.cos(t * (0.9 + 0.21 * np.arange(max(m, 1))))[:, :m]
    valid = np.ones((T, n), dtype=bool)
    if dropouts:
        for start in range(150, T - 10, 97):
            valid[start:start + 4, 0] = False
            valid[start + 2:start + 5, n - 1] = False
    X = np.where(valid, X, np.nan)
    return (np.ascontiguousarray(X.astype(cfg.dtype)), np.ascontiguousarray(U.astype(cfg.dtype)), valid)


def variants(base: IdentifierConfig, count: int, *, betas: bool = False) -> list[IdentifierConfig]:
    """Tunings of one structure: P0, Q, R, eta scaled per member; with betas,
    the slope too; every third member with forgetting and a trace ceiling,
    and reset_after."""
    out = []
    for k in range(count):
        f = 1.0 + 0.3 * k
        neurons = []
        for nr in base.neurons:
            nr = replace(nr, p0=nr.p0_matrix() * f, q=nr.q_diagonal() * f * f, r=nr.r * (2.0 - 0.1 * k),
                         eta=nr.eta / f, beta=nr.beta * (f if betas else 1.0))
            if k % 3 == 2:
                nr = replace(nr, forgetting=0.995, p_trace_max=float(np.trace(nr.p0_matrix())) * 2.0, reset_after=2)
            neurons.append(nr)
        out.append(base.replace(neurons=tuple(neurons)))
    return out


def same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


def state(ident: Identifier) -> list[bytes]:
    """Everything the identifier exposes, as bytes: prediction, weights,
    covariances as stored, regressors, history, steps, health."""
    out = [ident.prediction.tobytes(), repr(ident.steps).encode()]
    out += [w.tobytes() for w in ident.weights] + [z.tobytes() for z in ident.regressors]
    out += [ident._stored_covariance(i).tobytes() for i in range(ident.n_states)]
    out += [a.tobytes() for a in ident._history().values()]
    out += [repr(h).encode() for h in ident.healths]
    return out


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("name, betas", [("firmware-lim", False), ("example3", False), ("example1", True)])
def test_each_member_equals_its_single_run_bit_for_bit(name: str, betas: bool, dtype: str) -> None:
    base = load_shipped(name).config.replace(dtype=dtype)
    configs = variants(base, max_population(dtype), betas=betas)
    X, U, valid = trajectory(base)
    got = run_population(configs, X, U, valid)
    assert len(got) == len(configs)
    for k, cfg in enumerate(configs):
        want = Identifier(cfg).run(X, U, valid)
        assert same_bits(got[k], want), f"configs[{k}] ({name}, {dtype}): predictions differ"


@pytest.mark.parametrize("dtype", DTYPES)
def test_identifiers_continue_from_their_state_and_end_in_the_single_runs_state(dtype: str) -> None:
    base = load_shipped("firmware-lim").config.replace(dtype=dtype)
    configs = variants(base, 5)
    X, U, valid = trajectory(base, T=500)
    members, alone = [Identifier(c) for c in configs], [Identifier(c) for c in configs]
    for k in range(len(configs)):  # members start from different states
        for ident in (members[k], alone[k]):
            ident.run(X[:k * 7], U[:k * 7], valid[:k * 7])
    got = run_identifiers(members, X, U, valid)
    for k in range(len(configs)):
        want = alone[k].run(X, U, valid)
        assert same_bits(got[k], want), f"member {k}: predictions differ"
        assert state(members[k]) == state(alone[k]), f"member {k}: final state differs"
        assert same_bits(members[k].step(X[5], U[5]), alone[k].step(X[5], U[5]))


@pytest.mark.parametrize("dtype", DTYPES)
def test_members_with_and_without_innovation_gates_equal_their_single_runs(dtype: str) -> None:
    """Gates run in the lanes, member by member: a population mixing members
    without a gate, with one on every neuron, on the outlier's neuron only,
    and one too high to trip, continuing from their own states, gives each
    member its single run bit for bit (predictions, state, health with the
    gated counts), and the outlier trips exactly the low enough gates."""
    base = load_shipped("firmware-lim").config.replace(dtype=dtype)
    configs = variants(base, 5)

    def gated(cfg: IdentifierConfig, gate: float, only: int | None = None) -> IdentifierConfig:
        return cfg.replace(neurons=tuple(replace(nr, gate=gate) if only in (None, i) else nr
                                         for i, nr in enumerate(cfg.neurons)))

    configs[1] = gated(configs[1], 4.0)
    configs[2] = gated(configs[2], 9.0, only=1)
    configs[3] = gated(configs[3], 1e30)
    X, U, valid = trajectory(base, T=400)
    X = X.copy()
    X[200, 1] += np.asarray(50.0, dtype=dtype)  # an outlier in state 1
    members, alone = [Identifier(c) for c in configs], [Identifier(c) for c in configs]
    for k, (a, b) in enumerate(zip(members, alone)):  # each from a state of its own
        a.run(X[:k + 1], U[:k + 1])
        b.run(X[:k + 1], U[:k + 1])
    got = run_identifiers(members, X, U, valid)
    for k in range(len(configs)):
        assert same_bits(got[k], alone[k].run(X, U, valid)), f"member {k}: predictions differ"
        assert state(members[k]) == state(alone[k]), f"member {k}: final state differs"
    gates = [[h.gated for h in m.healths] for m in members]
    assert sum(gates[1]) > 0 and gates[2][1] > 0
    assert sum(gates[2]) == gates[2][1]  # only its gated neuron
    assert sum(gates[0]) == sum(gates[3]) == sum(gates[4]) == 0


def test_one_config_runs_as_a_population_of_one() -> None:
    cfg = load_shipped("example1").config
    X, U, valid = trajectory(cfg, T=200)
    (got,) = run_population([cfg], X, U, valid)
    assert same_bits(got, Identifier(cfg).run(X, U, valid))


def test_a_member_that_stops_raises_naming_it_and_changes_nothing() -> None:
    base = load_shipped("example1").config
    X, U, valid = trajectory(base, T=300, dropouts=False)
    # a learning rate that makes the first weight update overflow
    bad = base.replace(neurons=(replace(base.neurons[0], eta=1e300),) + base.neurons[1:])
    with pytest.raises(IdentifierError):
        Identifier(bad).run(X, U, valid)
    members = [Identifier(base), Identifier(bad), Identifier(base)]
    before = [state(i) for i in members]
    with pytest.raises(IdentifierError, match=r"^identifiers\[1\]: neurons\[0\]: .*\[RHONN_E_") as exc:
        run_identifiers(members, X, U, valid)
    assert exc.value.status != "RHONN_OK"
    assert [state(i) for i in members] == before
    with pytest.raises(IdentifierError, match=r"^configs\[1\]: neurons\[0\]"):
        run_population([base, bad], X, U, valid)


def test_outcomes_give_each_member_its_run_or_its_own_error() -> None:
    from pyrhonn.population import run_identifiers_outcomes

    base = load_shipped("example1").config
    X, U, valid = trajectory(base, T=300, dropouts=False)
    bad = base.replace(neurons=(replace(base.neurons[0], eta=1e300),) + base.neurons[1:])
    slow = base.replace(neurons=tuple(replace(nr, eta=0.5) for nr in base.neurons))
    with pytest.raises(IdentifierError) as alone:
        Identifier(bad).run(X, U, valid)
    members = [Identifier(base), Identifier(bad), Identifier(slow)]
    before = state(members[1])
    got = run_identifiers_outcomes(members, X, U, valid)
    assert state(members[1]) == before  # the stopped member is as it was
    assert same_bits(got[0], Identifier(base).run(X, U, valid))
    assert same_bits(got[2], Identifier(slow).run(X, U, valid))
    assert isinstance(got[1], IdentifierError)
    assert str(got[1]) == str(alone.value) and got[1].sample == alone.value.sample
    other = base.replace(neurons=(replace(base.neurons[0], covariance=CovarianceForm.UD),) + base.neurons[1:])
    with pytest.raises(ValueError, match=r"identifiers\[1\]\.neurons\[0\]\.covariance: differs"):
        run_identifiers_outcomes([Identifier(base), Identifier(other)], X, U, valid)


def test_structures_that_differ_are_refused_naming_the_config_and_field() -> None:
    base = load_shipped("firmware-lim").config
    X, U, valid = trajectory(base, T=20)
    other_terms = base.replace(neurons=base.neurons[:3] + (replace(base.neurons[3], terms=base.neurons[2].terms),)
                               + base.neurons[4:])
    with pytest.raises(ValueError, match=r"^configs\[1\]\.neurons\[3\]\.terms\[0\]: differs from configs\[0\]"):
        run_population([base, other_terms], X, U, valid)
    other_form = base.replace(neurons=(replace(base.neurons[0], covariance=CovarianceForm.FULL),) + base.neurons[1:])
    with pytest.raises(ValueError, match=r"^configs\[2\]\.neurons\[0\]\.covariance: differs"):
        run_population([base, base, other_form], X, U, valid)
    other_act = base.replace(neurons=base.neurons[:1] + (replace(base.neurons[1], activation=Activation.BIPOLAR),)
                             + base.neurons[2:])
    with pytest.raises(ValueError, match=r"^configs\[1\]\.neurons\[1\]\.activation: differs"):
        run_population([base, other_act], X, U, valid)
    ex1 = load_shipped("example1").config.replace(dtype=base.dtype)
    with pytest.raises(ValueError, match=r"^configs\[1\]\.n_states: differs"):
        run_population([base, ex1], X, U, valid)
    with pytest.raises(ValueError, match=r"^configs\[1\]\.dtype: 'float64' differs from configs\[0\]\.dtype 'float32'"):
        run_population([base, base.replace(dtype="float64")], X, U, valid)


def test_structure_key_is_equal_exactly_for_configs_one_population_runs() -> None:
    base = load_shipped("firmware-lim").config
    X, U, valid = trajectory(base, T=20)
    tuned = base.replace(neurons=tuple(replace(nr, eta=0.5, r=nr.r * 3.0, beta=2.0) for nr in base.neurons))
    variants = [
        tuned,
        base.replace(neurons=base.neurons[:3] + (replace(base.neurons[3], terms=base.neurons[2].terms),)
                     + base.neurons[4:]),
        base.replace(neurons=(replace(base.neurons[0], covariance=CovarianceForm.FULL),) + base.neurons[1:]),
        base.replace(neurons=base.neurons[:1] + (replace(base.neurons[1], activation=Activation.BIPOLAR),)
                     + base.neurons[2:]),
        base.replace(dtype="float64"),
    ]
    for other in variants:
        try:
            run_population([base, other], X, U, valid)
            runs = True
        except ValueError:
            runs = False
        assert (structure_key(other) == structure_key(base)) == runs
    assert structure_key(tuned) == structure_key(base) and hash(structure_key(base)) == hash(structure_key(tuned))
    with pytest.raises(ValueError, match=r"^config: expected an IdentifierConfig, got dict"):
        structure_key({})  # type: ignore[arg-type]


def test_bad_arguments_are_refused_naming_them() -> None:
    cfg = load_shipped("example1").config
    X, U, valid = trajectory(cfg, T=20, dropouts=False)
    limit = max_population("float64")
    with pytest.raises(ValueError, match=rf"^configs: expected 1\.\.{limit} members"):
        run_population([cfg] * (limit + 1), X, U)
    with pytest.raises(ValueError, match=r"^configs: expected at least one"):
        run_population([], X, U)
    with pytest.raises(ValueError, match=r"^configs: expected a sequence"):
        run_population(cfg, X, U)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"^configs\[1\]: expected an IdentifierConfig"):
        run_population([cfg, "example1"], X, U)  # type: ignore[list-item]
    with pytest.raises(ValueError, match=r"^X: expected dtype float64, got float32"):
        run_population([cfg, cfg], X.astype(np.float32), U)
    with pytest.raises(ValueError, match=r"^U: expected shape"):
        run_population([cfg, cfg], X, U[:5])
    Xn = X.copy()
    Xn[4, 2] = np.nan
    with pytest.raises(ValueError, match=r"^X\[4, 2\]: not finite"):
        run_population([cfg, cfg], Xn, U)
    ident = Identifier(cfg)
    with pytest.raises(ValueError, match=r"^identifiers: the same Identifier is given twice"):
        run_identifiers([ident, ident], X, U)
    # a config the float32 core refuses (beta rounds to 0)
    cfg32 = cfg.replace(dtype="float32")
    tiny_beta = cfg32.replace(neurons=(replace(cfg32.neurons[0], beta=1e-50),) + cfg32.neurons[1:])
    with pytest.raises(ValueError, match=r"^configs\[1\]\.neurons\[0\]\.beta: rejected by the C core"):
        run_population([cfg32, tiny_beta], X.astype(np.float32), U.astype(np.float32))
