"""``pyrhonn tune`` and :mod:`pyrhonn.tuning`: the objective is what its docstring says, tuning never
does worse than the base config on the held-out part, the written config loads and runs, studies
resume, parallel trials work, diverging trials are recorded and skipped, and bad inputs exit 2."""
from __future__ import annotations

import csv
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from pyrhonn import Factor, Identifier, IdentifierConfig
from pyrhonn import tuning
from pyrhonn.cli import main
from pyrhonn.configfile import load_config, load_shipped, save_config
from pyrhonn.plants import Corruption, Trajectory, oscillator
from pyrhonn.regressors import refit_w0
from pyrhonn.simulation import simulate

HORIZON = 40.0  # 201 samples at T = 0.2 s: short, and still past the oscillator's start-up


@pytest.fixture(scope="module")
def traj() -> Trajectory:
    return oscillator.simulate(dt=0.2, horizon=HORIZON)


@pytest.fixture(scope="module")
def base() -> IdentifierConfig:
    return load_shipped("example1").config


def with_tuning(cfg: IdentifierConfig, **values: float) -> IdentifierConfig:
    return cfg.replace(neurons=tuple(replace(nr, **values) for nr in cfg.neurons))


def write_csv(path: Path, traj: Trajectory) -> None:
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["t", *traj.state_names, *traj.input_names])
        for k in range(traj.n_samples):
            w.writerow([repr(float(traj.t[k])), *(repr(float(v)) for v in traj.X_meas[k]),
                        *(repr(float(v)) for v in traj.U[k])])


# -- the objective -----------------------------------------------------------------------------------


def test_objective_is_the_documented_held_out_normalised_rmse(traj: Trajectory, base: IdentifierConfig) -> None:
    noisy = traj.remeasure(corruption=Corruption(dropout=0.1, seed=3))
    assert not noisy.valid.all()
    T = traj.n_samples
    N = int(np.floor(0.6 * T))
    rows = Identifier(base).run(noisy.X_meas, noisy.U, noisy.valid)  # one run, learning on throughout
    # Reference = measurements: valid held-out targets only.
    expected = []
    for j in range(4):
        keep = noisy.valid[N:, j]
        y, yhat = noisy.X_meas[N:, j][keep], rows[N - 1:-1, j][keep]
        expected.append(np.sqrt(np.mean((y - yhat) ** 2)) / np.std(y))
    s = tuning.held_out_score(base, noisy.X_meas, noisy.U, noisy.valid, train_fraction=0.6)
    assert s.value == pytest.approx(np.mean(expected), rel=1e-12)
    np.testing.assert_allclose(s.normalised, expected, rtol=1e-12)
    # Reference = truth: every held-out target.
    y, yhat = traj.X[N:], rows[N - 1:-1]
    rmse = np.sqrt(np.mean((y - yhat) ** 2, axis=0))
    t = tuning.held_out_score(base, noisy.X_meas, noisy.U, noisy.valid, truth=traj.X, train_fraction=0.6)
    np.testing.assert_allclose(t.rmse, rmse, rtol=1e-12)
    np.testing.assert_allclose(t.scale, np.std(y, axis=0), rtol=1e-12)
    assert t.value == pytest.approx(float(np.mean(rmse / np.std(y, axis=0))), rel=1e-12)


def test_split_point() -> None:
    assert tuning.split_point(10, 0.6) == 6
    assert tuning.split_point(201, 0.6) == 120
    for bad in (0.0, 1.0, -0.1, 0.95, float("nan"), True):
        with pytest.raises(ValueError, match="train_fraction"):
            tuning.split_point(10, bad)


# -- the search ----------------------------------------------------------------------------------------


def test_tuning_improves_the_held_out_score(traj: Trajectory, base: IdentifierConfig) -> None:
    r = tuning.tune(base, traj.X_meas, traj.U, traj.valid, truth=traj.X, n_trials=15, seed=0)
    assert r.base is not None and r.best is not None
    assert r.best.value <= r.base.value  # the base config is trial 0 of a new study
    assert r.improved and r.best.value < r.base.value
    assert r.top[0]["trial"] == r.best_trial and r.top[0]["objective"] == r.best.value
    assert r.counts == tuning.TrialCounts(total=15, complete=15, failed=0, errored=0, running=0)
    # The returned config scores exactly what the study recorded (values rounded before evaluation).
    again = tuning.held_out_score(r.config, traj.X_meas, traj.U, traj.valid, truth=traj.X)
    assert again.value == r.best.value
    for d in r.space:
        assert float(f"{r.best_values[d.name]:.2e}") == r.best_values[d.name]
        assert getattr(r.config.neurons[0], d.param) == r.best_values[d.name]
    assert r.config.neurons[0].terms == base.neurons[0].terms
    summary = r.summary()
    assert summary["trials"]["total"] == 15 and summary["best"]["objective"] == r.best.value


