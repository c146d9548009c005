"""The covariance stays a covariance: after every step that returns RHONN_OK
each committed P_i is positive definite at working precision, in float32
first (the firmware's precision); the factored U D U^T form runs where the
full form must refuse; the covariance read is one the setter accepts, and
writing it back changes nothing; windup protection bounds the gain after a
quiet stretch, and forgetting cannot blow P up there; automatic recovery
resets a neuron that keeps failing."""
from __future__ import annotations

from dataclasses import replace
from fractions import Fraction

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pyrhonn import Activation, CovarianceForm, Identifier, IdentifierConfig, IdentifierError, terms
from pyrhonn.configfile import load_shipped
from pyrhonn.reference import ReferenceIdentifier

from strategies import configs, trajectory

FULL, UD = CovarianceForm.FULL, CovarianceForm.UD


def with_neurons(config: IdentifierConfig, **fields) -> IdentifierConfig:
    return config.replace(neurons=tuple(replace(nr, **fields) for nr in config.neurons))


def snapshot(ident: Identifier) -> tuple:
    return (tuple(w.tobytes() for w in ident.weights), tuple(P.tobytes() for P in ident.covariances),
            ident.prediction.tobytes(), ident.steps)


def assert_definite(ident: Identifier) -> None:
    """Cholesky succeeds at the identifier's own precision (numpy keeps float32 in float32)."""
    for i, P in enumerate(ident.covariances):
        assert P.dtype == ident.dtype
        np.testing.assert_array_equal(P, P.T)
        try:
            np.linalg.cholesky(P)
        except np.linalg.LinAlgError:
            pytest.fail(f"P_{i} is not positive definite at {ident.dtype}: eigenvalues "
                        f"{np.linalg.eigvalsh(P.astype(np.float64))}")


def moving_lim(T: int, dtype: str = "float32") -> tuple[np.ndarray, np.ndarray]:
    """A LIM already moving at the first sample: q_m = 0.5 + 0.3 t, the rest
    constant, constant input; 0.3 ms sampling."""
    t = 0.3e-3 * np.arange(T)
    X = np.empty((T, 6))
    X[:, 0] = 0.5 + 0.3 * t
    X[:, 1:] = [0.3, 0.1, 0.1, 1.0, 1.0]
    return X.astype(dtype), np.full((T, 2), 10.0, dtype=dtype)


def test_example3_in_float32_runs_a_moving_start_with_the_position_neuron_factored() -> None:
    config = load_shipped("example3").config.replace(dtype="float32")
    assert config.neurons[0].covariance is UD
    ident = Identifier(config)
    X, U = moving_lim(20_000)
    ident.run(X, U)
    assert_definite(ident)
    assert all(h.rejected == 0 for h in ident.healths)


def test_the_full_form_refuses_the_update_that_would_leave_p_indefinite_and_commits_nothing() -> None:
    """The moving start that once committed P_0 = [[26.47, -44.12], [-44.12, 73.53]]
    (an eigenvalue of -3.6e-6) with RHONN_OK in float32."""
    config = load_shipped("example3").config.replace(dtype="float32")
    config = config.replace(neurons=(replace(config.neurons[0], covariance=FULL),) + config.neurons[1:])
    ident = Identifier(config)
    X, U = moving_lim(50)
    refused = None
    for k in range(50):
        before = snapshot(ident)
        try:
            ident.step(X[k], U[k])
        except IdentifierError as exc:
            refused = exc
            assert snapshot(ident) == before
            break
        assert_definite(ident)
    assert refused is not None and refused.status == "RHONN_E_NOT_PD"
    assert "neurons[0]" in str(refused) and 'covariance = "ud"' in str(refused)
    assert ident.health(0).rejected == 1


@pytest.mark.parametrize("form", [FULL, UD])
def test_a_large_p0_with_a_bias_and_no_q_never_commits_a_zero_covariance(form: CovarianceForm) -> None:
    """P0 = 6.8e6, R = 0.06, Q = 0, a bias term: the full form's cancellation
    once drove P to exactly 0 with RHONN_OK, and learning stopped silently."""
    config = IdentifierConfig.uniform(terms.bias(), n_states=1, n_inputs=0, p0=6.8e6, q=0.0, r=0.06,
                                      covariance=form, dtype="float32")
    ident = Identifier(config)
    x = np.array([0.25], dtype=np.float32)
    for _ in range(200):
        try:
            ident.step(x)
        except IdentifierError as exc:
            assert form is FULL and exc.status == "RHONN_E_NOT_PD"
            continue
        assert ident.get_covariance(0)[0, 0] > 0
    if form is UD:
        # RLS without process noise: P shrinks like R / k, never to 0
        assert 0.06 / 400 < float(ident.get_covariance(0)[0, 0]) < 0.06 / 100
        assert ident.health(0).rejected == 0


