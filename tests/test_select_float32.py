"""``select`` in float32 keeps what its fit determined well through online
learning: on the measured cascaded tanks (the benchmark's own records,
estimation and validation apart), the float32 config learns through the
start of the estimation record as the float64 one does, and its free run on
the validation record stays where the fit put it."""
from __future__ import annotations

import csv
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from pyrhonn import Identifier, IdentifierConfig
from pyrhonn.config import CovarianceForm
from pyrhonn.simulation import simulate
from pyrhonn.structure import Selection, select

DATA = Path(__file__).resolve().parents[1] / "bench" / "data" / "cascaded_tanks" / "dataBenchmark.csv"


def records() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    with DATA.open(newline="", encoding="utf-8") as fh:
        rows = [r for r in csv.reader(fh) if r]
    head = [h.strip() for h in rows[0]]

    def column(name: str) -> np.ndarray:
        return np.array([float(r[head.index(name)]) for r in rows[1:]]).reshape(-1, 1)

    return column("yEst"), column("uEst"), column("yVal"), column("uVal")


@pytest.fixture(scope="module")
def selection() -> Selection:
    y, u, _, _ = records()
    return select(y, u)


def free_run_after_learning(cfg: IdentifierConfig, steps: int) -> float:
    """Free-run RMSE on the validation record of ``cfg`` with the weights it
    learnt through the first ``steps`` samples of the estimation record."""
    y, u, yv, uv = records()
    ident = Identifier(cfg)
    ident.run(y[:steps].astype(cfg.dtype), u[:steps].astype(cfg.dtype))
    learnt = cfg.replace(neurons=tuple(replace(nr, w0=np.asarray(w, dtype=np.float64))
                                       for nr, w in zip(cfg.neurons, ident.weights)))
    frozen = Identifier(learnt)
    frozen.learning = False
    K = cfg.max_delay + 1
    sim = simulate(frozen, yv.astype(cfg.dtype), uv.astype(cfg.dtype), free_run_from=K)
    assert sim.free_run is not None
    e = sim.free_run[K:, 0].astype(np.float64) - yv[K:, 0]
    return float(np.sqrt(np.mean(e * e)))


def test_float32_learning_keeps_the_fit_as_float64_does(selection: Selection) -> None:
    c32, c64 = selection.config(dtype="float32"), selection.config(dtype="float64")
    assert all(nr.covariance is CovarianceForm.UD and nr.skip_refused for nr in c32.neurons)
    frozen = free_run_after_learning(c32, 0)
    for steps in (10, 100):
        f32, f64 = free_run_after_learning(c32, steps), free_run_after_learning(c64, steps)
        assert f32 == pytest.approx(f64, rel=0.05), f"after {steps} learning steps"
    # a few learning steps leave the free run where the fit put it
    assert free_run_after_learning(c32, 10) == pytest.approx(frozen, rel=0.05)