def test_per_neuron_search(traj: Trajectory, base: IdentifierConfig) -> None:
    r = tuning.tune(base, traj.X_meas, traj.U, n_trials=6, seed=1, per_neuron=True, params=("p0", "eta"))
    assert [d.name for d in r.space] == [f"neurons[{i}].p0" for i in range(4)] + \
        [f"neurons[{i}].eta" for i in range(4)]
    assert r.best is not None and r.base is not None and r.best.value <= r.base.value
    for nr in r.config.neurons:  # unsearched values stay as in the base config
        assert (nr.q, nr.r, nr.beta) == (base.neurons[0].q, base.neurons[0].r, base.neurons[0].beta)


@pytest.mark.parametrize("suffix", [".db", ".log"])
def test_resuming_a_study_continues_the_trial_count(tmp_path: Path, traj: Trajectory, base: IdentifierConfig,
                                                    suffix: str) -> None:
    study = tmp_path / f"study{suffix}"
    first = tuning.tune(base, traj.X_meas, traj.U, n_trials=3, study_path=study)
    assert first.counts.total == 3 and study.is_file()
    second = tuning.tune(base, traj.X_meas, traj.U, n_trials=5, study_path=study, seed=5)
    assert second.counts.total == 5 and second.new_trials == 2  # n_trials is the study's total
    again = tuning.tune(base, traj.X_meas, traj.U, n_trials=4, study_path=study)
    assert again.counts.total == 5 and again.new_trials == 0
    assert second.best is not None and first.best is not None and second.best.value <= first.best.value
    with pytest.raises(ValueError, match="different tuning problem.*train fraction"):
        tuning.tune(base, traj.X_meas, traj.U, n_trials=1, study_path=study, train_fraction=0.5)
    with pytest.raises(ValueError, match="different tuning problem.*base config"):
        tuning.tune(with_tuning(base, beta=0.02), traj.X_meas, traj.U, n_trials=1, study_path=study)


@pytest.mark.parametrize("suffix", [None, ".db", ".log"])
def test_parallel_trials(tmp_path: Path, traj: Trajectory, base: IdentifierConfig, suffix: str | None) -> None:
    # SQLite with threads once ran the enqueued base trial twice (optuna issue #4002): count exactly.
    lines: list[str] = []
    study = None if suffix is None else tmp_path / f"s{suffix}"
    r = tuning.tune(base, traj.X_meas, traj.U, n_trials=6, n_jobs=2, study_path=study, progress=lines.append)
    assert r.counts.total == 6 and r.counts.complete + r.counts.failed == 6
    assert len(lines) == 6 and all("best" in line for line in lines)
    assert r.best is not None and r.base is not None and r.best.value <= r.base.value


def test_diverging_trials_are_recorded_and_skipped(traj: Trajectory, base: IdentifierConfig) -> None:
    # P0 beyond ~1e30 loses positive definiteness, eta >> 1 blows the weights up: many trials fail.
    r = tuning.tune(base, traj.X_meas, traj.U, n_trials=20, seed=0,
                    ranges={"p0": (1e2, 1e36), "eta": (0.5, 50.0)})
    assert r.counts.failed > 0 and r.counts.complete > 0
    assert r.best is not None and np.isfinite(r.best.value)


def test_a_base_config_that_diverges_does_not_stop_the_search(traj: Trajectory, base: IdentifierConfig) -> None:
    bad = with_tuning(base, eta=30.0)
    with pytest.raises(ValueError, match="cannot be scored"):
        tuning.held_out_score(bad, traj.X_meas, traj.U)
    r = tuning.tune(bad, traj.X_meas, traj.U, n_trials=15, seed=0, ranges={"eta": (0.1, 30.0)})
    assert r.base is None and r.base_failure and "diverged" in r.base_failure
    assert r.improved and r.best is not None and r.counts.complete > 0
    # Nothing can be scored: the base config comes back, nothing crashes.
    hopeless = with_tuning(base, p0=1e33)
    r = tuning.tune(hopeless, traj.X_meas, traj.U, n_trials=4, params=("p0",), ranges={"p0": (1e31, 1e36)})
    assert r.counts.failed == 4 and not r.improved and r.best is None and r.config == hopeless


