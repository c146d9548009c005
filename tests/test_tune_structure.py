"""``pyrhonn tune`` beyond the single split: blocked cross-validation (``--folds``), structure search
(``--structure``: each trial runs ``pyrhonn select`` on the training part), the study's total trial count
shared by workers, and database URLs for ``--study``."""
from __future__ import annotations

import os
import re
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from pyrhonn import Identifier, IdentifierConfig, terms
from pyrhonn import tuning
from pyrhonn.regressors import refit_w0
from pyrhonn.cli import main
from pyrhonn.configfile import load_config, load_shipped
from pyrhonn.plants import Trajectory, oscillator
from pyrhonn.structure import select


@pytest.fixture(scope="module")
def traj() -> Trajectory:
    return oscillator.simulate(dt=0.2, horizon=60.0)  # 301 samples


@pytest.fixture(scope="module")
def base() -> IdentifierConfig:
    return load_shipped("example1").config


def test_fold_bounds_cut_the_held_out_part_into_contiguous_blocks() -> None:
    assert tuning.fold_bounds(100, 60, 1) == ((60, 100),)
    assert tuning.fold_bounds(100, 60, 4) == ((60, 70), (70, 80), (80, 90), (90, 100))
    assert tuning.fold_bounds(101, 60, 3) == ((60, 73), (73, 87), (87, 101))
    with pytest.raises(ValueError, match="^folds: 30 folds of the 40 held-out samples"):
        tuning.fold_bounds(100, 60, 30)


def test_folds_score_each_block_one_step_ahead_and_average(traj: Trajectory, base: IdentifierConfig) -> None:
    rows = Identifier(base).run(traj.X_meas, traj.U, traj.valid)  # learning on from sample 0 throughout
    folds = tuning.fold_bounds(traj.n_samples, tuning.split_point(traj.n_samples, 0.6), 3)
    per_fold = []
    for N, E in folds:
        y, yhat = traj.X[N:E], rows[N - 1:E - 1]
        per_fold.append(np.sqrt(np.mean((y - yhat) ** 2, axis=0)) / np.std(y, axis=0))
    s = tuning.held_out_score(base, traj.X_meas, traj.U, traj.valid, truth=traj.X, folds=3)
    np.testing.assert_allclose(s.folds, [np.mean(f) for f in per_fold], rtol=1e-12)
    assert s.value == pytest.approx(np.mean(per_fold), rel=1e-12)
    np.testing.assert_allclose(s.normalised, np.mean(per_fold, axis=0), rtol=1e-12)
    single = tuning.held_out_score(base, traj.X_meas, traj.U, traj.valid, truth=traj.X)
    assert single.folds == (single.value,) and single.value != s.value


def test_structure_search_selects_on_the_training_part_and_scores_what_it_writes(
        traj: Trajectory, base: IdentifierConfig) -> None:
    search = tuning.StructureSearch(max_delay=(0, 6), degree=(1, 2), max_terms=(2, 10))
    r = tuning.tune(base, traj.X_meas, traj.U, traj.valid, truth=traj.X, structure=search, n_trials=10, seed=0)
    assert r.counts.complete + r.counts.failed == 10 and r.best is not None
    if not r.improved:
        pytest.fail(f"a 10-trial structure search did not beat the shipped config ({r.base})")
    N = r.split.n_train
    settings = r.best_structure
    assert set(settings) == set(tuning.STRUCTURE_SETTINGS)
    # The written config is the selection on samples 0..N-1 alone, with the best factors applied ...
    sel = select(traj.X_meas[:N], traj.U[:N], traj.valid[:N], space=search.space(settings["max_delay"],
                 settings["degree"]), criterion=search.criterion, max_terms=settings["max_terms"])
    base = sel.config()  # P0 the fit's covariance of the weights, which trials scale (its shape kept)
    expected = refit_w0(tuning.apply_factors(base, r.space, r.best_values), traj.X_meas, traj.U, traj.valid,
                        N, base)  # a beta factor other than 1 refits w0 on the same samples
    assert [nr.terms for nr in r.config.neurons] == [nr.terms for nr in expected.neurons]
    for got, want in zip(r.config.neurons, expected.neurons):
        assert (got.q, got.r, got.eta, got.beta) == (want.q, want.r, want.eta, want.beta)
        np.testing.assert_array_equal(got.p0, want.p0)
        np.testing.assert_array_equal(got.w0, want.w0)
    # ... so the held-out part cannot have steered the terms, and its score is what the study recorded.
    assert tuning.held_out_score(r.config, traj.X_meas, traj.U, traj.valid, truth=traj.X).value == r.best.value
    changed = traj.X_meas.copy()
    changed[N:] *= 1.5
    sel2 = select(changed[:N], traj.U[:N], traj.valid[:N], space=search.space(settings["max_delay"],
                  settings["degree"]), criterion=search.criterion, max_terms=settings["max_terms"])
    assert [n.terms for n in sel2.neurons] == [n.terms for n in sel.neurons]