def test_a_p0_near_the_float32_limit_is_refused_not_committed_negative() -> None:
    """P0 near FLT_MAX once gave P00 = -2e31 with RHONN_OK."""
    config = IdentifierConfig.uniform(terms.first_order(1, 0) + terms.bias(), n_states=1, n_inputs=0,
                                      p0=3.0e38, q=0.0, r=1.0, dtype="float32")
    ident = Identifier(config)
    x = np.array([0.5], dtype=np.float32)
    ident.step(x)
    for _ in range(5):
        with pytest.raises(IdentifierError):
            ident.step(x)
        assert_definite(ident)


@pytest.mark.parametrize("dtype", ["float32", "float64"])
@pytest.mark.parametrize("form", [FULL, UD])
@settings(max_examples=25, deadline=None)
@given(config=configs(), seed=st.integers(0, 2**31 - 1), data=st.data())
def test_after_every_ok_step_every_covariance_is_positive_definite(config: IdentifierConfig, seed: int,
                                                                   data: st.DataObject, form: CovarianceForm,
                                                                   dtype: str) -> None:
    config = with_neurons(config.replace(dtype=dtype), covariance=form)
    ident = Identifier(config)
    X, U, valid = trajectory(seed, 60, config.n_states, config.n_inputs, dropout=0.1, dtype=dtype)
    scale = data.draw(st.sampled_from([1.0, 1e3, 1e-3]))
    X = np.where(valid, X * np.asarray(scale, dtype=dtype), X)
    for k in range(60):
        before = snapshot(ident)
        try:
            ident.step(X[k], U[k], valid[k])
        except IdentifierError:
            assert snapshot(ident) == before
            continue
        assert_definite(ident)
        for h in ident.healths:
            assert h.nis >= 0.0


@settings(max_examples=20, deadline=None)
@given(config=configs(), seed=st.integers(0, 2**31 - 1))
def test_the_factored_form_is_the_same_filter_as_eq7_in_float64(config: IdentifierConfig, seed: int) -> None:
    """U D U^T (Bierman + Thornton) against the NumPy reference's full P."""
    config = with_neurons(config, covariance=UD)
    ident, ref = Identifier(config), ReferenceIdentifier(config)
    X, U, valid = trajectory(seed, 40, config.n_states, config.n_inputs, dropout=0.1)
    got = ident.run(X, U, valid)
    want = ref.run(X, U, valid)
    np.testing.assert_allclose(got, want, rtol=1e-8, atol=1e-8)
    for P, Pr in zip(ident.covariances, ref.covariances):
        np.testing.assert_allclose(P, Pr, rtol=1e-7, atol=1e-9 * float(np.max(np.abs(Pr))))


@pytest.mark.parametrize("form", [FULL, UD])
def test_forgetting_and_the_trace_ceiling_follow_the_reference(form: CovarianceForm) -> None:
    config = IdentifierConfig.uniform(terms.first_order(3, 1) + terms.bias(), n_states=3, n_inputs=1,
                                      activation=Activation.BIPOLAR, beta=0.5, p0=10.0, q=1e-2, r=0.1,
                                      covariance=form, forgetting=0.98, p_trace_max=50.0)
    ident, ref = Identifier(config), ReferenceIdentifier(config)
    X, U, _ = trajectory(11, 300, 3, 1)
    U[100:250] = 0.0
    X[100:250] = X[100]  # a quiet stretch: the ceiling binds
    np.testing.assert_allclose(ident.run(X, U), ref.run(X, U), rtol=1e-8, atol=1e-10)
    for P, Pr in zip(ident.covariances, ref.covariances):
        np.testing.assert_allclose(P, Pr, rtol=1e-7, atol=1e-9)
    assert all(h.bounded > 0 for h in ident.healths)
    assert all(float(np.trace(P)) <= 50.0 * (1 + 1e-12) for P in ident.covariances)