def test_search_space_defaults_and_overrides(base: IdentifierConfig) -> None:
    dims = {d.name: d for d in tuning.search_space(base)}
    assert list(dims) == ["p0", "q", "r", "eta", "beta"]
    assert (dims["p0"].low, dims["p0"].high, dims["p0"].base) == pytest.approx((1e4, 1e12, 1e8))
    assert (dims["eta"].low, dims["eta"].high) == pytest.approx((0.01, 2.0))
    assert dims["beta"].neurons == (0, 1, 2, 3)
    no_q = with_tuning(base, q=0.0)
    q = {d.name: d for d in tuning.search_space(no_q)}["q"]
    assert q.base is None and (q.low, q.high) == pytest.approx((1e8 * 1e-3 * 1e-4, 1e8 * 1e-3 * 1e4))
    over = {d.name: d for d in tuning.search_space(base, ranges={"r": (1e5, 1e6)})}["r"]
    assert (over.low, over.high, over.base) == (1e5, 1e6, None)  # base 1e4 out of range: not enqueued
    with pytest.raises(ValueError, match="params: unknown parameter 'gamma'"):
        tuning.search_space(base, params=("gamma",))
    with pytest.raises(ValueError, match="low must be < high"):
        tuning.search_space(base, ranges={"p0": (10.0, 1.0)})
    with pytest.raises(ValueError, match="ranges"):
        tuning.search_space(base, ranges={"p0": [1.0, 10.0]})  # type: ignore[dict-item]


def test_bad_library_inputs(tmp_path: Path, traj: Trajectory, base: IdentifierConfig) -> None:
    X, U = traj.X_meas, traj.U
    with pytest.raises(ValueError, match="^X: expected a float64"):
        tuning.tune(base, X.astype(np.float32), U)
    with pytest.raises(ValueError, match="^U: expected a float64 array of shape"):
        tuning.tune(base, X, U[:-1])
    with pytest.raises(ValueError, match="^n_trials"):
        tuning.tune(base, X, U, n_trials=0)
    with pytest.raises(ValueError, match="^n_jobs"):
        tuning.tune(base, X, U, n_jobs=0)
    with pytest.raises(ValueError, match="^study_path: .*unknown study file type"):
        tuning.tune(base, X, U, study_path=tmp_path / "s.txt")
    corrupt = tmp_path / "corrupt.db"
    corrupt.write_bytes(b"not a database\n" * 100)
    with pytest.raises(ValueError, match="not a readable optuna study file"):
        tuning.tune(base, X, U, n_trials=1, study_path=corrupt)


# -- the command ---------------------------------------------------------------------------------------------


