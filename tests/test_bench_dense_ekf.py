"""The core-vs-dense benchmark's C harness (bench/bench_core_vs_dense.py,
bench/c/) still compiles warning-free, and its two baselines (the textbook
dense EKF and the generic-library EKF) still predict what pyrhonn's core
predicts on the LIM, so the benchmark cannot silently compare against a
broken baseline. No timing is asserted."""
from __future__ import annotations

import os
import shlex
import shutil
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest
from source_scripts import load_script  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
STEPS = 300


def _bench() -> ModuleType:
    return load_script(ROOT / "bench" / "bench_core_vs_dense.py", "bench_core_vs_dense")


@pytest.fixture(scope="module")
def bench() -> ModuleType:
    if shutil.which(shlex.split(os.environ.get("CC", "cc"))[0]) is None:
        pytest.skip("no C compiler")
    return _bench()


@pytest.mark.parametrize("config", ["firmware-lim", "example3"])
def test_both_baselines_predict_what_the_core_predicts_on_the_lim_in_float64(bench, config: str,
                                                                             tmp_path: Path) -> None:
    samples = bench.record(bench.lim_config(config, "float64"), STEPS)
    exe, data = bench.build(samples, tmp_path, "O2", unroll=False)
    p = bench.predictions(exe, data, samples)
    assert p.status == f"core: RHONN_OK after {STEPS} steps"
    # The harness runs the very core pyrhonn's Identifier runs ...
    assert bench.relative_difference(p.core, samples.Xhat) < 1e-12
    # ... and both baselines, fed the regressors the Identifier formed, learn the same weights,
    # the generic one without skipping an update.
    assert bench.relative_difference(p.dense, p.core) < 1e-9
    assert bench.relative_difference(p.generic, p.core) < 1e-9 and p.generic_refused == 0
    # The comparison is not vacuous: the predictions move with the plant.
    assert np.ptp(p.core, axis=0).min() > 0


def test_the_harness_times_the_three_filters_and_counts_their_instructions_and_learnings(bench,
                                                                                       tmp_path: Path) -> None:
    samples = bench.record(bench.lim_config("firmware-lim", "float32"), STEPS)
    exe, data = bench.build(samples, tmp_path, "O2", unroll=True)
    figures = bench.timed(exe, data, STEPS, 2)
    assert figures["core_status"] == "RHONN_OK" and int(figures["core_steps"]) == STEPS
    assert all(float(figures[f"{which}_ns_per_step"]) > 0
               for which in ("core", "dense", "generic", "core_frozen", "dense_frozen"))
    if shutil.which("valgrind") is None:
        pytest.skip("valgrind not installed: instruction counts not checked")
    counts = {}
    for which in ("core", "dense", "generic"):
        short, long = (bench.instructions_per_step(exe, data, n, which) for n in (100, 200))
        # The count covers the filter's own steps, not the process around them
        # (start-up, loading the data): per step, it does not depend on the run's length.
        assert short > 0 and 0.8 < short / long < 1.25, (which, short, long)
        counts[which] = long
    # The generic form does everything the dense one does and F P F^T on top.
    assert counts["generic"] > counts["dense"] > counts["core"]
    # Learning alone (the run minus the same run with learning off): the core
    # frozen still forms its regressor and predicts, the dense EKF still
    # predicts; the EKF updates are most of either filter's work.
    learning = {}
    for which in ("core", "dense"):
        frozen = bench.instructions_per_step(exe, data, 200, which, frozen=True)
        assert 0 < frozen < counts[which] and counts[which] - frozen > 0.5 * counts[which], (which, frozen)
        learning[which] = counts[which] - frozen
    assert learning["dense"] > learning["core"]
    with pytest.raises(ValueError, match="frozen"):
        bench.instructions_per_step(exe, data, 200, "generic", frozen=True)


@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_the_core_compiled_for_the_config_predicts_the_identifiers_bits(bench, dtype: str, tmp_path: Path) -> None:
    """The benchmark's "fixed" build (RHONN_FIXED_CONFIG, as the firmware
    builds the core) runs the same operations: pyrhonn's predictions, bit
    for bit."""
    samples = bench.record(bench.lim_config("firmware-lim", dtype), STEPS)
    exe, data = bench.build(samples, tmp_path, "O2", fixed=True)
    p = bench.predictions(exe, data, samples)
    assert p.status == f"core: RHONN_OK after {STEPS} steps"
    assert p.core.dtype == samples.Xhat.dtype and p.core.tobytes() == samples.Xhat.tobytes()


def test_a_native_build_is_counted_or_said_uncountable_never_a_crash(bench, tmp_path: Path) -> None:
    """valgrind does not decode every instruction an -march=native build may
    use (AVX-512's): such a build gets no count ("-"), and the run goes on."""
    if shutil.which("valgrind") is None:
        pytest.skip("valgrind not installed: instruction counts not checked")
    samples = bench.record(bench.lim_config("firmware-lim", "float64"), 50)
    exe, data = bench.build(samples, tmp_path, "O3-native", fixed=True)
    count = bench.instructions_per_step(exe, data, 50, "core")
    assert count is None or count > 0