def example1_windup_run(quiet: int, protect: bool) -> float:
    """Example 1 (eq. 20 tuning) in float32: `quiet` samples of a plant at
    rest under a constant input, then 1,000 excited samples; the largest
    weight change of one step among those 1,000."""
    config = load_shipped("example1").config.replace(dtype="float32")
    if protect:
        trace0 = [float(np.trace(nr.p0_matrix())) for nr in config.neurons]
        config = config.replace(neurons=tuple(replace(nr, p_trace_max=t) for nr, t in zip(config.neurons, trace0)))
    ident = Identifier(config)
    X, U, _ = trajectory(7, 1100, 4, 1, dtype="float32")
    ident.run(X[:100], U[:100])  # learnt a little first
    if quiet:
        ident.run(np.repeat(X[99:100], quiet, axis=0), np.repeat(U[99:100], quiet, axis=0))
    largest = 0.0
    w = np.concatenate(ident.weights)
    for k in range(100, 1100):
        ident.step(X[k], U[k])
        w_new = np.concatenate(ident.weights)
        largest = max(largest, float(np.max(np.abs(w_new - w))))
        w = w_new
    return largest


def test_windup_protection_keeps_the_first_excited_steps_as_calm_as_without_a_quiet_stretch() -> None:
    reference = example1_windup_run(quiet=0, protect=True)
    protected = example1_windup_run(quiet=1_000_000, protect=True)
    unprotected = example1_windup_run(quiet=1_000_000, protect=False)
    assert protected <= 2.0 * reference
    assert unprotected > 4.0 * protected  # the burst the ceiling removes


@pytest.mark.parametrize("form", [FULL, UD])
def test_reset_after_replaces_the_nth_refusal_in_a_row_by_a_covariance_reset(form: CovarianceForm) -> None:
    config = IdentifierConfig.uniform(terms.first_order(2, 1), n_states=2, n_inputs=1, p0=10.0, q=1e-3, r=0.1,
                                      covariance=form, reset_after=3, dtype="float32")
    ident = Identifier(config)
    X, U, _ = trajectory(2, 30, 2, 1, dtype="float32")
    ident.run(X[:20], U[:20])
    big = np.finfo(np.float32).max / 4
    bad = np.array([big, X[20, 1]], dtype=np.float32)  # neuron 0's update overflows
    w0 = ident.get_weights(0)
    for failures in (1, 2):
        with pytest.raises(IdentifierError):
            ident.step(bad, U[20])
        assert ident.health(0).fail_run == failures
    ident.step(bad, U[20])  # the third refusal in a row: P_0 back to P0, weights kept, step goes on
    h = ident.health(0)
    assert (h.resets, h.rejected, h.fail_run) == (1, 3, 0)
    np.testing.assert_array_equal(ident.get_weights(0), w0)
    np.testing.assert_allclose(ident.get_covariance(0), 10.0 * np.eye(3), rtol=0, atol=0)
    assert ident.health(1).updates == 20


def test_protection_fields_are_validated_with_the_field_named() -> None:
    base = dict(terms=terms.first_order(1, 0), p0=4.0)
    from pyrhonn import NeuronConfig

    for kwargs, field in [(dict(forgetting=0.0), "forgetting"), (dict(forgetting=1.5), "forgetting"),
                          (dict(forgetting=float("nan")), "forgetting"), (dict(p_trace_max=3.9), "p_trace_max"),
                          (dict(p_trace_max=-1.0), "p_trace_max"), (dict(reset_after=-1), "reset_after"),
                          (dict(reset_after=70000), "reset_after"), (dict(reset_after=1.0), "reset_after"),
                          (dict(covariance="ud"), "covariance"), (dict(gate=-1.0), "gate"),
                          (dict(gate=float("nan")), "gate"), (dict(gate=float("inf")), "gate"),
                          (dict(gate="9"), "gate")]:
        with pytest.raises(ValueError, match=rf"^{field}"):
            NeuronConfig(**base, **kwargs)


