"""The same C core on a Cortex-M4F (QEMU mps2-an386, newlib, hard float)
and on the host (float32, glibc): every prediction of the LIM test vector
must be bit-identical. The core carries its own exp and is built with
-ffp-contract=off so that this holds; this test is what proves it. The
command authentication's AES-CMAC is checked on the target too."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
TOOLS = ("arm-none-eabi-gcc", "qemu-system-arm", "cmake")
missing = [t for t in TOOLS if shutil.which(t) is None]
required = os.environ.get("PYRHONN_REQUIRE_CORTEX_M4") == "1"


def test_cortex_m4_toolchain_is_present_when_required() -> None:
    if required:
        assert not missing, f"PYRHONN_REQUIRE_CORTEX_M4=1 but {missing} not on PATH"


@pytest.mark.skipif(bool(missing) and not required, reason=f"Cortex-M4 toolchain missing: {missing}")
def test_cortex_m4_predictions_are_bit_identical_to_host_float32(tmp_path: Path) -> None:
    report_file = tmp_path / "m4.json"
    proc = subprocess.run([sys.executable, str(ROOT / "firmware_sim" / "cortex_m4" / "run_m4.py"),
                           "--out", str(tmp_path / "build"), "--samples", "1500", "--json", str(report_file)],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode in (0, 1), proc.stderr
    report = json.loads(report_file.read_text())
    for build in ("unrolled", "generic"):
        r = report[build]
        print(f"\n{build}: {r['instructions_per_step']:.0f} instructions/step "
              f"({100 * r['budget_fraction']:.1f} % of 0.3 ms at 168 MHz), core .text {r['core_object']['text']} B, "
              f"rhonn_t {r['sizeof_rhonn_t']} B, stack {r['rhonn_step_worst_stack_bytes']} B")
        assert r["predictions_compared"] == 1500
        assert r["distinct_predictions"] > 1000  # a live trajectory, not a constant
        assert r["bit_identical_to_host_float32"], f"{build}: M4 and host float32 predictions differ"
    # the command authentication on the target: RFC 4493's examples, and secured frames verify
    secoc = report["secoc"]
    print(f"secoc: {secoc['instructions_per_control_verify']:.0f} instructions per Control verified, "
          f"{secoc['instructions_per_weight_load_verify']:.0f} per WeightLoad")
    assert secoc["cmac_rfc4493_and_verification_on_target"]
    assert proc.returncode == 0
