"""The same C on a Cortex-M4F (QEMU mps2-an386, newlib, hard float) and on
the host (float32, glibc).

- The core: every prediction of the LIM test vector must be bit-identical.
  The core carries its own exp and is built with -ffp-contract=off so that
  this holds; this test is what proves it.
- The whole firmware application (fw_app over the memory HAL) fed a recorded
  frame stream: every frame it sends (Estimates, ControlAcks, Diagnostics and
  Health frames) must equal, byte for byte, what the host's firmware
  (pyrhonn._fwapp) sent for the same stream, and every frame's status too.
- The command authentication's AES-CMAC is checked on the target too, and the
  cycle estimate of the application's frames runs on a short prefix.
- The application calls no software double-precision routine: the float32
  firmware's signal scaling runs in float and integer arithmetic.

run_m4.py runs once for the module (about 20 s)."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from docs_blocks import blocks_by, commands

ROOT = Path(__file__).resolve().parent.parent
M4 = ROOT / "firmware_sim" / "cortex_m4"
TOOLS = ("arm-none-eabi-gcc", "qemu-system-arm", "cmake")
missing = [t for t in TOOLS if shutil.which(t) is None]
required = os.environ.get("PYRHONN_REQUIRE_CORTEX_M4") == "1"
needs_m4 = pytest.mark.skipif(bool(missing) and not required, reason=f"Cortex-M4 toolchain missing: {missing}")
SAMPLES, FRAMES, CYCLE_FRAMES = 1500, 200, 25


def test_cortex_m4_toolchain_is_present_when_required() -> None:
    if required:
        assert not missing, f"PYRHONN_REQUIRE_CORTEX_M4=1 but {missing} not on PATH"


def test_the_pages_cortex_m4_commands_take_options_their_scripts_accept() -> None:
    # the page shows full-length runs the module's fixture runs shorter: each command names a script of
    # the repository and only options its --help lists (no toolchain needed for that)
    body = blocks_by("docs/firmware-sim.md",
                     "test_cortex_m4.py::test_the_pages_cortex_m4_commands_take_options_their_scripts_accept")
    lines = commands(body[0])
    assert len(lines) == 2, lines
    for line in lines:
        python, script, *args = line.split("#")[0].split()
        assert python == "python" and (ROOT / script).is_file(), line
        usage = subprocess.run([sys.executable, str(ROOT / script), "--help"], capture_output=True, text=True,
                               timeout=60, check=True, cwd=str(ROOT)).stdout
        options = [a for a in args if a.startswith("--")]
        assert options, line
        for option in options:
            assert option in usage.split(), f"{line}: {script} --help lists no {option}"


@pytest.fixture(scope="module")
def m4(tmp_path_factory: pytest.TempPathFactory) -> tuple[dict, Path, int]:
    """run_m4.py's report, its build folder and exit status."""
    out = tmp_path_factory.mktemp("m4")
    report_file = out / "m4.json"
    # the installed pyrhonn (the source tree has no compiled extensions), from a folder that cannot shadow it
    proc = subprocess.run([sys.executable, str(M4 / "run_m4.py"), "--out", str(out / "build"),
                           "--samples", str(SAMPLES), "--frames", str(FRAMES), "--cycle-frames", str(CYCLE_FRAMES),
                           "--json", str(report_file)], capture_output=True, text=True, timeout=900, cwd=str(out))
    assert proc.returncode in (0, 1), proc.stderr
    return json.loads(report_file.read_text()), out / "build", proc.returncode


@needs_m4
def test_cortex_m4_predictions_are_bit_identical_to_host_float32(m4) -> None:
    report, _, _ = m4
    for build in ("unrolled", "generic"):
        r = report[build]
        print(f"\n{build}: {r['instructions_per_step']:.0f} instructions/step "
              f"({100 * r['budget_fraction']:.1f} % of 0.3 ms at 168 MHz), core .text {r['core_object']['text']} B, "
              f"rhonn_t {r['sizeof_rhonn_t']} B, stack {r['rhonn_step_worst_stack_bytes']} B")
        assert r["predictions_compared"] == SAMPLES
        assert r["distinct_predictions"] > 1000  # a live trajectory, not a constant
        assert r["bit_identical_to_host_float32"], f"{build}: M4 and host float32 predictions differ"
    # the command authentication on the target: RFC 4493's examples, and secured frames verify
    secoc = report["secoc"]
    print(f"secoc: {secoc['instructions_per_control_verify']:.0f} instructions per Control verified, "
          f"{secoc['instructions_per_weight_load_verify']:.0f} per WeightLoad")
    assert secoc["cmac_rfc4493_and_verification_on_target"]