def test_the_firmware_lim_position_neuron_runs_with_p0_100_and_r_1e_6_in_float32() -> None:
    config = load_shipped("firmware-lim").config
    position = config.neurons[0]
    assert config.dtype == "float32"
    assert (position.covariance, float(position.p0), position.r) == (UD, 100.0, 1e-6)
    ident = Identifier(config)
    X, U = moving_lim(20_000)
    ident.run(X, U)
    assert_definite(ident)
    assert all(h.rejected == 0 for h in ident.healths)
    # eq. 7 as written cannot: the moving start makes [q_m, v]'s P indefinite at once
    full = Identifier(config.replace(neurons=(replace(position, covariance=FULL),) + config.neurons[1:]))
    with pytest.raises(IdentifierError, match="RHONN_E_NOT_PD") as info:
        full.run(X, U)
    assert info.value.sample == 1  # the failing row, for a caller that skips it and goes on


def exactly_definite(P: np.ndarray) -> bool:
    """L D L^T of the stored matrix in exact rational arithmetic: every pivot > 0."""
    L = P.shape[0]
    a = [[Fraction(float(P[r, c])) for c in range(L)] for r in range(L)]
    for j in range(L):
        if a[j][j] <= 0:
            return False
        for r in range(j + 1, L):
            f = a[r][j] / a[j][j]
            for c in range(j + 1, L):
                a[r][c] -= f * a[j][c]
    return True


def proven(ident: Identifier, i: int) -> bool:
    """Does neuron i's committed full-form P carry the core's proof of exact definiteness?"""
    ident._settle()  # the proofs back in the struct, if step() lent them to the vector lanes
    net = ident._net
    return bool(net.cert[i][net.bank[i]])


@pytest.mark.parametrize("dtype", ["float32", "float64"])
@settings(max_examples=15, deadline=None)
@given(config=configs(), seed=st.integers(0, 2**31 - 1), data=st.data())
def test_a_covariance_the_core_proves_definite_is_definite_in_exact_arithmetic(config: IdentifierConfig, seed: int,
                                                                              data: st.DataObject,
                                                                              dtype: str) -> None:
    """The full form skips its O(L^3) factorisation when rounding-error
    bounds prove the new P definite from the old one's proof; a proof that
    does not hold in exact arithmetic would let an indefinite P through."""
    q = data.draw(st.sampled_from([1e-2, 1e-4, 1e-7, 0.0]))
    r = data.draw(st.sampled_from([1.0, 1e-3, 1e-6]))
    config = with_neurons(config.replace(dtype=dtype), covariance=FULL, q=q, r=r)
    ident = Identifier(config)
    X, U, valid = trajectory(seed, 60, config.n_states, config.n_inputs, dropout=0.1, dtype=dtype)
    for k in range(60):
        try:
            ident.step(X[k], U[k], valid[k])
        except IdentifierError:
            continue
        if k % 6 == 5:
            for i, P in enumerate(ident.covariances):
                if proven(ident, i):
                    assert exactly_definite(P), f"P_{i} after step {k}"


def test_the_firmware_full_form_neurons_prove_their_covariance_without_factorising_on_the_rig_data() -> None:
    """firmware-lim's four full-form neurons (Q = 1e-3 I) on the LIM
    trajectory in float32: after their first update, the proof carries on
    from step to step, so the M4 runs the O(L) bound instead of the O(L^3)
    factorisation; a covariance set from outside starts without a proof."""
    config = load_shipped("firmware-lim").config
    full = [i for i, nr in enumerate(config.neurons) if nr.covariance is FULL]
    assert len(full) == 4
    ident = Identifier(config)
    X, U = moving_lim(400)
    carried = 0
    for k in range(400):
        ident.step(X[k], U[k])
        carried += sum(proven(ident, i) for i in full)
    assert carried >= 0.95 * 4 * 399
    i = full[0]
    ident.set_covariance(i, ident.get_covariance(i))
    assert not proven(ident, i)
    ident.step(X[0], U[0])
    assert proven(ident, i)  # the shifted factorisation proves it again


@pytest.mark.parametrize("dtype", ["float32", "float64"])
def test_a_population_skips_the_factorisation_only_where_it_proves_the_covariance(dtype: str) -> None:
    """run_identifiers carries each member's proof in and out: its members
    end with the proof (the population ran the O(L) bound, not the
    factorisation), every proven P is definite in exact arithmetic, and the
    members match identifiers run alone bit for bit, proofs included."""
    from pyrhonn.population import run_identifiers

    base = load_shipped("firmware-lim").config.replace(dtype=dtype)
    full = [i for i, nr in enumerate(base.neurons) if nr.covariance is FULL]
    configs = [with_neurons(base, q=q) if q is not None else base for q in (None, 1e-2, 1e-4, 1e-7)]
    X, U = moving_lim(300, dtype)
    members, alone = [Identifier(c) for c in configs], [Identifier(c) for c in configs]
    run_identifiers(members, X, U)
    for a, b in zip(members, alone):
        b.run(X, U)
        for i in range(base.n_states):
            np.testing.assert_array_equal(a.get_covariance(i), b.get_covariance(i))
            if i in full:
                assert proven(a, i) == proven(b, i)
                if proven(a, i):
                    assert exactly_definite(a.get_covariance(i))
    assert all(proven(members[0], i) for i in full)


