"""The public-benchmark comparison (bench/bench_real_data.py) runs end to end
in its --quick form: every data set gets figures from pyrhonn's default
``select`` and from SysIdentPy's FROLS (a test dependency: no skip), the
cascaded tanks rows carry the published figures, and select sees the
estimation record only. No timing is asserted."""
from __future__ import annotations

import csv
import json
import math
import subprocess
import sys
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest
from source_scripts import load_script  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
DATASETS = ("cascaded_tanks", "bouc_wen", "narendra_li")
PUBLISHED = {"best linear approximation": 0.76, "third-degree Volterra": 0.54,
             "polynomial nonlinear state space": 0.45, "NLSS2": 0.34}


def _bench() -> ModuleType:
    return load_script(ROOT / "bench" / "bench_real_data.py", "bench_real_data")


def _strict(text: str) -> Any:
    def refuse(name: str) -> None:
        raise ValueError(f"not JSON: {name}")
    return json.loads(text, parse_constant=refuse)


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> tuple[ModuleType, dict[str, Any], Path, str]:
    bench = _bench()
    tmp = tmp_path_factory.mktemp("bench_real_data")
    out, work = tmp / "figures.json", tmp / "work"
    # In a process of its own: SysIdentPy sets matplotlib's global rcParams when imported, and every
    # plot the rest of the suite draws in this process would change (the killed-identify test compares
    # an in-process run's PNG with a subprocess's, byte for byte).
    proc = subprocess.run([sys.executable, str(ROOT / "bench" / "bench_real_data.py"), "--quick", "--json",
                           str(out), "--keep", str(work)], capture_output=True, text=True, check=False)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "sysidentpy" not in sys.modules
    return bench, _strict(out.read_text(encoding="utf-8")), work, proc.stdout


def _finite(s: dict[str, Any]) -> bool:
    return (not s["diverged"] and isinstance(s["rmse"], float) and math.isfinite(s["rmse"]) and s["rmse"] >= 0
            and isinstance(s["rrse"], float) and math.isfinite(s["rrse"]))


def test_every_data_set_has_one_step_figures_from_both_tools(run) -> None:
    _, figures, _, table = run
    assert set(figures["datasets"]) == set(DATASETS)
    for key, r in figures["datasets"].items():
        assert r["estimation_samples"] > 0 and r["validation_samples"] > r["scored_from"] >= 1, key
        assert r["source"]["citation"] and r["source"]["kind"] in ("measured", "simulated"), key
        py = r["pyrhonn"]
        assert "error" not in py, (key, py.get("error"))
        assert _finite(py["one_step"]), (key, py["one_step"])
        assert py["free_run_from"] == py["max_delay"] + 1 and py["n_terms"] >= 1, key
        # learning online, as written (select sets wait_for_history) and with it off
        assert py["wait_for_history"] and all(py["wait_for_history"]), key
        assert _finite(py["online"]) and _finite(py["online_padded"]), key
        for which in ("sysidentpy_aic", "sysidentpy_best_on_validation"):
            assert _finite(r[which]["one_step"]), (key, which, r[which]["one_step"])
        for s in [py["free_run"]] + [g["free_run"] for g in r["sysidentpy_grid"]]:
            # a free run is figures or "diverged" at a scored sample, never a huge number
            assert _finite(s) or (s["diverged"] and s["rmse"] is None
                                  and r["scored_from"] <= s["diverged_at"] < r["validation_samples"]), (key, s)
        # (b) is the grid's best free run on validation, (a) the grid's smallest AIC: neither can beat its own pick
        grid = r["sysidentpy_grid"]
        assert r["sysidentpy_aic"]["aic"] == min(g["aic"] for g in grid)
        best = r["sysidentpy_best_on_validation"]["free_run"]
        assert all(g["free_run"]["diverged"] or (not best["diverged"] and best["rmse"] <= g["free_run"]["rmse"])
                   for g in grid)
        assert r["title"] in table
    assert figures["quick"] is True
    assert set(figures["versions"]) >= {"pyrhonn", "sysidentpy", "numpy"}
    assert len(figures["load_average"]["before"]) == 3 and len(figures["load_average"]["after"]) == 3


def test_the_cascaded_tanks_rows_carry_the_published_figures(run) -> None:
    _, figures, _, table = run
    tanks = figures["datasets"]["cascaded_tanks"]
    assert {p["model"]: p["free_run_rmse"] for p in tanks["published"]} == PUBLISHED
    assert tanks["source"]["kind"] == "measured" and tanks["scored_from"] >= 5
    assert "published" in table and "0.34" in table
    # the real records, whole: 1,024 samples each, with the note that must stay beside them
    assert tanks["estimation_samples"] == tanks["validation_samples"] == 1024
    data = ROOT / "bench" / "data" / "cascaded_tanks"
    assert (data / "SOURCE.md").is_file()
    with open(data / "dataBenchmark.csv", newline="", encoding="utf-8") as fh:
        rows = [r for r in csv.reader(fh) if r]
    assert rows[0][:5] == ["uEst", "uVal", "yEst", "yVal", "Ts"] and len(rows) == 1 + 1024


def test_select_sees_the_estimation_record_only(run) -> None:
    bench, figures, work, _ = run
    for key, r in figures["datasets"].items():
        py = r["pyrhonn"]
        # the command a user types, default options only, and no validation file on it
        assert py["command"] == ["pyrhonn", *bench.SELECT_ARGS]
        assert py["command"][1:3] == ["select", "estimation.csv"]
        assert not any("valid" in arg for arg in py["command"]), py["command"]
        assert py["select_rows"] < py["estimation_samples"] == r["estimation_samples"]
        assert py["select_wall_seconds"] > 0
        folder = work / key
        with open(folder / "estimation.csv", newline="", encoding="utf-8") as fh:
            lines = list(csv.reader(fh))
        assert lines[0] == ["t", "y", "u"] and len(lines) == 1 + r["estimation_samples"]
        # the validation record was written only after select had written its config and report
        written = (folder / "validation.csv").stat().st_mtime_ns
        assert written >= (folder / "config.toml").stat().st_mtime_ns
        assert written >= (folder / "select.json").stat().st_mtime_ns
