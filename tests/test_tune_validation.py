"""``pyrhonn tune`` judged on data kept apart: trials learn on the estimation data only and are
scored on validation recordings (weights frozen), by the objective asked for (one-step, free-run,
k-step:H, mix); a diverging free run fails the trial naming the sample; the base config is kept
when no trial beats it on that objective; bad options are refused naming the option."""
from __future__ import annotations

import csv
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from pyrhonn import Factor, Identifier, IdentifierConfig
from pyrhonn import tuning
from pyrhonn.cli import main
from pyrhonn.configfile import ConfigFile, load_config, save_config
from pyrhonn.experiments import Experiment
from pyrhonn.refine import DataRange
from pyrhonn.search import validate
from pyrhonn.simulation import simulate
from pyrhonn.tuning_validation import learnt, validated_score

T = 240


def plant(gain: float, seed: int, n: int = T) -> tuple[np.ndarray, np.ndarray]:
    """x(k+1) = 0.8 x(k) + gain tanh(u(k)): a stable first-order plant, a random-step input."""
    rng = np.random.default_rng(seed)
    u = np.repeat(rng.uniform(-1.5, 1.5, n // 8 + 1), 8)[:n]
    x = np.zeros(n)
    for k in range(n - 1):
        x[k + 1] = 0.8 * x[k] + gain * np.tanh(u[k])
    return x[:, None], u[:, None]


def experiment(gain: float, seed: int, name: str) -> Experiment:
    X, U = plant(gain, seed)
    return Experiment(X, U, np.ones(X.shape, dtype=bool), name=name)


@pytest.fixture(scope="module")
def base() -> IdentifierConfig:
    terms = ((Factor.x(0),), (Factor.u(0),), (Factor.one(),))
    return IdentifierConfig.uniform(terms, n_states=1, n_inputs=1, p0=10.0, q=1e-4, r=1.0, eta=1.0)


def test_validation_data_never_learn(base: IdentifierConfig) -> None:
    """The weights are those learnt on the estimation data alone: a validation recording of another
    plant changes the score, not the weights; learning on the validation data would change them."""
    est = experiment(1.0, 1, "est")
    same, other = experiment(1.0, 2, "val"), experiment(3.0, 2, "val")
    frozen = learnt(base, [est])
    assert not np.allclose(frozen.neurons[0].w0_vector(), base.neurons[0].w0_vector())
    objective = tuning.Objective("free-run")
    s_same, v_same = validated_score(base, [est], [same], objective)
    s_other, _ = validated_score(base, [est], [other], objective)
    assert s_other.value > 2 * s_same.value  # the validation data are what is scored
    # The frozen model's figures are validate() of the weights learnt on est only
    expected = validate(frozen, [same], DataRange.of([est]))
    np.testing.assert_allclose(v_same.free_rrse, expected.free_rrse, rtol=1e-12)
    np.testing.assert_allclose(s_same.normalised, expected.free_rrse, rtol=1e-12)
    # ... and not of weights that also learnt the validation data.
    both = validate(learnt(base, [est, same]), [same], DataRange.of([est]))
    assert not np.allclose(both.one_rrse, v_same.one_rrse)
    # Through tune: each trial's recorded score is that of weights learnt on est alone.
    r = tuning.tune(base, est.X, est.U, est.valid, validation=[other], objective="free-run", n_trials=4,
                    n_startup_trials=4, estimation_name="est")
    assert r.fit_rows == ("est rows 0..239",) and r.validation_rows == ("val rows 0..239",)
    redo, _ = validated_score(r.config, [est], [other], objective)
    assert r.best is not None and r.best.value == pytest.approx(redo.value, rel=1e-12)


@pytest.mark.parametrize("kind", ["one-step", "free-run", "k-step:3", "mix"])
def test_the_objective_is_the_figure_of_that_kind(base: IdentifierConfig, kind: str) -> None:
    est, val = experiment(1.0, 1, "est"), experiment(1.0, 2, "val")
    score, v = validated_score(base, [est], [val], tuning.Objective.parse(kind))
    if kind == "one-step":
        np.testing.assert_allclose(score.normalised, v.one_rrse, rtol=1e-12)
    elif kind == "free-run":
        np.testing.assert_allclose(score.normalised, v.free_rrse, rtol=1e-12)
    elif kind == "mix":
        np.testing.assert_allclose(score.normalised, np.sqrt(v.one_rrse * v.free_rrse), rtol=1e-12)
    else:  # x(k) predicted from x(k - 3) measured, weights frozen, from the first sample it can be
        ident = Identifier(learnt(base, [est]))
        ident.learning = False
        ahead = simulate(ident, val.X, val.U, val.valid, steps=3).ahead
        assert ahead is not None
        y, yhat = val.X[3:, 0], ahead[3:, 0]
        rrse = np.sqrt(np.sum((y - yhat) ** 2) / np.sum((y - y.mean()) ** 2))
        assert score.normalised[0] == pytest.approx(rrse, rel=1e-9)
        assert v.one_rrse[0] < rrse
    assert score.value == pytest.approx(float(np.mean(score.normalised)))


def test_the_chosen_objective_drives_the_choice(base: IdentifierConfig) -> None:
    """The same 12 random candidates (start-up trials only, one seed) ranked by two objectives: each
    picks its own best, and the free-run pick simulates better than the one-step pick."""
    est, val = experiment(1.0, 1, "est"), experiment(1.0, 2, "val")
    res = {kind: tuning.tune(base, est.X, est.U, est.valid, validation=[val], objective=kind, n_trials=12,
                             n_startup_trials=12, seed=3)
           for kind in ("one-step", "free-run")}
    one, free = res["one-step"], res["free-run"]
    assert one.best_trial != free.best_trial
    score = {(pick, kind): validated_score(res[pick].config, [est], [val], tuning.Objective(kind))[0].value
             for pick in res for kind in res}
    assert score["free-run", "free-run"] < score["one-step", "free-run"]
    assert score["one-step", "one-step"] < score["free-run", "one-step"]
    assert one.best is not None and free.best is not None
    assert one.best.value == pytest.approx(score["one-step", "one-step"], rel=1e-12)
    assert free.best.value == pytest.approx(score["free-run", "free-run"], rel=1e-12)


def test_the_base_is_kept_when_no_trial_beats_it_on_the_objective(base: IdentifierConfig) -> None:
    est, val = experiment(1.0, 1, "est"), experiment(1.0, 2, "val")
    r = tuning.tune(base, est.X, est.U, est.valid, validation=[val], objective="free-run", n_trials=4,
                    params=("q",), ranges={"q": (10.0, 100.0)})  # every trial forgets fast: worse
    assert not r.improved and r.config is base
    assert r.kept_base is not None and "free-run score" in r.kept_base and "base config is kept" in r.kept_base


def test_bad_validation_arguments_are_refused_naming_them(base: IdentifierConfig) -> None:
    est, val = experiment(1.0, 1, "est"), experiment(1.0, 2, "val")
    two = Experiment(np.hstack([val.X, val.X]), val.U, np.ones((T, 2), dtype=bool), name="two")
    for kwargs, name in (({"validation": val}, "validation"), ({"validation": [two]}, "validation"),
                         ({"validation": [val], "folds": 2}, "folds"),
                         ({"validation": [val], "truth": est.X}, "truth"),
                         ({"validation": [val], "structure": tuning.StructureSearch()}, "structure"),
                         ({"objective": "k-step:0"}, "objective"),
                         ({"objective": "mix", "structure": tuning.StructureSearch()}, "objective")):
        with pytest.raises(ValueError, match=name):
            tuning.tune(base, est.X, est.U, est.valid, n_trials=1, **kwargs)  # type: ignore[arg-type]


def test_a_diverging_free_run_fails_the_trial_naming_the_sample(base: IdentifierConfig) -> None:
    est, val = experiment(1.0, 1, "est"), experiment(1.0, 2, "val")
    unstable = base.replace(neurons=tuple(replace(nr, eta=1e-9, w0=np.array([1.6, 0.0, 0.0]))
                                          for nr in base.neurons))
    with pytest.raises(tuning.TrialFailure, match=r"val: free run left the data's range at sample \d+"):
        validated_score(unstable, [est], [val], tuning.Objective("free-run"))
    # One step ahead it still scores (the measured state is fed back)
    validated_score(unstable, [est], [val], tuning.Objective("one-step"))


def test_single_file_frozen_objective_and_the_base_kept(base: IdentifierConfig) -> None:
    """Without validation files a frozen objective scores the held-out part with the weights frozen
    at the split; the written config is never worse than the base on it."""
    X, U = plant(1.0, 1, 300)
    s = tuning.held_out_score(base, X, U)  # learning on
    r = tuning.tune(base, X, U, objective="free-run", n_trials=3, n_startup_trials=3)
    assert r.objective == "free-run"
    assert r.base is not None and r.best is not None and r.best.value <= r.base.value
    assert r.base.value != pytest.approx(s.value)
    with pytest.raises(ValueError, match="objective"):
        tuning.tune(base, X, U, objective="free-run", folds=2, n_trials=1)
    for bad in ("free", "k-step", "k-step:1", "k-step:x", "mix:2", 3):
        with pytest.raises(ValueError, match="objective"):
            tuning.Objective.parse(bad)


def write(path: Path, X: np.ndarray, U: np.ndarray) -> None:
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["t", "y", "u"])
        for k in range(X.shape[0]):
            w.writerow([k, repr(float(X[k, 0])), repr(float(U[k, 0]))])


@pytest.fixture()
def files(tmp_path: Path, base: IdentifierConfig) -> Path:
    X, U = plant(1.0, 1)
    write(tmp_path / "est.csv", X, U)
    X, U = plant(1.0, 2)
    write(tmp_path / "val.csv", X, U)
    save_config(ConfigFile.from_config(base, state_names=("y",), input_names=("u",)), tmp_path / "base.toml")
    return tmp_path


def test_cli_validate_and_fit_rows(files: Path, capsys: pytest.CaptureFixture[str]) -> None:
    d = files
    code = main(["tune", "--data", str(d / "est.csv"), "--validate", str(d / "val.csv"), "--config",
                 str(d / "base.toml"), "--out", str(d / "t.toml"), "--trials", "3", "--objective", "free-run",
                 "--json", str(d / "t.json")])
    assert code == 0
    out = capsys.readouterr().out
    assert f"learning on {d / 'est.csv'} rows 0..239" in out and f"{d / 'val.csv'} rows 0..239" in out
    assert "free-run base" in out
    payload = json.loads((d / "t.json").read_text())
    assert payload["fit_rows"] == [f"{d / 'est.csv'} rows 0..239"]
    assert payload["validation_rows"] == [f"{d / 'val.csv'} rows 0..239"]
    assert payload["objective_kind"] == "free-run"
    assert set(payload["validation_figures"]) == {"base", "tuned"}
    load_config(d / "t.toml")
    # --fit-rows without --validate: the rest of the file validates
    code = main(["tune", "--data", str(d / "est.csv"), "--fit-rows", "0:160", "--config", str(d / "base.toml"),
                 "--out", str(d / "t2.toml"), "--trials", "2", "--json", str(d / "t2.json")])
    assert code == 0
    payload = json.loads((d / "t2.json").read_text())
    assert payload["fit_rows"] == [f"{d / 'est.csv'} rows 0..159"]
    assert payload["validation_rows"] == [f"{d / 'est.csv'} rows 160..239"]


@pytest.mark.parametrize("extra, option", [
    (["--objective", "sideways"], "--objective"),
    (["--objective", "k-step:1"], "--objective"),
    (["--validate", "missing.csv"], "--validate"),
    (["--fit-rows", "5:3"], "--fit-rows"),
    (["--fit-rows", "0:240"], "--fit-rows"),
    (["--validate", "VAL", "--train-fraction", "0.5"], "--train-fraction"),
    (["--validate", "VAL", "--folds", "2"], "--folds"),
    (["--objective", "free-run", "--folds", "2"], "--objective"),
    (["--json", "x.txt"], "--json"),
])
def test_cli_bad_options_name_the_option(files: Path, capsys: pytest.CaptureFixture[str], extra: list[str],
                                         option: str) -> None:
    d = files
    extra = [str(d / "val.csv") if e == "VAL" else e for e in extra]
    code = main(["tune", "--data", str(d / "est.csv"), "--config", str(d / "base.toml"), "--out",
                 str(d / "t.toml"), "--trials", "1", *extra])
    assert code == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and option in err
    assert not (d / "t.toml").exists()