# -- the covariance read is one the setter accepts (rhonn.h ROUND TRIP) ----------------------------


@pytest.mark.parametrize("dtype", ["float32", "float64"])
@pytest.mark.parametrize("form", [FULL, UD])
@settings(max_examples=25, deadline=None)
@given(config=configs(), seed=st.integers(0, 2**31 - 1), data=st.data())
def test_a_covariance_read_is_accepted_back_and_writing_it_changes_nothing(config: IdentifierConfig, seed: int,
                                                                          data: st.DataObject, form: CovarianceForm,
                                                                          dtype: str) -> None:
    """After every OK step, set_covariance(i, get_covariance(i)) succeeds for
    every neuron and leaves the next predictions unchanged, bit for bit: the
    identifier that does it and a twin that does not stay identical. Ill
    conditioned on purpose (small R and Q, scaled data, forgetting), where
    U D U^T formed in float32 used to come out indefinite. A U D U^T
    neuron's P read is positive definite in float64 too."""
    r = data.draw(st.sampled_from([1.0, 1e-3, 1e-6]))
    q = data.draw(st.sampled_from([1e-2, 1e-6, 0.0]))
    lam = data.draw(st.sampled_from([1.0, 0.99, 0.9]))
    config = with_neurons(config.replace(dtype=dtype), covariance=form, r=r, q=q, forgetting=lam)
    ident, twin = Identifier(config), Identifier(config)
    X, U, valid = trajectory(seed, 80, config.n_states, config.n_inputs, dropout=0.1, dtype=dtype)
    scale = data.draw(st.sampled_from([1.0, 1e3, 1e-3]))
    X = np.where(valid, X * np.asarray(scale, dtype=dtype), X)
    for k in range(80):
        try:
            want = twin.step(X[k], U[k], valid[k])
        except IdentifierError as exc:
            with pytest.raises(IdentifierError) as info:
                ident.step(X[k], U[k], valid[k])
            assert info.value.status == exc.status
            continue
        got = ident.step(X[k], U[k], valid[k])
        assert got.tobytes() == want.tobytes()
        for i in range(config.n_states):
            P = ident.get_covariance(i)
            if form is UD:
                np.linalg.cholesky(P.astype(np.float64))  # definite, not only at working precision
            ident.set_covariance(i, P)
    assert snapshot(ident)[:3] == snapshot(twin)[:3]
    assert [h.updates for h in ident.healths] == [h.updates for h in twin.healths]


@pytest.mark.parametrize("dtype", ["float32", "float64"])
def test_a_factored_covariance_read_is_definite_where_its_plain_product_is_not(dtype: str) -> None:
    """U D U^T factors of nearly singular covariances (d over 8 decades, |U|
    up to 1e3), set with rhonn_set_factors: their product formed in float32
    is often indefinite (the getter used to return it, and the setter then
    refused it); what the getter reads passes a float64 Cholesky and both
    setters (the identifier's own and another's), and writing it back keeps
    the factors bit for bit."""
    config = IdentifierConfig.uniform(terms.first_order(2, 1) + terms.bias(), n_states=2, n_inputs=1,
                                      covariance=UD, dtype=dtype)
    L = config.neurons[0].n_terms
    ident, other = Identifier(config), Identifier(config)
    lib, ffi = ident._lib, ident._ffi
    rng = np.random.default_rng(5)
    plain_indefinite = 0
    for _ in range(500):
        F = np.triu(rng.uniform(-1, 1, (L, L)) * 10.0 ** rng.uniform(0, 3, (L, L)), 1)
        F[np.diag_indices(L)] = 10.0 ** rng.uniform(-6, 2, L)
        packed = np.ascontiguousarray(F[np.triu_indices(L)].astype(dtype))
        assert lib.rhonn_set_factors(ident._net, 0, ffi.from_buffer(ident._real_array, packed), packed.size) == 0
        Fd = _unpacked_factors(packed, L)
        Ud = np.triu(Fd, 1) + np.eye(L, dtype=Fd.dtype)
        plain = (Ud * np.diag(Fd)) @ Ud.T  # the product at working precision
        try:
            np.linalg.cholesky(plain.astype(np.float64))
        except np.linalg.LinAlgError:
            plain_indefinite += 1
        P = ident.get_covariance(0)
        np.linalg.cholesky(P.astype(np.float64))
        ident.set_covariance(0, P)
        assert ident._stored_covariance(0).tobytes() == packed.tobytes()
        other.set_covariance(0, P)
    if dtype == "float32":
        assert plain_indefinite > 0  # the case the getter repairs does occur


