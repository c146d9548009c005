"""Structure selection (pyrhonn.structure, ``pyrhonn select``): a plant of
known terms and state delay is recovered exactly from noise-free data, the
written config loads and identifies, and every bad input is refused with a
message naming the option, column or line."""
from __future__ import annotations

import json

import csv
from pathlib import Path

import numpy as np
import pytest

from pyrhonn import Activation, Factor, Identifier, capacities
from pyrhonn.cli import main
from pyrhonn.config import monomial
from pyrhonn.configfile import dumps, load_config, loads
from pyrhonn.structure import CandidateSpace, Criterion, candidate_terms, select

DELAY = 5


def S(v: np.ndarray | float) -> np.ndarray:
    return np.tanh(0.5 * np.asarray(v))  # the bipolar activation, beta = 1


def plant(T: int = 1500, seed: int = 3, delay: int = DELAY) -> tuple[np.ndarray, np.ndarray]:
    """x1(k+1) = 0.6 S(x1) - 0.4 S(x2(k-delay)) + 0.5 u1;  x2(k+1) = 0.7 S(x2) + 0.5 S(x1) u1 + 0.3."""
    rng = np.random.default_rng(seed)
    U = rng.uniform(-1.0, 1.0, (T, 1))
    X = np.zeros((T, 2))
    for k in range(T - 1):
        xd = X[max(k - delay, 0)]
        X[k + 1, 0] = 0.6 * S(X[k, 0]) - 0.4 * S(xd[1]) + 0.5 * U[k, 0]
        X[k + 1, 1] = 0.7 * S(X[k, 1]) + 0.5 * S(X[k, 0]) * U[k, 0] + 0.3
    return X, U


TRUTH = [
    {(Factor.s(0),): 0.6, (Factor.s(1, delay=DELAY),): -0.4, (Factor.u(0),): 0.5},
    {(Factor.s(1),): 0.7, (Factor.s(0), Factor.u(0)): 0.5, (Factor.one(),): 0.3},
]
SPACE = CandidateSpace(max_delay=8, degree=2)


@pytest.fixture(scope="module")
def data() -> tuple[np.ndarray, np.ndarray]:
    return plant()


def write_csv(path: Path, X: np.ndarray, U: np.ndarray, *, valid: np.ndarray | None = None) -> None:
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["t", "x1", "x2", "u1"] + (["x1_valid", "x2_valid"] if valid is not None else []))
        for k in range(X.shape[0]):
            row = [repr(0.1 * k)] + [repr(float(v)) for v in X[k]] + [repr(float(U[k, 0]))]
            if valid is not None:
                row += [str(int(v)) for v in valid[k]]
            w.writerow(row)


@pytest.mark.parametrize("criterion", ["ebic", "bic", "aic", "holdout"])
def test_known_terms_and_delay_are_recovered_from_noise_free_data(data, criterion: str) -> None:
    X, U = data
    sel = select(X, U, space=SPACE, criterion=criterion)
    for i, truth in enumerate(TRUTH):
        nr = sel.neurons[i]
        assert nr.activation is Activation.BIPOLAR and nr.beta == 1.0
        got = {monomial(t.term): t.weight for t in nr.terms}
        assert set(got) == {monomial(t) for t in truth}, sel.report()
        for term, w in truth.items():
            assert got[monomial(term)] == pytest.approx(w, abs=1e-9)
        assert nr.err_total == pytest.approx(1.0, abs=1e-9)
    assert sel.state_delays() == (None, DELAY)
    assert sel.neurons[0].delays == ((1, DELAY),)


def test_the_delay_is_found_wherever_it_is(data) -> None:
    X, U = plant(delay=3)
    sel = select(X, U, space=SPACE)
    assert sel.state_delays() == (None, 3)


def test_terms_are_listed_in_the_order_of_their_error_reduction(data) -> None:
    X, U = data
    nr = select(X, U, space=SPACE).neurons[0]
    # the first term chosen explains the most of the target on its own
    first = nr.terms[0]
    assert first.err == max(t.err for t in nr.terms)
    assert "ERR" in select(X, U, space=SPACE).report()


def test_selected_config_round_trips_and_identifies_the_plant(data) -> None:
    X, U = data
    sel = select(X, U, space=SPACE)
    cf = sel.config_file(("x1", "x2"), ("u1",))
    again = loads(dumps(cf))
    assert again.config == cf.config
    ident = Identifier(again.config)
    Xhat = ident.run(X, U)
    e = X[1:] - Xhat[:-1]
    assert np.max(np.abs(e[SPACE.window + 1:])) < 1e-6
    assert all(h.rejected == 0 for h in ident.healths)