@needs_m4
def test_cortex_m4_application_sends_exactly_the_host_firmwares_frames(m4) -> None:
    report, build, status = m4
    app = report["application"]
    expected = (build / "frames" / "frames_expected.txt").read_text().splitlines()
    sent_ids = {line.split()[1] for line in expected if line.startswith("T ")}
    # the stream reaches every path: estimates, acks, diagnostics with health, and each rejection
    assert {"101", "111", "130", "131"} <= sent_ids, sent_ids
    assert {"FW_E_SEQ_REPEAT", "FW_E_SEQ_JUMP", "FW_E_RANGE", "FW_E_UNKNOWN_ID"} <= set(app["status_counts"])
    assert app["frames"] > FRAMES and app["lines_compared"] == len(expected)
    assert app["identical_to_host"], f"the M4 application differs from the host's: {app['first_difference']}"
    assert app["status_counts"] == {s: sum(1 for line in expected if line.startswith("F ") and line.split()[2] == s)
                                    for s in app["status_counts"]}
    print(f"\napplication: {app['frames']} frames, {app['frames_sent']} sent, identical; flash {app['flash_bytes']} B, "
          f"fw_app {app['sizeof_fw_app']} B, stack {app['fw_app_on_frame_worst_stack_bytes']} B")
    assert status == 0


@needs_m4
def test_cortex_m4_application_comparison_finds_a_changed_frame(m4, tmp_path: Path) -> None:
    """The comparison is not vacuous: one changed byte of one recorded
    output frame is reported at its line."""
    sys.path.insert(0, str(M4))
    try:
        import run_m4
    finally:
        sys.path.remove(str(M4))
    _, build, _ = m4
    frames = tmp_path / "frames"
    shutil.copytree(build / "frames", frames)
    lines = (frames / "frames_expected.txt").read_text().splitlines()
    k = next(i for i, line in enumerate(lines) if line.startswith("T 101") and i > len(lines) // 2)
    last = lines[k][-1]
    lines[k] = lines[k][:-1] + ("0" if last != "0" else "1")
    (frames / "frames_expected.txt").write_text("\n".join(lines) + "\n")
    app = run_m4.run_app(build / "unrolled", frames, 0)
    assert not app["identical_to_host"]
    assert app["first_difference"]["line"] == k
    assert app["first_difference"]["host"] == lines[k]


@needs_m4
def test_cortex_m4_cycle_estimate_covers_the_frame_and_its_step(m4) -> None:
    report, _, _ = m4
    c = report["application"]["cycles"]
    assert c["frames"] == CYCLE_FRAMES and c["steps"] == CYCLE_FRAMES   # the prefix: measurements only
    assert 0 < c["step_mean"] < c["measurement_frame_mean"]            # the frame holds its step and more
    assert c["app_overhead_mean"] > 0
    assert 0 < c["step_median"] <= c["step_p99"] <= c["step_max"]
    assert c["frame_target_met"] == (c["measurement_frame_max"] <= c["frame_target"])
    print(f"\ncycles: {c['measurement_frame_mean']:.0f} per measurement frame (target {c['frame_target']}), "
          f"{c['step_mean']:.0f} per rhonn_step")


@needs_m4
def test_cortex_m4_application_runs_no_software_double_arithmetic(m4) -> None:
    """The FPv4-SP FPU has single precision only: a double in the firmware's C
    becomes calls into libgcc's soft-float routines, about 10,600 cycles of
    each Measurement frame when the protocol scaled in double. None is linked
    from the application's objects, and none runs in the measured frames."""
    report, _, _ = m4
    app = report["application"]
    assert app["library_routines"], "the library routines were not listed"   # memcpy, memset at least
    assert app["soft_double_routines"] == [], app["soft_double_routines"]
    assert app["cycles"]["soft_double_cycles_per_frame"] == 0


@needs_m4
def test_cortex_m4_cycle_profile_names_the_source_lines_that_cost_most(m4) -> None:
    """cycles.py --lines: the estimated cycles per call summed per source line
    of the image's debug information, the costliest first, within the
    call's total; a negative count is refused with exit status 2. On the
    application image's rhonn_step over its first frames (the core image's
    whole vector, single-stepped, took half a minute)."""
    _, build, _ = m4
    elf = build / "unrolled" / "fw_app_m4.elf"
    objs = sorted((build / "unrolled" / "CMakeFiles" / "fw_app_m4.dir").rglob("rhonn.c.obj"))
    assert elf.is_file() and len(objs) == 1, objs
    proc = subprocess.run([sys.executable, str(M4 / "cycles.py"), str(elf), str(objs[0]), "--steps-symbol", "rhonn_step",
                           "--harness", "fw_app_on_frame", "--args", str(CYCLE_FRAMES), "--lines", "5"],
                          capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stderr
    est = json.loads(proc.stdout)
    lines = est["cycles_per_call_by_line"]
    assert len(lines) == 5 and all(k.startswith("rhonn") and ":" in k for k in lines), lines
    costs = list(lines.values())
    assert costs == sorted(costs, reverse=True) and costs[-1] > 0
    assert sum(costs) <= est["estimated_cycles_per_call"]
    bad = subprocess.run([sys.executable, str(M4 / "cycles.py"), str(elf), str(objs[0]), "--lines", "-1"],
                         capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and "--lines must be >= 0" in bad.stderr