def _unpacked_factors(packed: np.ndarray, L: int) -> np.ndarray:
    F = np.zeros((L, L), dtype=packed.dtype)
    F[np.triu_indices(L)] = packed
    return F


# -- forgetting cannot blow P up in a quiet stretch (rhonn.h WINDUP PROTECTION) ------------------


@pytest.mark.parametrize("dtype", ["float32", "float64"])
@pytest.mark.parametrize("form", [FULL, UD])
@pytest.mark.parametrize("lam", [0.999, 0.99])
def test_forgetting_survives_a_long_quiet_stretch_and_learns_every_excited_step_after(dtype: str,
                                                                                    form: CovarianceForm,
                                                                                    lam: float) -> None:
    """Example 1 (eq. 20 tuning) with forgetting: 10^5 samples with x and u
    held (float32, lambda 0.999, full form: refused for good from quiet
    step 15,508 before the ceiling), then 1,000 excited samples: every one
    learned by every neuron, none refused, every P finite and definite."""
    config = with_neurons(load_shipped("example1").config.replace(dtype=dtype), forgetting=lam, covariance=form)
    ident = Identifier(config)
    X, U, _ = trajectory(7, 1100, 4, 1, dtype=dtype)
    ident.run(X[:100], U[:100])
    for _ in range(10):  # 10 x 10^4 quiet samples; run() raises on any refusal
        ident.run(np.repeat(X[99:100], 10_000, axis=0), np.repeat(U[99:100], 10_000, axis=0))
        for P in ident.covariances:
            assert np.all(np.isfinite(P))
            np.linalg.cholesky(P.astype(np.float64))
    before = [h.updates for h in ident.healths]
    for k in range(100, 1100):
        ident.step(X[k], U[k])
        for P in ident.covariances:
            assert np.all(np.isfinite(P))
            np.linalg.cholesky(P.astype(np.float64))
    assert [h.updates - b for h, b in zip(ident.healths, before)] == [1000] * 4
    assert all(h.rejected == 0 for h in ident.healths)


@pytest.mark.parametrize("form", [FULL, UD])
def test_without_q_forgetting_keeps_trace_p_within_trace_p0(form: CovarianceForm) -> None:
    """Bounded forgetting's ceiling (trace P_i(0) here): a quiet stretch
    grows the unexcited directions only until trace P_i is back to where it
    started, and the core follows the NumPy reference through it."""
    config = IdentifierConfig.uniform(terms.first_order(3, 1) + terms.bias(), n_states=3, n_inputs=1,
                                      activation=Activation.BIPOLAR, beta=0.5, p0=10.0, q=0.0, r=0.1,
                                      covariance=form, forgetting=0.95)
    ident, ref = Identifier(config), ReferenceIdentifier(config)
    X, U, _ = trajectory(11, 600, 3, 1)
    U[100:500] = U[100]
    X[100:500] = X[100]  # quiet
    np.testing.assert_allclose(ident.run(X, U), ref.run(X, U), rtol=1e-8, atol=1e-10)
    for P, Pr in zip(ident.covariances, ref.covariances):
        np.testing.assert_allclose(P, Pr, rtol=1e-7, atol=1e-9)
    ident.reset()
    traces = []
    for k in range(500):
        ident.step(X[k], U[k])
        traces.append(max(h.trace_p for h in ident.healths))
    assert max(traces) <= 50.0 * (1 + 1e-12)  # trace P(0) = 5 x 10
    # the quiet stretch reached the ceiling: forgetting there keeps trace P in [lambda c, c]
    assert min(traces[400:500]) > 0.95 * 50.0 * 0.99