def run_cli(args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = main(["tune", *args])
    out, err = capsys.readouterr()
    return code, out, err


def test_cli_writes_a_config_that_identify_and_identifier_accept(tmp_path: Path, traj: Trajectory,
                                                                 capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "tuned.toml"
    code, stdout, stderr = run_cli(["--example", "example1", "--dt", "0.2", "--horizon", str(HORIZON),
                                    "--config", "example1", "--out", str(out), "--trials", "8"], capsys)
    assert code == 0, stderr
    assert "score (mean normalised RMSE): base" in stdout and "-> tuned" in stdout
    assert "trial 7 [8/8]" in stderr
    cf = load_config(out)
    assert cf.state_names == ("x1", "x2", "x3", "x4") and "Tuned by `pyrhonn tune`" in cf.description
    rows = Identifier(cf.config).run(traj.X_meas, traj.U, traj.valid)
    assert np.all(np.isfinite(rows))
    # The file is a config like any other: identify runs it, and tune can start from it (on a CSV).
    data = tmp_path / "osc.csv"
    write_csv(data, traj)
    assert main(["identify", str(data), "--config", str(out), "--out", str(tmp_path / "id"), "--no-plots"]) == 0
    capsys.readouterr()
    again = tmp_path / "again.toml"
    code, stdout, stderr = run_cli(["--data", str(data), "--config", str(out), "--out", str(again),
                                    "--trials", "3", "--per-neuron", "--dtype", "float32"], capsys)
    assert code == 0, stderr
    assert load_config(again).config.dtype == "float32"


def test_cli_reports_the_held_out_free_run_of_the_base_and_the_written_config(
        tmp_path: Path, traj: Trajectory, capsys: pytest.CaptureFixture[str]) -> None:
    from pyrhonn.configfile import load_named
    from pyrhonn.simulation import scores, simulate

    data = tmp_path / "osc.csv"
    write_csv(data, traj)
    out = tmp_path / "tuned.toml"
    code, stdout, stderr = run_cli(["--data", str(data), "--config", "example1", "--out", str(out),
                                    "--trials", "3"], capsys)
    assert code == 0, stderr
    N = tuning.split_point(traj.n_samples, tuning.DEFAULT_TRAIN_FRACTION)
    assert f"held-out free run (weights frozen after sample {N - 1}" in stdout
    table = stdout.split("held-out free run")[1].splitlines()[2:6]
    X = np.where(traj.valid, traj.X_meas, 0.0)
    mask = np.zeros(X.shape, dtype=bool)
    mask[N:] = True
    mask &= traj.valid
    for column, cfg in ((0, load_named("example1").config), (1, load_config(out).config)):
        sim = simulate(Identifier(cfg), X, traj.U, traj.valid, free_run_from=N)
        want = scores(X, sim.free_run, mask)
        for j, line in enumerate(table):
            cells = line.split()
            assert float(cells[1 + column]) == pytest.approx(want.rmse[j], rel=1e-4)
            assert float(cells[3 + column]) == pytest.approx(want.rrse[j], rel=1e-4)


def test_cli_resumes_a_study(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    args = ["--example", "example1", "--horizon", "30", "--config", "example1", "--out", str(tmp_path / "t.toml"),
            "--study", str(tmp_path / "s.db"), "--n-jobs", "2"]
    assert run_cli([*args, "--trials", "3"], capsys)[0] == 0
    code, stdout, _ = run_cli([*args, "--trials", "5"], capsys)
    assert code == 0 and "ran 2 trials; the study has 5:" in stdout


@pytest.fixture
def corrupt_studies(tmp_path: Path) -> tuple[Path, Path]:
    db, log = tmp_path / "bad.db", tmp_path / "bad.log"
    db.write_bytes(b"SQLite format 2\x00" + b"\xff" * 600)
    log.write_text('{"op_code": 0, "worker_id": "x"\nnot json\n')
    return db, log


@pytest.mark.parametrize("change, message", [
    ({"--example": "example9"}, "--example: unknown example 'example9'"),
    ({"--data": "same"}, "exactly one"),
    ({"--example": None}, "exactly one"),
    ({"--dt": "0.01", "--example": "example2"}, "--dt: only example1"),
    ({"--train-fraction": "1.5"}, "--train-fraction: must be between 0 and 1"),
    ({"--train-fraction": "0"}, "--train-fraction: must be between 0 and 1"),
    ({"--train-fraction": "half"}, "--train-fraction: expected a number"),
    ({"--trials": "0"}, "--trials: must be >= 1"),
    ({"--n-jobs": "0"}, "--n-jobs: must be >= 1"),
    ({"--seed": "-1"}, "--seed: must be >= 0"),
    ({"--dtype": "float16"}, "--dtype: expected one of"),
    ({"--params": "p0,gamma"}, "--params: unknown parameter 'gamma'"),
    ({"--range": "p0=1e9"}, "--range: expected NAME=LOW:HIGH"),
    ({"--range": "p0=10:1"}, "expected 0 < LOW < HIGH"),
    ({"--config": "missing.toml"}, "--config: no such file"),
    ({"--config": "example99"}, "unknown config 'example99'"),
    ({"--config": None}, "--config: missing"),
    ({"--example": None, "--data": "missing.csv"}, "--data: no such file"),
    ({"--out": "nowhere/t.toml"}, "--out: folder"),
    ({"--out": "folder.toml"}, "--out: 'folder.toml' is a directory"),
    ({"--out": "t.json"}, "must end in .toml"),
    ({"--study": "s.txt"}, "--study: 's.txt': unknown study file type"),
    ({"--study": "corrupt-db"}, "--study: 'bad.db' is not a readable optuna study file"),
    ({"--study": "corrupt-log"}, "--study: 'bad.log' is not a readable optuna study file"),
    ({"--config": "two-states.toml"}, "has 2 states and 1 inputs, but example1's plant has 4"),
])
def test_cli_bad_inputs_exit_2_with_one_line(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                            capsys: pytest.CaptureFixture[str], corrupt_studies: tuple[Path, Path],
                                            change: dict[str, str | None], message: str) -> None:
    monkeypatch.chdir(tmp_path)
    Path("folder.toml").mkdir()
    opts: dict[str, str | None] = {"--example": "example1", "--horizon": "10", "--config": "example1",
                                   "--out": "t.toml", "--trials": "2"}
    opts.update(change)
    if opts.get("--data") == "same":
        opts["--data"] = "t.csv"
        Path("t.csv").write_text("t,x1\n")
    if opts.get("--study") in ("corrupt-db", "corrupt-log"):
        opts["--study"] = corrupt_studies[0 if opts["--study"] == "corrupt-db" else 1].name
    if opts.get("--data") is not None:
        opts.pop("--horizon")
    if opts.get("--config") == "two-states.toml":
        save_config(IdentifierConfig.uniform([(Factor.s(0),), (Factor.s(1), Factor.u(0))], n_states=2,
                                             n_inputs=1), "two-states.toml")
    args = [x for k, v in opts.items() if v is not None for x in (k, v)]
    code, stdout, stderr = run_cli(args, capsys)
    assert code == 2, stdout
    lines = stderr.strip().splitlines()
    assert lines[-1].startswith("pyrhonn tune: error: ") and message in lines[-1], stderr
    assert len([ln for ln in lines if "error" in ln]) == 1
    assert not Path("t.toml").exists()


def test_a_journal_cut_short_by_an_interrupted_write_is_named_as_the_study_file(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    log = tmp_path / "s.log"
    args = ["--example", "example1", "--horizon", "10", "--config", "example1", "--out", str(tmp_path / "t.toml"),
            "--study", str(log)]
    assert run_cli([*args, "--trials", "2"], capsys)[0] == 0
    log.write_bytes(log.read_bytes()[:-40])  # the last record half written
    code, _, stderr = run_cli([*args, "--trials", "1"], capsys)
    assert code == 2 and f"--study: '{log}' is not a readable optuna study file" in stderr
    assert "Traceback" not in stderr


def test_the_tuned_config_is_written_with_the_usual_file_mode(tmp_path: Path,
                                                              capsys: pytest.CaptureFixture[str]) -> None:
    import os

    out = tmp_path / "t.toml"
    assert run_cli(["--example", "example1", "--horizon", "10", "--config", "example1", "--out", str(out),
                    "--trials", "1"], capsys)[0] == 0
    umask = os.umask(0)
    os.umask(umask)
    assert out.stat().st_mode & 0o777 == 0o666 & ~umask  # not mkstemp's 0600


# -- batched trials ----------------------------------------------------------------------------------------


@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_batched_trials_score_exactly_as_each_alone_and_count_the_failing_ones(
        traj: Trajectory, base: IdentifierConfig, dtype: str, population_calls: list[int]) -> None:
    calls = population_calls
    noisy = traj.remeasure(corruption=Corruption(dropout=0.1, seed=5))
    cfg = base.replace(dtype=dtype)
    # wide ranges: some trials diverge (eta >> 1, P0 beyond ~1e30) or, in float32, are refused (P0
    # beyond its range); each must fail alone, not take its batch with it
    ranges = {"p0": (1e2, 1e36), "eta": (0.5, 50.0)}
    result = tuning.tune(cfg, noisy.X_meas, noisy.U, noisy.valid, n_trials=16, batch=4, seed=0, ranges=ranges,
                         n_startup_trials=16)
    assert result.counts.total == 16 and result.new_trials == 16
    assert result.counts.failed > 0 and result.counts.complete > 0
    # one population call per batch of 4 whose configs the core accepts, two or more of them (a refused config
    # is not run, and a lone runnable one runs as Identifier.run)
    assert 1 <= len(calls) <= 4 and min(calls) >= 2
    space = tuning.search_space(cfg, ranges=ranges)
    for entry in result.top:
        # a trial whose beta differs from the base's starts from w0 refitted on the training part
        trial = refit_w0(tuning.apply_values(cfg, space, entry["values"]), np.where(noisy.valid, noisy.X_meas, 0.0),
                         noisy.U, noisy.valid, result.split.n_train, cfg)
        alone = tuning.held_out_score(trial, noisy.X_meas, noisy.U, noisy.valid)
        assert entry["objective"] == alone.value  # bit for bit: the population runs each member as alone


def test_batch_is_refused_beyond_the_population_size(
        traj: Trajectory, base: IdentifierConfig, capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    from pyrhonn.population import max_population

    with pytest.raises(ValueError, match=r"batch: .* out of range 1\.\.8"):
        tuning.tune(base, traj.X_meas, traj.U, n_trials=1, batch=max_population() + 1)
    for args, message in ((["--batch", "9"], "--batch: at most 8"), (["--batch", "0"], "--batch")):
        code, _, err = run_cli(["--example", "example1", "--config", "example1", "--out",
                                str(tmp_path / "t.toml"), "--trials", "2", *args], capsys)
        assert code == 2 and message in err and "Traceback" not in err, err


def test_the_free_run_guard_keeps_the_base_when_the_best_trial_simulates_worse(
        traj: Trajectory, base: IdentifierConfig, monkeypatch: pytest.MonkeyPatch) -> None:
    calls: list[IdentifierConfig] = []

    def free_run_score(self: tuning._Problem, config: IdentifierConfig) -> float:
        calls.append(config)
        return 0.5 if config == base else 0.9  # the base simulates, every tuned config worse

    monkeypatch.setattr(tuning._Problem, "free_run_score", free_run_score)
    r = tuning.tune(base, traj.X_meas, traj.U, traj.valid, n_trials=6, seed=0)
    assert not r.improved and r.config == base and r.best_trial is None
    assert r.kept_base is not None and "free run" in r.kept_base and "0.9" in r.kept_base
    assert r.summary()["kept_base"] == r.kept_base and r.summary()["free_run"]["written"] == 0.5
    guarded = tuning.tune(base, traj.X_meas, traj.U, traj.valid, n_trials=6, seed=0, free_run_guard=False)
    assert guarded.improved and guarded.kept_base is None  # the same search writes its best without the guard


def test_the_free_run_score_is_the_held_out_free_run_rrse(traj: Trajectory, base: IdentifierConfig) -> None:
    problem = tuning._Problem(base, traj.X_meas, traj.U, traj.valid, None, tuning.DEFAULT_TRAIN_FRACTION)
    N = problem.n_train
    sim = simulate(Identifier(base), traj.X_meas, traj.U, traj.valid, free_run_from=N)
    e = traj.X_meas[N:] - sim.free_run[N:]
    rrse = np.sqrt(np.sum(e ** 2, axis=0) / np.sum((traj.X_meas[N:] - traj.X_meas[N:].mean(axis=0)) ** 2, axis=0))
    assert problem.free_run_score(base) == pytest.approx(float(np.mean(rrse)), rel=1e-12)


def test_a_tuned_select_config_keeps_each_neuron_s_p0_shape(traj: Trajectory) -> None:
    """select's P0 is the fit's covariance of the weights (a matrix): a trial
    scales it (its diagonal's geometric mean becomes the trial value), so the
    tuned config keeps every weight's own P0 and the matrix's conditioning
    instead of a multiple of the identity; a factor (structure search)
    scales it too."""
    from pyrhonn.structure import CandidateSpace, select
    sel = select(traj.X_meas[:, :2], traj.U, traj.valid[:, :2], space=CandidateSpace(max_delay=1, degree=1),
                 max_terms=4)
    cfg = sel.config()
    assert all(isinstance(nr.p0, np.ndarray) and nr.p0.ndim == 2 for nr in cfg.neurons)
    r = tuning.tune(cfg, traj.X_meas[:, :2], traj.U, traj.valid[:, :2], n_trials=3, seed=0, params=("p0", "q"))
    assert r.best_values is not None
    for nr, nb in zip(r.config.neurons, cfg.neurons):
        assert isinstance(nr.p0, np.ndarray) and nr.p0.shape == nb.p0.shape
        ratio = nr.p0 / nb.p0
        np.testing.assert_allclose(ratio, ratio[0, 0], rtol=1e-12)  # one factor: the shape kept
        geo = float(np.exp(np.mean(np.log(np.diag(nr.p0)))))
        assert geo == pytest.approx(r.best_values["p0"], rel=1e-12)
        assert nr.q == r.best_values["q"]  # select's Q is a scalar: set, as before
    space = tuning.search_space(cfg, params=("p0",), relative=True)
    scaled = tuning.apply_factors(cfg, space, {"p0": 3.0})
    for nr, nb in zip(scaled.neurons, cfg.neurons):
        np.testing.assert_allclose(nr.p0, 3.0 * nb.p0, rtol=1e-15)
