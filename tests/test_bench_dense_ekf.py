"""The core-vs-dense benchmark's C harness (bench/bench_core_vs_dense.py,
bench/c/) still compiles warning-free, and its textbook dense EKF still
predicts what pyrhonn's core predicts on the LIM, so the benchmark cannot
silently compare against a broken baseline. No timing is asserted."""
from __future__ import annotations

import importlib.util
import os
import shlex
import shutil
import sys
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parent.parent
STEPS = 300


def _bench() -> ModuleType:
    spec = importlib.util.spec_from_file_location("bench_core_vs_dense", ROOT / "bench" / "bench_core_vs_dense.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look their module up there
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def bench() -> ModuleType:
    if shutil.which(shlex.split(os.environ.get("CC", "cc"))[0]) is None:
        pytest.skip("no C compiler")
    return _bench()


@pytest.mark.parametrize("config", ["firmware-lim", "example3"])
def test_the_dense_ekf_predicts_what_the_core_predicts_on_the_lim_in_float64(bench, config: str, tmp_path: Path) -> None:
    samples = bench.record(bench.lim_config(config, "float64"), STEPS)
    exe, data = bench.build(samples, tmp_path, "O2", unroll=False)
    core, dense, status = bench.predictions(exe, data, samples)
    assert status == f"core: RHONN_OK after {STEPS} steps"
    # The harness runs the very core pyrhonn's Identifier runs ...
    assert bench.relative_difference(core, samples.Xhat) < 1e-12
    # ... and the dense filter, fed the regressors the Identifier formed, learns the same weights.
    assert bench.relative_difference(dense, core) < 1e-9
    # The comparison is not vacuous: the predictions move with the plant.
    assert np.ptp(core, axis=0).min() > 0


def test_the_harness_times_both_filters_and_callgrind_counts_their_instructions(bench, tmp_path: Path) -> None:
    samples = bench.record(bench.lim_config("firmware-lim", "float32"), STEPS)
    exe, data = bench.build(samples, tmp_path, "O2", unroll=True)
    figures = bench.timed(exe, data, STEPS, 2)
    assert figures["core_status"] == "RHONN_OK" and int(figures["core_steps"]) == STEPS
    assert float(figures["core_ns_per_step"]) > 0 and float(figures["dense_ns_per_step"]) > 0
    if shutil.which("valgrind") is None:
        pytest.skip("valgrind not installed: instruction counts not checked")
    for which in ("core", "dense"):
        short, long = (bench.instructions_per_step(exe, data, n, which) for n in (100, 200))
        # The count covers the filter's own steps, not the process around them
        # (start-up, loading the data): per step, it does not depend on the run's length.
        assert short > 0 and 0.8 < short / long < 1.25, (which, short, long)


@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_the_core_compiled_for_the_config_predicts_the_identifiers_bits(bench, dtype: str, tmp_path: Path) -> None:
    """The benchmark's "fixed" build (RHONN_FIXED_CONFIG, as the firmware
    builds the core) runs the same operations: pyrhonn's predictions, bit
    for bit."""
    samples = bench.record(bench.lim_config("firmware-lim", dtype), STEPS)
    exe, data = bench.build(samples, tmp_path, "O2", fixed=True)
    core, _, status = bench.predictions(exe, data, samples)
    assert status == f"core: RHONN_OK after {STEPS} steps"
    assert core.dtype == samples.Xhat.dtype and core.tobytes() == samples.Xhat.tobytes()