def test_structure_search_with_folds_selects_per_fold(traj: Trajectory, base: IdentifierConfig) -> None:
    # A base without delayed terms; the folds' selections may use the delays example1's plant has.
    plain = IdentifierConfig.uniform(terms.first_order(4, 1), n_states=4, n_inputs=1, p0=1e4, q=1e2, r=1e4)
    search = tuning.StructureSearch(max_delay=(0, 8), degree=(1, 2), max_terms=(2, 12))
    r = tuning.tune(plain, traj.X_meas, traj.U, traj.valid, truth=traj.X, structure=search, folds=3,
                    n_trials=10, seed=1)
    assert r.best is not None and len(r.best.folds) == 3
    assert r.best.value == pytest.approx(np.mean(r.best.folds), rel=1e-12)
    assert r.base is not None and r.best.value < r.base.value
    assert r.selection is not None and r.selection.rows < r.split.folds[-1][0]  # the last fold's training part


def test_structure_settings_beyond_capacity_or_data_are_refused(traj: Trajectory, base: IdentifierConfig) -> None:
    with pytest.raises(ValueError, match=r"^max_delay: low must be <= high"):
        tuning.StructureSearch(max_delay=(5, 1))
    with pytest.raises(ValueError, match=r"^degree.high"):
        tuning.StructureSearch(degree=(1, 9))
    with pytest.raises(ValueError, match=r"^structure.max_terms: 200 exceeds the compiled capacity"):
        tuning.tune(base, traj.X_meas, traj.U, structure=tuning.StructureSearch(max_terms=(2, 200)))


def test_threads_stop_at_the_study_total(tmp_path: Path, traj: Trajectory, base: IdentifierConfig) -> None:
    study = tmp_path / "s.log"
    r = tuning.tune(base, traj.X_meas, traj.U, n_trials=9, n_jobs=3, study_path=study)
    assert r.counts.total == 9 and r.new_trials == 9
    r = tuning.tune(base, traj.X_meas, traj.U, n_trials=13, n_jobs=3, study_path=study)
    assert r.counts.total == 13 and r.new_trials == 4