def test_cli_select_writes_a_config_that_identify_accepts(data, tmp_path: Path,
                                                          capsys: pytest.CaptureFixture[str]) -> None:
    X, U = data
    csv_path, cfg_path, report = tmp_path / "run.csv", tmp_path / "sel.toml", tmp_path / "report.txt"
    write_csv(csv_path, X, U)
    assert main(["select", str(csv_path), "--states", "x1,x2", "--inputs", "u1", "--out", str(cfg_path),
                 "--max-delay", "8", "--report", str(report), "--json", str(tmp_path / "sel.json")]) == 0
    out = capsys.readouterr().out
    assert "estimated delay per state: x1 -, x2 5" in out
    assert report.read_text().strip() in out
    # the recovered model, its least-squares weights frozen, reproduces the plant one step ahead and
    # fed its own predictions: the report says so per state, RMSE and RRSE
    assert f"on the same data from sample {8 + 1} on:" in out
    checked = json.loads((tmp_path / "sel.json").read_text())["validation"]
    assert checked["from_sample"] == 9
    for kind in ("one_step", "free_run"):
        for name in ("x1", "x2"):
            assert 0 <= checked[kind][name]["rrse"] < 1e-6 and 0 <= checked[kind][name]["rmse"] < 1e-6
    cf = load_config(cfg_path)
    assert {monomial(t) for t in cf.config.neurons[0].terms} == {monomial(t) for t in TRUTH[0]}
    assert main(["identify", str(csv_path), "--config", str(cfg_path), "--out", str(tmp_path / "id"),
                 "--no-plots"]) == 0
    assert (tmp_path / "id" / "metrics.json").exists()


def test_invalid_samples_leave_their_rows_out(data) -> None:
    X, U = data
    X = X.copy()
    valid = np.ones(X.shape, dtype=bool)
    valid[200:210, 1] = False
    X[200:210, 1] = np.nan
    sel = select(X, U, valid, space=SPACE)
    assert sel.rows_dropped == 10 + SPACE.window + 1
    assert {monomial(t.term) for t in sel.neurons[0].terms} == {monomial(t) for t in TRUTH[0]}


def test_candidate_terms_follow_the_space() -> None:
    space = CandidateSpace(max_delay=2, degree=2, factors=("S", "1"), activations=(Activation.BIPOLAR,))
    terms = candidate_terms(space, 2, 0)
    atoms = 2 * 3
    assert len(terms) == atoms + atoms * (atoms + 1) // 2 + 1
    assert (Factor.s(0, power=2),) in terms and (Factor.one(),) in terms
    assert CandidateSpace(max_delay=20, delay_step=5).delays == (0, 1, 5, 10, 15, 20)


def run_cli(capsys: pytest.CaptureFixture[str], *argv: str) -> str:
    assert main(list(argv)) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    return err


