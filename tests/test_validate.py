"""``pyrhonn validate``: on CSV files of a known linear plant and configs carrying its weights,
the report's figures are pyrhonn.simulation's with the weights frozen, each file scored from its
own first sample with measured taps; the residual analysis finds a right model's residuals white
and independent of the input and a model missing the input term correlated with it; a diverging
model is reported with the sample where it left and fails --min-fit; --min-fit above the fit
exits 1 and below it 0; every bad input exits 2 naming the option or file."""
from __future__ import annotations

import contextlib
import csv
import io
import json
import re
from pathlib import Path

import numpy as np
import pytest

from pyrhonn import Identifier, atomic
from pyrhonn.cli import main
from pyrhonn.configfile import load_config
from pyrhonn.metrics import rmse, rrse
from pyrhonn.residuals import autocorrelation, cross_correlation, stretches
from pyrhonn.simulation import Simulation, simulate

D = 2          #: the deepest tap of the configs below, x1(k-2)
K = D + 1      #: the first sample scored
H = 4          #: --steps-ahead of the tests


def plant(T: int, seed: int, noise: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    """x1(k+1) = 0.6 x1(k) + 0.25 x1(k-2) + 0.5 u1(k) + w1;  x2(k+1) = 0.7 x2(k) + 0.4 x1(k) + w2,
    w white (equation error): the exact model's one-step residual is w itself."""
    rng = np.random.default_rng(seed)
    U = rng.uniform(-1.0, 1.0, (T, 1))
    W = noise * rng.standard_normal((T, 2))
    X = np.zeros((T, 2))
    for k in range(T - 1):
        X[k + 1, 0] = 0.6 * X[k, 0] + 0.25 * X[max(k - 2, 0), 0] + 0.5 * U[k, 0] + W[k, 0]
        X[k + 1, 1] = 0.7 * X[k, 1] + 0.4 * X[k, 0] + W[k, 1]
    return X, U


def write_csv(path: Path, X: np.ndarray, U: np.ndarray, valid: np.ndarray | None = None) -> Path:
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["x1", "x2", "u1"] + (["x1_valid", "x2_valid"] if valid is not None else []))
        for k in range(X.shape[0]):
            ok = np.ones(2, dtype=bool) if valid is None else valid[k]
            row = [repr(float(X[k, j])) if ok[j] else "" for j in range(2)] + [repr(float(U[k, 0]))]
            w.writerow(row + ([str(int(v)) for v in ok] if valid is not None else []))
    return path


def write_config(path: Path, neuron1: str = 'terms = ["x1", "x1(k-2)", "u1"]\nw0 = [0.6, 0.25, 0.5]') -> Path:
    path.write_text(f"""format = "pyrhonn-config"
version = 1
n_states = 2
n_inputs = 1
state_names = ["x1", "x2"]
input_names = ["u1"]

[defaults]
activation = "bipolar"
beta = 1.0
p0 = 1.0
q = 0.0
r = 1.0
eta = 1.0

[[neurons]]
{neuron1}

[[neurons]]
terms = ["x2", "x1"]
w0 = [0.7, 0.4]
""")
    return path


class Files:
    def __init__(self, base: Path) -> None:
        self.base = base
        Xa, Ua = plant(300, seed=1)
        valid = np.ones((300, 2), dtype=bool)
        valid[[40, 41, 120], 0] = False   # dropouts: the validity columns say 0 and the cells are empty
        valid[200, 1] = False
        Xb, Ub = plant(180, seed=2)
        self.a = write_csv(base / "a.csv", Xa, Ua, valid)
        self.b = write_csv(base / "b.csv", Xb, Ub)
        self.data = {str(self.a): (Xa, Ua, valid), str(self.b): (Xb, Ub, np.ones((180, 2), dtype=bool))}
        self.config = write_config(base / "model.toml")
        self.diverging = write_config(base / "diverging.toml", 'terms = ["x1", "x1(k-2)", "u1"]\nw0 = [1.3, 0.25, 0.5]')
        self.no_input = write_config(base / "no_input.toml", 'terms = ["x1", "x1(k-2)"]\nw0 = [0.6, 0.25]')


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> Files:
    return Files(tmp_path_factory.mktemp("validate"))


def validate(*argv: str) -> int:
    return main(["validate", *argv])


def direct(config: Path, X: np.ndarray, U: np.ndarray, valid: np.ndarray) -> Simulation:
    """A fresh identifier from the config, learning off, over one file."""
    ident = Identifier(load_config(config).config)
    ident.learning = False
    return simulate(ident, np.where(valid, X, np.nan), U, valid, free_run_from=K, steps=H)


