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