def test_bad_options_are_named(data, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    X, U = data
    csv_path, out = tmp_path / "run.csv", tmp_path / "sel.toml"
    write_csv(csv_path, X, U)
    base = ["select", str(csv_path), "--states", "x1,x2", "--inputs", "u1", "--out", str(out)]
    caps = capacities()
    over = str(caps["RHONN_MAX_DELAY"] + 1)
    assert "--max-delay: " in run_cli(capsys, *base, "--max-delay", over)
    err = run_cli(capsys, *base, "--max-terms", str(caps["RHONN_MAX_TERMS"] + 1))
    assert "--max-terms: " in err and "RHONN_MAX_TERMS" in err
    assert "--degree: " in run_cli(capsys, *base, "--degree", "0")
    assert "--factors: 'y'" in run_cli(capsys, *base, "--factors", "S,y")
    assert "--activation: 'relu'" in run_cli(capsys, *base, "--activation", "relu")
    assert "--beta: " in run_cli(capsys, *base, "--beta", "0")
    assert "--holdout: " in run_cli(capsys, *base, "--criterion", "holdout", "--holdout", "1.5")
    assert "--input-max-delay: " in run_cli(capsys, *base, "--input-max-delay", "x")
    assert "missing column 'speed'" in run_cli(capsys, *base[:3], "x1,speed", *base[4:])
    assert "--states: state_names[1]: 'x3' would be confused" in run_cli(capsys, *base[:3], "x1,x3", *base[4:])
    assert not out.exists()


def test_too_little_data_is_refused_before_any_work(data, tmp_path: Path, capsys) -> None:
    X, U = data
    csv_path = tmp_path / "short.csv"
    write_csv(csv_path, X[:40], U[:40])
    err = run_cli(capsys, "select", str(csv_path), "--states", "x1,x2", "--inputs", "u1",
                  "--out", str(tmp_path / "c.toml"), "--max-delay", "8")
    assert "usable rows" in err and "max_terms = 16 needs at least 64" in err


def test_constant_and_collinear_columns_are_named(data, tmp_path: Path, capsys) -> None:
    X, U = data
    csv_path = tmp_path / "const.csv"
    write_csv(csv_path, X, np.full_like(U, 0.25))
    err = run_cli(capsys, "select", str(csv_path), "--states", "x1,x2", "--inputs", "u1", "--out",
                  str(tmp_path / "c.toml"))
    assert "input column 'u1': constant" in err
    Xc = X.copy()
    Xc[:, 1] = 2.0 * X[:, 0] + 1.0
    with pytest.raises(ValueError, match=r"state column 'x2': the same as state column 'x1'"):
        select(Xc, U, space=SPACE)


def test_a_missing_value_in_a_valid_row_names_its_line(data, tmp_path: Path, capsys) -> None:
    X, U = data
    X = X.copy()
    X[57, 0] = np.nan
    csv_path = tmp_path / "nan.csv"
    write_csv(csv_path, X, U)
    err = run_cli(capsys, "select", str(csv_path), "--states", "x1,x2", "--inputs", "u1", "--out",
                  str(tmp_path / "c.toml"))
    assert "line 59" in err and "'x1'" in err
    with pytest.raises(ValueError, match=r"^X: row 57, x1: not finite"):
        select(X, U, space=SPACE)


def test_collinear_candidates_are_never_chosen_twice(data) -> None:
    # S and x of the same state at small beta, and a bias beside products: many near-duplicate columns
    X, U = data
    sel = select(X, U, space=CandidateSpace(max_delay=8, degree=2, factors=("S", "x", "u", "1"),
                                            activations=(Activation.BIPOLAR,)), criterion=Criterion.EBIC)
    for nr in sel.neurons:
        assert len({monomial(t.term) for t in nr.terms}) == len(nr.terms)
        assert all(np.isfinite(t.weight) for t in nr.terms)


def _small_scale_plant(T: int = 2000, seed: int = 5) -> tuple[np.ndarray, np.ndarray]:
    """x(k+1) = 0.8 x + 1e-3 u - 2e4 x^3 + noise, x of order 1e-3: the cube's regressor is a million
    times smaller than x's, so the fit's weight variances lie many decades apart."""
    rng = np.random.default_rng(seed)
    U = rng.uniform(-1.0, 1.0, (T, 1))
    X = np.zeros((T, 1))
    for k in range(T - 1):
        x = X[k, 0]
        X[k + 1, 0] = 0.8 * x + 1e-3 * U[k, 0] - 2e4 * x ** 3 + rng.normal(0.0, 1e-6)
    return X, U


def test_the_fit_p0_keeps_the_variance_of_every_weight_whatever_the_regressors_scale() -> None:
    """The fit's P0 = sigma^2 (Z^T Z)^-1 is conditioned for the core on its correlations, not on
    its eigenvalues: the well-determined weights (of x, of u) keep their least-squares variances
    even beside a cube whose weight's variance is decades larger; online learning then continues
    the fit instead of moving them beyond their uncertainty, and Q stays below every variance."""
    X, U = _small_scale_plant()
    sel = select(X, U, space=CandidateSpace(factors=("x", "u", "1"), degree=3))
    nr = sel.neurons[0]
    assert nr.covariance is not None and len(nr.terms) >= 3
    exact = nr.residual_variance * nr.covariance
    cfg = sel.config()
    P0 = np.asarray(cfg.neurons[0].p0)
    variances = np.diag(exact)
    assert variances.max() / variances.min() > 1e12  # the scales this guards against
    np.testing.assert_allclose(np.diag(P0), variances, rtol=1e-6)
    q = float(cfg.neurons[0].q)
    assert 0.0 < q <= variances.min() / sel.rows
    Identifier(cfg)  # the core factorises it
    # learning online on a continuation of the same plant predicts as well as the frozen weights
    Xv, Uv = _small_scale_plant(seed=6)
    frozen = Identifier(cfg)
    frozen.learning = False
    e_frozen = Xv[2:, 0] - frozen.run(Xv, Uv)[1:-1, 0]
    e_online = Xv[2:, 0] - Identifier(cfg).run(Xv, Uv)[1:-1, 0]
    assert np.sqrt(np.mean(e_online ** 2)) <= 1.05 * np.sqrt(np.mean(e_frozen ** 2))