def significant_digits(text: str) -> list[int]:
    """The significant digits of every number written in ``text``."""
    mantissas = (m.split("e")[0].replace(".", "").lstrip("0")
                 for m in re.findall(r"\d*\.?\d+(?:e[-+]?\d+)?", text))
    return [len(m) for m in mantissas]


def nrmse_fit(x: np.ndarray, xh: np.ndarray) -> float:
    return 100.0 * (1.0 - np.linalg.norm(x - xh) / np.linalg.norm(x - x.mean()))


@pytest.fixture(scope="module")
def two_files(files: Files, tmp_path_factory: pytest.TempPathFactory) -> tuple[dict, str, Path]:
    out = tmp_path_factory.mktemp("out") / "v"
    buffer = io.StringIO()
    with contextlib.redirect_stdout(buffer):
        assert validate(str(files.a), str(files.b), "--config", str(files.config), "--out", str(out),
                        "--steps-ahead", str(H), "--lags", "20") == 0
    return json.loads((out / "validation.json").read_text()), buffer.getvalue(), out


def test_figures_are_the_frozen_simulation_of_each_file_scored_from_its_own_start(files: Files, two_files) -> None:
    report, _, _ = two_files
    assert report["first_sample"] == K and report["max_delay"] == D and report["learning"] is False
    assert [e["data"] for e in report["experiments"]] == [str(files.a), str(files.b)]
    for ex in report["experiments"]:
        X, U, valid = files.data[ex["data"]]
        T = X.shape[0]
        assert ex["samples"] == T and ex["first_line"] == K + 2
        sim = direct(files.config, X, U, valid)
        for kind, estimate, first in (("one_step", sim.one_step, K), ("steps_ahead", sim.ahead, K + H - 1),
                                      ("free_run", sim.free_run, K)):
            for j, name in enumerate(("x1", "x2")):
                rows = valid[:, j].copy()
                rows[:first] = False
                x, xh = X[rows, j], estimate[rows, j]
                got = ex["states"][name][kind]
                assert got["scored"] == int(rows.sum()) == T - first - int((~valid[first:, j]).sum())
                assert got["diverged_at_sample"] is None and got["diverged_at_line"] is None
                assert got["rmse"] == pytest.approx(rmse(x[:, None], xh[:, None])[0], rel=1e-12), (kind, name)
                assert got["rrse"] == pytest.approx(rrse(x[:, None], xh[:, None])[0], rel=1e-12), (kind, name)
                assert got["fit_percent"] == pytest.approx(nrmse_fit(x, xh), rel=1e-12), (kind, name)
    # the exact model: one step leaves only the equation error; fed its own outputs it drifts
    for ex in report["experiments"]:
        for name in ("x1", "x2"):
            st = ex["states"][name]
            assert 60.0 < st["free_run"]["fit_percent"] < st["one_step"]["fit_percent"] < 100.0


def test_residuals_are_the_usable_one_step_errors_pooled_over_the_files(files: Files, two_files) -> None:
    report, _, _ = two_files
    L = report["lags"]
    for j, name in enumerate(("x1", "x2")):
        e_parts, u_parts = [], []
        for path in (files.a, files.b):
            X, U, valid = files.data[str(path)]
            sim = direct(files.config, X, U, valid)
            usable = np.zeros(X.shape[0], dtype=bool)
            for k in range(K, X.shape[0]):  # a valid target, and every state measured in the rows the taps read
                usable[k] = valid[k, j] and valid[k - 1 - D:k].all()
            e_parts += stretches(X[:, j] - sim.one_step[:, j], usable)
            u_parts += stretches(U[:, 0], usable)
        got = report["residuals"]["states"][name]
        N = sum(len(s) for s in e_parts)
        # a: x1 drops out at 40, 41 and 120 and x2 at 200, each removing its rows and the D + 1 after
        assert got["usable"] == N and got["stretches"] == len(e_parts)
        auto, cross = got["autocorrelation"], got["cross_correlation"]["u1"]
        assert auto["lags"] == list(range(L + 1)) and cross["lags"] == list(range(-L, L + 1))
        np.testing.assert_allclose(auto["values"], autocorrelation(e_parts, L), rtol=0, atol=1e-12)
        np.testing.assert_allclose(cross["values"], cross_correlation(u_parts, e_parts, L), rtol=0, atol=1e-12)
        assert auto["bound"] == pytest.approx(2.576 / np.sqrt(N)) == cross["bound"]
        assert auto["outside"] == int(np.sum(np.abs(auto["values"][1:]) > auto["bound"]))
        assert auto["fraction"] == pytest.approx(auto["outside"] / L)
        # the exact model's residual is the white equation error, independent of the input
        assert auto["white"] is True and cross["independent"] is True
    assert report["residuals"]["white"] is True and report["residuals"]["independent"] is True


