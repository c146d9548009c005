"""The automatic structure search, simulation-error refinement and experiments kept apart.

The plant: a NARX system with an input dead time of 3 samples and a mild
nonlinearity, y(k+1) = 0.6 y(k) + 0.25 y(k-1) + 0.5 u(k-3) - 0.2 u(k-3)^2 + 0.1 y(k) u(k-3),
which no candidate space without delayed inputs can describe.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from pyrhonn.cli import main
from pyrhonn.config import Factor, IdentifierConfig, NeuronConfig
from pyrhonn.configfile import load_config
from pyrhonn.experiments import Experiment, hold_out, merge
from pyrhonn.refine import DataRange, free_run_of, refine
from pyrhonn.search import (REFINED, TIE, SearchGrid, SpaceScore, Validation, _finalists, dead_times, search,
                            state_delay, validate)
from pyrhonn.structure import CandidateSpace, select

DEAD = 3
SMALL_GRID = SearchGrid(factor_sets=(("x", "u", "1"),), max_degree=2, max_delay=1, input_taps=1)


def plant(T: int, seed: int, noise: float = 0.0) -> Experiment:
    rng = np.random.default_rng(seed)
    u = np.repeat(rng.uniform(-1.0, 1.0, T // 5 + 1), 5)[:T]  # held for 5 samples: a rich, slow input
    y = np.zeros(T)
    for k in range(1, T - 1):
        ud = u[k - DEAD] if k >= DEAD else 0.0
        y[k + 1] = 0.6 * y[k] + 0.25 * y[k - 1] + 0.5 * ud - 0.2 * ud ** 2 + 0.1 * y[k] * ud
    y = y + noise * rng.standard_normal(T)
    return Experiment(y[:, None], u[:, None], np.ones((T, 1), dtype=bool), name=f"run{seed}")


def write_csv(path: Path, ex: Experiment) -> None:
    lines = ["y,u"] + [f"{float(y)!r},{float(u)!r}" for y, u in zip(ex.X[:, 0], ex.U[:, 0])]
    path.write_text("\n".join(lines) + "\n")


def test_the_input_dead_time_is_found() -> None:
    assert dead_times([plant(800, 1)], 10) == (DEAD,)


def test_merged_experiments_never_read_across_a_boundary() -> None:
    a, b = plant(300, 1), plant(300, 2)
    X, U, valid, starts = merge([a, b])
    assert starts == (300,)
    space = CandidateSpace(factors=("x", "u", "1"), degree=2, max_delay=1, input_min_delay=DEAD,
                           input_max_delay=DEAD)
    joined = select(X, U, valid, space=space, starts=starts)
    # each experiment loses the rows whose window reaches before its first sample, and its last
    assert joined.rows == 2 * (300 - space.window - 1)
    assert joined.neurons[0].residual_variance < 1e-20  # the exact model: no row mixes the two runs
    blind = select(X, U, valid, space=space)
    assert blind.rows == joined.rows + space.window + 1
    assert blind.neurons[0].residual_variance > 1e-12  # rows across the seam cannot be explained


def test_hold_out_names_the_rows_it_cuts() -> None:
    fit, val = hold_out(plant(100, 1), 0.3)
    assert (fit.rows, val.rows) == ("0..69", "70..99")
    with pytest.raises(ValueError, match="fraction"):
        hold_out(plant(100, 1), 1.0)


def test_a_free_run_that_leaves_the_data_is_reported_with_its_sample() -> None:
    ex = plant(400, 3)
    unstable = IdentifierConfig(n_states=1, n_inputs=1, neurons=(NeuronConfig(
        terms=((Factor.x(0),), (Factor.u(0),)), w0=np.array([1.05, 0.5])),))
    run = free_run_of(unstable, ex, DataRange.of([ex]))
    assert run.left_range is not None and run.left_range > run.start
    assert np.all(np.isnan(run.free_run[run.left_range:]))
    assert np.all(np.isfinite(run.free_run[run.start:run.left_range]))
    v = validate(unstable, [ex], DataRange.of([ex]))
    assert v.left_range == (ex.name, run.left_range) and v.score == np.inf


def test_refinement_lowers_the_free_run_error_and_changes_only_w0() -> None:
    est = plant(600, 4, noise=0.1)  # output noise: least squares on noisy regressors is biased
    space = CandidateSpace(factors=("x", "u", "1"), degree=2, max_delay=1, input_min_delay=DEAD,
                           input_max_delay=DEAD)
    X, U, valid, _ = merge([est])
    base = select(X, U, valid, space=space).config()
    ref = refine(base, [est])
    assert ref.cost_after < ref.cost_before
    for a, b in zip(base.neurons, ref.config.neurons):
        assert a.terms == b.terms and (a.r, a.activation, a.beta) == (b.r, b.activation, b.beta)
        np.testing.assert_array_equal(a.p0_matrix(), b.p0_matrix())
        np.testing.assert_array_equal(a.q_diagonal(), b.q_diagonal())
    assert not np.array_equal(base.neurons[0].w0_vector(), ref.config.neurons[0].w0_vector())
    # the refined model also simulates a record it was not fitted on better
    val = plant(600, 5)
    rng = DataRange.of([est])
    assert validate(ref.config, [val], rng).score < validate(base, [val], rng).score


def test_a_balanced_refinement_gives_up_less_one_step_accuracy_for_its_free_run_gain() -> None:
    est = plant(600, 4, noise=0.1)
    space = CandidateSpace(factors=("x", "u", "1"), degree=2, max_delay=1, input_min_delay=DEAD,
                           input_max_delay=DEAD)
    X, U, valid, _ = merge([est])
    base = select(X, U, valid, space=space).config()
    free_only = refine(base, [est])
    balanced = refine(base, [est], objective="balanced")
    assert (free_only.objective, balanced.objective) == ("free_run", "balanced")
    assert balanced.one_step_before == free_only.one_step_before and balanced.cost_before == free_only.cost_before
    assert balanced.cost_after < balanced.cost_before  # it still simulates better than least squares
    # least squares is the one-step optimum: both lose some of it, the balanced refinement less
    assert free_only.one_step_after > free_only.one_step_before
    assert balanced.one_step_before < balanced.one_step_after < free_only.one_step_after
    with pytest.raises(ValueError, match="objective"):
        refine(base, [est], objective="one_step")


def _scored(free: float, one: float, terms: int) -> SpaceScore:
    v = Validation(free_rrse=np.array([free]), free_rmse=np.array([free]), one_rrse=np.array([one]),
                   one_rmse=np.array([one]), scored=100, left_range=None)
    return SpaceScore(CandidateSpace(factors=("x",), degree=terms), terms, "scored", v)


def test_a_space_tied_by_the_free_run_but_better_one_step_ahead_is_a_finalist() -> None:
    scored = [_scored(0.50, 0.5, 1), _scored(0.505, 0.5, 2), _scored(0.51, 0.5, 3),
              _scored(0.50 * (1 + TIE) - 1e-9, 0.1, 4),  # tied with the best free run, far better one step ahead
              _scored(0.50 * (1 + TIE) + 0.05, 0.01, 4)]  # better still one step ahead, but not tied
    ranked = sorted(range(len(scored)), key=lambda s: scored[s].score)
    finalists = _finalists(scored, ranked, REFINED, TIE)
    assert finalists[:REFINED] == ranked[:REFINED]
    assert 3 in finalists and 4 not in finalists
    assert _finalists(scored, ranked, 1, TIE) == [0]  # without refinement only the best by the free run


def test_search_finds_a_model_that_simulates_on_unseen_data() -> None:
    est, val = plant(800, 6), plant(800, 7)
    found = search([est], state_names=["y"], input_names=["u"])
    assert found.dead_times == (DEAD,)
    assert found.held_out and found.validation is None
    assert found.fit_rows == ("run6 rows 0..799",)
    assert found.validation_rows == ("run6 (validate) rows 560..799", "run6 (validate) rows 0..239")
    check = validate(found.config, [val], DataRange.of([est]))
    assert check.left_range is None and check.score < 1e-3
    text = found.report(["y"], ["u"])
    assert "input dead time: u 3 sample(s)" in text and "fitted on: run6 rows 0..799" in text


def test_search_ranks_on_the_validation_experiments_given() -> None:
    est, val = plant(500, 8), plant(500, 9)
    found = search([est], [val], grid=SMALL_GRID, state_names=["y"], input_names=["u"])
    assert not found.held_out and found.validation is not None
    assert found.validation_rows == ("run9 rows 0..499",)
    assert found.validation.score < 1e-3
    assert found.refinement is None or found.refinement.objective == "balanced"
    assert len(found.scores) == 2 * 2 * 2  # degrees 1-2, state delays 0-1, input taps dead..dead+1
    assert all(sc.status == "scored" or sc.status.startswith(("rejected", "skipped")) for sc in found.scores)


def test_a_search_refuses_bad_data_before_any_work() -> None:
    ex = plant(300, 1)
    const = Experiment(ex.X, np.full_like(ex.U, 0.5), ex.valid, "const")
    with pytest.raises(ValueError, match="input column 'u1': constant"):
        search([const], grid=SMALL_GRID)
    with pytest.raises(ValueError, match="max_terms"):
        search([ex], max_terms=10_000)
    other = Experiment(np.hstack([ex.X, ex.X ** 2]), ex.U, np.ones((300, 2), dtype=bool), "two")
    with pytest.raises(ValueError, match=r"validation\[0\]|experiments\[1\]"):
        search([ex], [other], grid=SMALL_GRID)


def test_cli_select_searches_by_default_and_says_which_rows_fit_and_validate(tmp_path: Path, capsys) -> None:
    data = tmp_path / "run.csv"
    write_csv(data, plant(900, 10))
    out, js = tmp_path / "cfg.toml", tmp_path / "sel.json"
    assert main(["select", str(data), "--states", "y", "--inputs", "u", "--out", str(out), "--json", str(js),
                 "--fit-rows", "0:600", "--validate-rest"]) == 0
    text = capsys.readouterr().out
    assert f"fitted on: {data} rows 0..599" in text
    assert f"validation data: {data} rows 600..899" in text
    assert "input dead time: u 3 sample(s)" in text
    report = json.loads(js.read_text())
    assert report["rows"] <= 600 and report["search"]["ranked_by"] == "validation data"
    assert report["search"]["validation"]["free_run"]["y"]["rrse"] < 1e-3
    assert report["search"]["input_dead_times"] == [3]
    cfg = load_config(out).config
    assert cfg.max_delay >= DEAD


def test_cli_select_merges_experiments_and_takes_validation_files(tmp_path: Path, capsys) -> None:
    a, b, v = tmp_path / "a.csv", tmp_path / "b.csv", tmp_path / "v.csv"
    write_csv(a, plant(400, 11))
    write_csv(b, plant(400, 12))
    write_csv(v, plant(400, 13))
    out = tmp_path / "cfg.toml"
    assert main(["select", str(a), str(b), "--states", "y", "--inputs", "u", "--out", str(out),
                 "--validate", str(v), "--no-refine"]) == 0
    text = capsys.readouterr().out
    assert f"fitted on: {a} rows 0..399; {b} rows 0..399" in text
    assert "weights: least squares" in text and f"validation data: {v} rows 0..399" in text


@pytest.mark.parametrize("extra, message", [
    (["--search", "auto", "--degree", "2"], "--search auto: --degree fix(es) the candidate space"),
    (["--validate-rest"], "--validate-rest: needs --fit-rows"),
    (["--fit-rows", "5:3"], "--fit-rows: expected 0 <= A < B"),
    (["--fit-rows", "x"], "--fit-rows: expected A:B"),
    (["--fit-rows", "0:5000", "--validate-rest"], "--validate-rest: --fit-rows 0:5000 leaves no samples"),
    (["--holdout", "1.5"], "--holdout: expected a fraction in (0, 1)"),
])
def test_cli_select_names_bad_options(tmp_path: Path, capsys, extra: list[str], message: str) -> None:
    data = tmp_path / "run.csv"
    write_csv(data, plant(300, 14))
    out = tmp_path / "cfg.toml"
    assert main(["select", str(data), "--states", "y", "--inputs", "u", "--out", str(out), *extra]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
    assert not out.exists()


def test_cli_select_names_a_validation_file_with_a_missing_column(tmp_path: Path, capsys) -> None:
    data, bad = tmp_path / "run.csv", tmp_path / "bad.csv"
    write_csv(data, plant(300, 15))
    bad.write_text("y,v\n1,2\n3,4\n")
    assert main(["select", str(data), "--states", "y", "--inputs", "u", "--out", str(tmp_path / "c.toml"),
                 "--validate", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "bad.csv" in err and "'u'" in err


def test_identify_prints_small_and_huge_errors_in_significant_digits(tmp_path: Path, capsys) -> None:
    data = tmp_path / "run.csv"
    write_csv(data, plant(500, 16))
    cfg = tmp_path / "cfg.toml"
    # P0 = 1e-30, Q = 0: the online filter keeps the exact least-squares weights
    assert main(["select", str(data), "--states", "y", "--inputs", "u", "--out", str(cfg), "--no-refine",
                 "--p0", "1e-30", "--q", "0"]) == 0
    capsys.readouterr()
    assert main(["identify", str(data), "--config", str(cfg), "--out", str(tmp_path / "id"), "--no-plots",
                 "--free-run-from", "100"]) == 0
    out = capsys.readouterr().out
    rows = [line for line in out.splitlines() if line.strip().startswith("y ")]
    assert rows and "0.0000" not in rows[0] and "e-" in rows[0]  # an exact model's RRSE, e.g. 3.1e-12


def test_when_no_model_simulates_the_search_falls_back_to_the_one_step_error(monkeypatch) -> None:
    import pyrhonn.search as search_module
    real = search_module.free_run_of

    def leaves(config, experiment, data_range):  # every free run leaves the data one sample after it starts
        run = real(config, experiment, data_range)
        free = run.free_run.copy()
        free[run.start + 1:] = np.nan
        return type(run)(run.one_step, free, run.start, run.start + 1)

    monkeypatch.setattr(search_module, "free_run_of", leaves)
    est = plant(500, 17)
    found = search([est], grid=SMALL_GRID, state_names=["y"], input_names=["u"])
    assert found.by_one_step and found.refinement is None
    assert all(sc.status.startswith(("rejected", "skipped")) for sc in found.scores)
    best = min(sc.one_step for sc in found.scores)
    assert found.scores[found.chosen].one_step == best and best < 1e-3
    assert any("does not simulate" in note for note in found.notes)
    assert "does not simulate" in found.report(["y"], ["u"])


def delayed_plant(T: int, seed: int, delay: int = 12) -> Experiment:
    """y(k+1) = 0.5 y(k) + 0.4 y(k-delay) + u(k): a state delay far beyond the grid's short taps."""
    rng = np.random.default_rng(seed)
    u = np.repeat(rng.uniform(-1.0, 1.0, T // 4 + 1), 4)[:T]
    y = np.zeros(T)
    for k in range(delay, T - 1):
        y[k + 1] = 0.5 * y[k] + 0.4 * y[k - delay] + u[k]
    return Experiment(y[:, None], u[:, None], np.ones((T, 1), dtype=bool), name=f"delayed{seed}")


def test_a_deep_state_delay_is_found_and_searched() -> None:
    est, val = delayed_plant(1000, 1), delayed_plant(1000, 2)
    assert state_delay([est], 3, 30, (0,)) == 12
    assert state_delay([plant(800, 8)], 3, 30, (DEAD,)) is None  # no delay: no spurious deep tap
    found = search([est], grid=SMALL_GRID, state_names=["y"], input_names=["u"])
    assert found.state_delay == 12
    assert any(sc.space.extra_delays == (12,) for sc in found.scores)
    assert found.config.max_delay == 12
    assert validate(found.config, [val], DataRange.of([est])).score < 1e-3
    assert "state delay beyond the short taps: 12 samples" in found.report(["y"], ["u"])


def test_a_chaotic_plant_is_chosen_by_its_one_step_error() -> None:
    # the logistic map: every model's free run loses the phase, so no free run beats the mean
    T = 1000
    y = np.empty(T)
    y[0] = 0.3
    for k in range(T - 1):
        y[k + 1] = 3.9 * y[k] * (1.0 - y[k])
    rng = np.random.default_rng(0)
    y += 1e-4 * rng.standard_normal(T)  # measurement noise: a free run loses the phase within tens of samples
    ex = Experiment(y[:, None], rng.uniform(-1e-3, 1e-3, (T, 1)), np.ones((T, 1), dtype=bool), "logistic")
    found = search([ex], grid=SearchGrid(factor_sets=(("x", "1"),), max_degree=2, max_delay=1, input_taps=0),
                   state_names=["y"], input_names=["u"])
    assert found.by_one_step and found.refinement is None
    assert min(sc.score for sc in found.scores) >= 0.95
    assert found.in_sample.one_rrse[0] < 1e-3  # y(k+1) = 3.9 y - 3.9 y^2, recovered one step ahead
    assert any("clearly beats the data's mean" in note for note in found.notes)


def test_learning_online_after_select_continues_the_fit_instead_of_undoing_it() -> None:
    # the cascaded tanks (real data): a slow plant whose model has a pole near 1, so that weights moved
    # beyond their uncertainty by a few EKF steps stop it simulating
    rows = np.genfromtxt(Path(__file__).resolve().parents[1] / "bench" / "data" / "cascaded_tanks" /
                         "dataBenchmark.csv", delimiter=",", names=True)
    yE, uE, yV, uV = (np.ascontiguousarray(rows[k])[:, None] for k in ("yEst", "uEst", "yVal", "uVal"))
    space = CandidateSpace(factors=("x", "u", "1"), degree=3, max_delay=1, input_min_delay=6, input_max_delay=8)
    sel = select(yE, uE, space=space)

    def free_run_rmse(config: IdentifierConfig, learn_until: int) -> float:
        from pyrhonn import Identifier
        from pyrhonn.simulation import simulate
        ident = Identifier(config)
        with np.errstate(all="ignore"):
            sim = simulate(ident, yV, uV, None, free_run_from=learn_until)  # learning on before learn_until
        e = sim.free_run[learn_until:, 0] - yV[learn_until:, 0]
        with np.errstate(over="ignore"):  # a free run that has left for good
            return float(np.sqrt(np.mean(e ** 2)))

    fit = sel.config()
    assert isinstance(fit.neurons[0].p0, np.ndarray)  # the least-squares covariance, not a diagonal
    frozen = validate(fit, [Experiment(yV, uV, np.ones(yV.shape, dtype=bool), "val")], DataRange.of(
        [Experiment(yE, uE, np.ones(yE.shape, dtype=bool), "est")])).free_rmse[0]
    for K in (20, 100, 300):
        assert free_run_rmse(fit, K) < 1.2 * frozen
    # the per-weight form, after 20 learning steps, no longer simulates
    assert not free_run_rmse(sel.config(p0_form="scalar"), 20) < 3.0 * frozen


def test_search_and_select_take_recordings_with_dropouts(tmp_path: Path, capsys) -> None:
    est = plant(900, 18)
    valid = est.valid.copy()
    valid[300:320, 0] = False
    valid[650, 0] = False
    X = np.where(valid, est.X, np.nan)
    holed = Experiment(X, est.U, valid, "holed")
    found = search([holed], grid=SMALL_GRID, state_names=["y"], input_names=["u"])
    check = validate(found.config, [plant(600, 19)], DataRange.of([holed]))
    assert check.left_range is None and check.score < 1e-3
    data = tmp_path / "holed.csv"
    lines = ["y,u,y_valid"] + [(repr(float(y)) if v else "") + f",{float(u)!r},{int(v)}"
                               for y, u, v in zip(X[:, 0], est.U[:, 0], valid[:, 0])]
    data.write_text("\n".join(lines) + "\n")
    assert main(["select", str(data), "--states", "y", "--inputs", "u", "--out", str(tmp_path / "c.toml")]) == 0
    assert "fitted on:" in capsys.readouterr().out


def test_identify_reports_where_a_free_run_leaves_the_data(tmp_path: Path, capsys) -> None:
    from pyrhonn.configfile import ConfigFile, dumps
    data, cfg = tmp_path / "run.csv", tmp_path / "unstable.toml"
    write_csv(data, plant(400, 20))
    unstable = IdentifierConfig(n_states=1, n_inputs=1, neurons=(NeuronConfig(
        terms=((Factor.x(0),), (Factor.u(0),)), w0=np.array([1.05, 0.5])),))
    cfg.write_text(dumps(ConfigFile.from_config(unstable, state_names=("y",), input_names=("u",))))
    assert main(["identify", str(data), "--config", str(cfg), "--out", str(tmp_path / "id"), "--no-plots",
                 "--free-run-from", "10"]) == 0
    out = capsys.readouterr().out
    metrics = json.loads((tmp_path / "id" / "metrics.json").read_text())
    line = metrics["free_run"]["left_range_at_line"]
    assert line is not None and line > 12 and f"the free run left the data's range at line {line}" in out


def test_experiments_refine_and_search_refuse_bad_arguments_naming_them() -> None:
    ex = plant(200, 21)
    with pytest.raises(ValueError, match=r"^bad: X: expected a \(T, n\) float64"):
        Experiment(ex.X.astype(np.float32), ex.U, ex.valid, "bad")
    with pytest.raises(ValueError, match=r"^bad: U: expected a \(200, m\)"):
        Experiment(ex.X, ex.U[:-1], ex.valid, "bad")
    with pytest.raises(ValueError, match=r"^bad: valid: expected a \(200, 1\) bool"):
        Experiment(ex.X, ex.U, ex.valid.astype(int), "bad")
    nan = ex.X.copy()
    nan[5, 0] = np.nan
    with pytest.raises(ValueError, match=r"^bad: X: sample 5, state 0: not finite but marked valid"):
        Experiment(nan, ex.U, ex.valid, "bad")
    Experiment(nan, ex.U, ~np.isnan(nan), "holed")  # a NaN where the sample is marked missing is fine
    two = Experiment(np.hstack([ex.X, ex.X]), ex.U, np.ones((200, 2), dtype=bool), "two")
    with pytest.raises(ValueError, match=r"^experiments\[1\]: 2 states and 1 inputs"):
        merge([ex, two])
    with pytest.raises(ValueError, match=r"^experiments: expected at least one"):
        merge([])
    cfg = IdentifierConfig(n_states=1, n_inputs=1, neurons=(NeuronConfig(terms=((Factor.x(0),),)),))
    with pytest.raises(ValueError, match=r"^config: expected an IdentifierConfig"):
        refine("cfg", [ex])  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"^experiments: expected a non-empty list"):
        refine(cfg, [])
    with pytest.raises(ValueError, match=r"^max_evaluations: "):
        refine(cfg, [ex], max_evaluations=0)
    with pytest.raises(ValueError, match=r"^grid: expected a SearchGrid"):
        search([ex], grid="small")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"^criterion: expected one of"):
        search([ex], grid=SMALL_GRID, criterion="mdl")
    with pytest.raises(ValueError, match=r"^refine_weights: expected a bool"):
        search([ex], grid=SMALL_GRID, refine_weights=1)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"^max_degree: "):
        SearchGrid(max_degree=5)
    with pytest.raises(ValueError, match=r"^factors\[0\]: expected one of"):
        SearchGrid(factor_sets=(("q",),))
    with pytest.raises(ValueError, match=r"^extra_delays\[0\]: "):
        CandidateSpace(extra_delays=(0,))