def installed(args: list[str], cwd: Path) -> subprocess.Popen[str]:
    env = dict(os.environ)
    env.pop("PYTHONPATH", None)  # the installed pyrhonn, run from a folder that cannot shadow it
    return subprocess.Popen([sys.executable, "-m", "pyrhonn.cli", "tune", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, cwd=str(cwd), env=env)


@pytest.mark.parametrize("study", ["s.log", "sqlite:///s.db"])
def test_two_workers_on_one_study_file_run_the_total(tmp_path: Path, study: str) -> None:
    trials = 30
    procs = [installed(["--example", "example1", "--horizon", "400", "--config", "example1", "--out", f"t{w}.toml",
                        "--study", study, "--trials", str(trials)], tmp_path) for w in range(2)]
    ran = []
    for p in procs:
        out, err = p.communicate(timeout=240)
        assert p.returncode == 0, err
        ran.append(int(re.search(r"^ran (\d+) trials", out, re.M).group(1)))
    assert sum(ran) == trials, ran
    assert (tmp_path / study.removeprefix("sqlite:///")).is_file()


def run_cli(args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = main(["tune", *args])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.parametrize("batch", ["1", "3"])
def test_cli_structure_search_writes_a_loadable_config(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                       batch: str) -> None:
    out = tmp_path / "s.toml"
    code, stdout, stderr = run_cli(["--example", "example1", "--horizon", "60", "--config", "example1", "--out",
                                    str(out), "--trials", "6", "--structure", "--max-delay", "0:4", "--degree", "1",
                                    "--folds", "2", "--batch", batch], capsys)
    assert code == 0, stderr
    assert "score per fold: " in stdout and "2 folds, fold f learning from sample 0" in stdout
    cf = load_config(out)
    assert "Tuned by `pyrhonn tune`" in cf.description
    assert "selected structure: max delay" in stdout, stdout  # a trial beat the shipped config
    text = " ".join(cf.description.split())  # its selection is written, with the selection's own texts
    assert "Terms selected from data by forward orthogonal least squares" in text
    assert re.search(r"Terms selected by pyrhonn select on samples 0\.\.\d+ with max delay \d, degree 1", text)
    assert all(len(t) == 1 for nr in cf.config.neurons for t in nr.terms)  # --degree 1
    assert all("ERR" in w for w in cf.why)


@pytest.mark.parametrize("change, message", [
    ({"--study": "postgresql://localhost"}, "--study: 'postgresql://localhost' names no database"),
    ({"--study": "mysql://u@h/db"}, "--study: 'mysql://u@h/db': database 'mysql' is not supported"),
    ({"--study": "sqlite://"}, "--study: 'sqlite://' names no database file"),
    ({"--study": "sqlite:///nowhere/s.db"}, "--study: 'sqlite:///nowhere/s.db': folder 'nowhere' does not exist"),
    ({"--study": "postgresql+nodriver://u@h/db"}, "--study: "),
    ({"--max-delay": "5"}, "--max-delay: only with --structure"),
    ({"--structure": "", "--max-delay": "3:1"}, "--max-delay: expected LOW <= HIGH"),
    ({"--structure": "", "--max-delay": "0:500"}, "--max-delay: "),
    ({"--structure": "", "--degree": "two"}, "--degree: expected LOW:HIGH or one whole number"),
    ({"--structure": "", "--max-terms": "2:300"}, "--max-terms: "),
    ({"--structure": "", "--criterion": "best"}, "--criterion: expected one of"),
    ({"--structure": "", "--factors": "S,y"}, "--factors: 'y' is not a factor kind"),
    ({"--folds": "0"}, "--folds: must be >= 1"),
    ({"--folds": "40"}, "--folds: 40 folds of the 21 held-out samples"),
])
def test_cli_bad_options_exit_2_naming_the_option(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                 capsys: pytest.CaptureFixture[str], change: dict[str, str],
                                                 message: str) -> None:
    monkeypatch.chdir(tmp_path)
    opts = {"--example": "example1", "--horizon": "10", "--config": "example1", "--out": "t.toml", "--trials": "2",
            **change}
    args = [x for k, v in opts.items() for x in ((k, v) if v else (k,))]
    code, stdout, stderr = run_cli(args, capsys)
    assert code == 2, stdout
    lines = stderr.strip().splitlines()
    assert lines[-1].startswith("pyrhonn tune: error: ") and message in lines[-1], stderr
    assert not Path("t.toml").exists()


# -- batched structure trials ------------------------------------------------------------------------------


@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_batched_structure_trials_share_their_settings_and_score_exactly_as_alone(
        traj: Trajectory, base: IdentifierConfig, dtype: str, population_calls: list[int]) -> None:
    calls = population_calls
    cfg = base.replace(dtype=dtype)
    search = tuning.StructureSearch(max_delay=(0, 6), degree=(1, 2), max_terms=(2, 10))
    # wide factor ranges: some tunings of a structure diverge and must fail alone, not take their batch along
    ranges = {"p0": (1e-3, 1e12), "eta": (0.5, 40.0)}
    r = tuning.tune(cfg, traj.X_meas, traj.U, traj.valid, truth=traj.X, structure=search, folds=2, n_trials=12,
                    batch=4, seed=3, ranges=ranges, n_startup_trials=12)
    assert r.counts.total == 12 and r.new_trials == 12 and r.counts.complete > 0 and r.top
    problem = tuning._Problem(cfg, traj.X_meas, traj.U, traj.valid, traj.X, tuning.DEFAULT_TRAIN_FRACTION, 2)
    selector = tuning._Selector(problem, search)
    for entry in r.top:
        settings = {name: int(entry["values"][name]) for name in tuning.STRUCTURE_SETTINGS}
        configs = [problem.refit(tuning.apply_factors(c, r.space, entry["values"]), c, problem.folds[f][0])
                   for f, c in enumerate(selector.configs(settings))]
        assert problem.score_folds(configs).value == entry["objective"]  # bit for bit what the trial ran alone
    assert calls and max(calls) >= 2 and all(c <= 4 for c in calls)
    assert len(calls) <= 2 * 3  # at most one population call per fold and batch


def test_a_batch_of_structure_trials_keeps_the_first_trials_settings(
        traj: Trajectory, base: IdentifierConfig, tmp_path: Path) -> None:
    import optuna

    search = tuning.StructureSearch(max_delay=(0, 6), degree=(1, 2), max_terms=(2, 10))
    study = tmp_path / "s.log"
    r = tuning.tune(base, traj.X_meas, traj.U, traj.valid, truth=traj.X, structure=search, n_trials=9, batch=3,
                    seed=0, study_path=study)
    assert r.counts.total == 9
    storage = tuning._open_storage(tuning.check_study(study))
    trials = optuna.load_study(study_name=tuning.STUDY_NAME, storage=storage).get_trials()
    assert len(trials) == 9
    batches = [trials[b:b + 3] for b in range(0, 9, 3)]
    for batch in batches:
        first = {name: batch[0].params.get(name) for name in tuning.STRUCTURE_SETTINGS}
        for t in batch[1:]:
            assert {name: t.params.get(name) for name in tuning.STRUCTURE_SETTINGS} == first
        assert len({tuple(sorted((k, v) for k, v in t.params.items() if k not in first)) for t in batch}) == 3
    assert len({tuple(b[0].params[name] for name in tuning.STRUCTURE_SETTINGS) for b in batches}) > 1


def test_score_folds_many_groups_trials_by_structure_and_matches_each_alone(
        traj: Trajectory, base: IdentifierConfig) -> None:
    problem = tuning._Problem(base, traj.X_meas, traj.U, traj.valid, traj.X, 0.6, 2)
    a = IdentifierConfig.uniform(terms.first_order(4, 1), n_states=4, n_inputs=1, p0=1e4, q=1e2, r=1e4)
    b = base
    tunings = [a, a.replace(neurons=tuple(replace(nr, eta=0.5) for nr in a.neurons)), b,
               b.replace(neurons=tuple(replace(nr, p0=nr.p0_matrix() * 10.0) for nr in b.neurons)),
               a.replace(neurons=tuple(replace(nr, eta=60.0, p0=1e12) for nr in a.neurons))]  # diverges
    trials = [[tunings[0], tunings[2]], [tunings[1], tunings[3]], [tunings[2], tunings[0]], [tunings[4], tunings[4]],
              [tunings[3], tunings[1]]]
    got = problem.score_folds_many(trials)
    for configs, outcome in zip(trials, got):
        try:
            alone: object = problem.score_folds(configs)
        except tuning.TrialFailure as exc:
            alone = exc
        if isinstance(alone, tuning.TrialFailure):
            assert isinstance(outcome, tuning.TrialFailure) and str(outcome) == str(alone)
        else:
            assert isinstance(outcome, tuning.Score) and outcome.value == alone.value  # type: ignore[attr-defined]
            np.testing.assert_array_equal(outcome.rmse, alone.rmse)  # type: ignore[attr-defined]
    assert any(isinstance(o, tuning.TrialFailure) for o in got)
    with pytest.raises(ValueError, match=r"^trials\[1\]: expected one config per fold \(2\), got 1"):
        problem.score_folds_many([[a, a], [a]])
