"""Shared test settings: a hypothesis profile for CI (fixed seed, derandomised
so a red run can be reproduced) and one for local runs."""
from __future__ import annotations

import os
from pathlib import Path

import pytest

from hypothesis import settings

settings.register_profile("ci", derandomize=True, print_blob=True)
settings.register_profile("dev", print_blob=True)
settings.load_profile("ci" if os.environ.get("CI") else "dev")


def _vcan0_present() -> bool:
    return Path("/sys/class/net/vcan0").exists()


@pytest.fixture
def vcan0() -> str:
    """The vcan0 interface, or a skip (a failure when PYRHONN_REQUIRE_VCAN=1)."""
    if not _vcan0_present():
        if os.environ.get("PYRHONN_REQUIRE_VCAN") == "1":
            pytest.fail("PYRHONN_REQUIRE_VCAN=1 but there is no vcan0")
        pytest.skip("no vcan0 here (SocketCAN tests run in the VM tier: hil/vm/run_in_vm.py)")
    return "vcan0"


@pytest.fixture(scope="session")
def runner(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """firmware_sim's Linux runner: the one `make test-c` built (RHONN_RUNNER
    or build/release), else one built here with cc."""
    import shutil
    import subprocess

    root = Path(__file__).resolve().parent.parent
    built = Path(os.environ.get("RHONN_RUNNER", root / "build" / "release" / "firmware_sim" / "rhonn_runner"))
    if built.exists():
        return built
    cc = shutil.which("cc")
    if cc is None:
        pytest.skip("no rhonn_runner and no C compiler to build one")
    out = tmp_path_factory.mktemp("runner") / "rhonn_runner"
    fw = root / "firmware_sim"
    subprocess.run([cc, "-std=c99", "-O2", "-ffp-contract=off", "-DRHONN_SINGLE", f"-I{root / 'csrc' / 'include'}",
                    f"-I{fw / 'app'}", f"-I{fw / 'generated'}", f"-I{fw / 'config'}", str(fw / "linux" / "rhonn_runner.c"),
                    str(fw / "app" / "fw_app.c"), str(fw / "app" / "fw_protocol.c"), str(fw / "generated" / "rhonn_id.c"),
                    str(root / "csrc" / "src" / "rhonn.c"), "-lm", "-o", str(out)], check=True)
    return out