def test_gaps_cut_the_residual_into_stretches(files: Files, two_files) -> None:
    report, _, _ = two_files
    # x1's residual: a's dropouts at 40-41 and 120 of x1 and 200 of x2 each end a stretch, as does the file end
    assert report["residuals"]["states"]["x1"]["stretches"] == 4 + 1
    X, _, _ = files.data[str(files.a)]
    a_rows = X.shape[0] - K - (2 + 1 + D) - (1 + 1 + D) - (1 + D)     # x1 targets lost: 40-44, 120-123, 201-203
    b_rows = files.data[str(files.b)][0].shape[0] - K
    assert report["residuals"]["states"]["x1"]["usable"] == a_rows + b_rows


def test_the_report_prints_four_significant_digits_and_is_written(two_files) -> None:
    report, printed, out = two_files
    assert (out / "report.txt").read_text() == printed.split("wrote ")[0]
    rrse_b = report["experiments"][1]["states"]["x2"]["free_run"]["rrse"]
    assert format(rrse_b, ".4g") in printed
    assert "experiment 2: " in printed and "white" in printed and "independent of u1" in printed
    assert max(significant_digits(printed)) == 4  # figures carry 4 significant digits, never more
    assert sorted(p.name for p in out.iterdir()) == ["report.txt", "validation.json", "x1_compare.png",
                                                     "x1_residuals.png", "x2_compare.png", "x2_residuals.png"]
    for png in out.glob("*.png"):
        assert png.read_bytes().startswith(b"\x89PNG")


def test_a_tiny_error_prints_as_an_exponent_not_as_zero(files: Files, tmp_path: Path,
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    data = write_csv(tmp_path / "quiet.csv", *plant(120, seed=5, noise=1e-7))
    assert validate(str(data), "--config", str(files.config), "--out", str(tmp_path / "o"), "--no-plots",
                    "--lags", "10") == 0
    printed = capsys.readouterr().out
    report = json.loads((tmp_path / "o" / "validation.json").read_text())
    one = report["experiments"][0]["states"]["x1"]["one_step"]["rrse"]
    assert 1e-9 < one < 1e-5 and format(one, ".4g") in printed and "e-0" in format(one, ".4g")
    assert "0.0000" not in printed


def test_min_fit_above_the_achieved_fit_exits_1_and_below_it_0(files: Files, two_files, tmp_path: Path,
                                                               capsys: pytest.CaptureFixture[str]) -> None:
    report, _, _ = two_files
    fits = {(e["data"], name): e["states"][name]["free_run"]["fit_percent"]
            for e in report["experiments"] for name in ("x1", "x2")}
    worst = min(fits, key=fits.__getitem__)
    args = [str(files.a), str(files.b), "--config", str(files.config), "--no-plots", "--steps-ahead", str(H),
            "--lags", "20"]
    assert validate(*args, "--out", str(tmp_path / "hi"), "--min-fit", str(fits[worst] + 0.01)) == 1
    printed = capsys.readouterr().out
    assert "FAIL" in printed and f"{worst[0]}: {worst[1]}: free run fit" in printed
    verdict = json.loads((tmp_path / "hi" / "validation.json").read_text())["verdict"]
    assert verdict["passed"] is False and len(verdict["failures"]) == 1
    assert verdict["min_fit"] == pytest.approx(fits[worst] + 0.01) and verdict["fit_kind"] == "free_run"
    assert validate(*args, "--out", str(tmp_path / "lo"), "--min-fit", str(fits[worst] - 0.01)) == 0
    assert "PASS" in capsys.readouterr().out
    assert json.loads((tmp_path / "lo" / "validation.json").read_text())["verdict"]["passed"] is True
    # the one-step fit is higher than the free run's: the same threshold passes it
    assert validate(*args, "--out", str(tmp_path / "one"), "--min-fit", str(fits[worst] + 0.01),
                    "--fit-kind", "one_step") == 0


def test_a_diverging_model_is_reported_with_the_sample_it_left_and_fails_min_fit(
        files: Files, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert validate(str(files.b), "--config", str(files.diverging), "--out", str(tmp_path / "o"), "--no-plots",
                    "--steps-ahead", str(H), "--min-fit", "0") == 1
    printed = capsys.readouterr().out
    report = json.loads((tmp_path / "o" / "validation.json").read_text())
    X, U, valid = files.data[str(files.b)]
    sim = direct(files.diverging, X, U, valid)
    free = sim.free_run[:, 0]
    span = X[:, 0].max() - X[:, 0].min()
    left = ~np.isfinite(free) | (free < X[:, 0].min() - span) | (free > X[:, 0].max() + span)
    left[:K] = False
    expected = int(np.flatnonzero(left)[0])
    got = report["experiments"][0]["states"]["x1"]["free_run"]
    assert got["diverged_at_sample"] == expected and got["diverged_at_line"] == expected + 2
    assert got["fit_percent"] is None and got["rmse"] is None and got["rrse"] is None
    assert report["experiments"][0]["free_run_diverged_at_sample"] <= expected
    assert f"diverged at sample {expected} (line {expected + 2})" in printed
    assert "FAIL" in printed and report["verdict"]["passed"] is False
    assert not re.search(r"\d{7,}", printed)  # no runaway number printed
    # a one-step fit that passes still fails when the free run diverged
    assert validate(str(files.b), "--config", str(files.diverging), "--out", str(tmp_path / "p"), "--no-plots",
                    "--steps-ahead", str(H), "--min-fit=-1e9", "--fit-kind", "one_step") == 1
    assert "the free run diverged at sample" in capsys.readouterr().out


def test_a_model_missing_the_input_term_leaves_a_residual_correlated_with_the_input(
        files: Files, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert validate(str(files.b), "--config", str(files.no_input), "--out", str(tmp_path / "o"), "--no-plots") == 0
    printed = capsys.readouterr().out
    res = json.loads((tmp_path / "o" / "validation.json").read_text())["residuals"]
    cross = res["states"]["x1"]["cross_correlation"]["u1"]
    assert cross["independent"] is False and cross["peak_lag"] == 1  # u(k) drives x(k+1)
    assert res["independent"] is False and "correlated with u1" in printed
    assert res["states"]["x2"]["autocorrelation"]["values"][0] == 1.0


def test_the_default_folder_is_named_after_the_first_file_and_marked_incomplete_while_written(
        files: Files, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "validate-b"
    marked: dict[str, bool] = {}
    real = atomic.write_text

    def watched(path: str | Path, text: str, **kwargs: str) -> Path:
        marked[Path(path).name] = (out / atomic.MARKER).exists()
        return real(path, text, **kwargs)

    monkeypatch.setattr(atomic, "write_text", watched)
    assert validate(str(files.b), str(files.a), "--config", str(files.config), "--no-plots") == 0
    assert marked == {atomic.MARKER: False, "validation.json": True, "report.txt": True}
    assert (out / "validation.json").exists() and (out / "report.txt").exists()
    assert not (out / "INCOMPLETE").exists() and not list(out.glob("*.png"))


@pytest.mark.parametrize("args, message", [
    (["{a}", "--steps-ahead", "0"], "--steps-ahead: must be >= 1, got 0"),
    (["{a}", "--steps-ahead", "two"], "--steps-ahead: expected a whole number, got 'two'"),
    (["{a}", "--lags", "0"], "--lags: must be >= 1, got 0"),
    (["{a}", "--lags", "5000"], "--lags 5000: too large for the data: state x1 has 285 usable"),
    (["{a}", "--min-fit", "high"], "--min-fit: expected a number, got 'high'"),
    (["{a}", "--steps-ahead", "298"], "--steps-ahead 298: too long for {a}"),
    (["{a}", "{base}/missing.csv"], "missing.csv"),
    (["{short}"], "{short}: 4 data rows, too short for the config's window: its deepest tap delay is 2"),
    (["{one_state}"], "missing column 'x2'"),
    (["{a}", "--valid-suffix", ""], "--valid-suffix: expected a non-empty column-name suffix"),
])
def test_bad_input_exits_2_with_one_line_naming_it(files: Files, tmp_path: Path, cli_error, args: list[str],
                                                   message: str) -> None:
    short = write_csv(tmp_path / "short.csv", *plant(4, seed=3))
    one_state = tmp_path / "one_state.csv"
    one_state.write_text("x1,u1\n0.0,1.0\n0.5,1.0\n0.3,0.0\n0.1,0.0\n0.2,1.0\n")
    names = {"a": str(files.a), "base": str(files.base), "short": str(short), "one_state": str(one_state)}
    out = tmp_path / "o"
    err = cli_error(["validate", *[a.format(**names) for a in args], "--config", str(files.config),
                     "--out", str(out), "--no-plots"])
    assert message.format(**names) in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


def test_a_missing_config_exits_2_naming_it(files: Files, tmp_path: Path, cli_error) -> None:
    err = cli_error(["validate", str(files.a), "--config", str(tmp_path / "nope.toml"), "--out", str(tmp_path / "o")])
    assert "nope.toml" in err
