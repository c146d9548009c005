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
    import importlib.util

    root = Path(__file__).resolve().parent.parent
    built = Path(os.environ.get("RHONN_RUNNER", root / "build" / "release" / "firmware_sim" / "rhonn_runner"))
    if built.exists():
        return built
    spec = importlib.util.spec_from_file_location("_build_runner", root / "firmware_sim" / "linux" / "build_runner.py")
    module = importlib.util.module_from_spec(spec)
    assert spec.loader is not None
    spec.loader.exec_module(module)
    try:
        return module.build(tmp_path_factory.mktemp("runner"))
    except RuntimeError as exc:
        pytest.skip(f"no rhonn_runner and it cannot be built: {exc}")


@pytest.fixture
def cli_error(capsys):
    """``cli_error(argv)``: run ``pyrhonn argv``, require exit code 2 with a
    message on stderr and no traceback; return that stderr."""
    from pyrhonn.cli import main

    def run(argv: list[str]) -> str:
        try:
            code = main(argv)
        except SystemExit as exc:
            code = exc.code
        assert code == 2, argv
        err = capsys.readouterr().err
        assert "Traceback" not in err and err.strip(), argv
        return err

    return run


@pytest.fixture
def population_calls(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """The member count of every ``run_identifiers_outcomes`` call made
    during the test (the calls the tuning searches make into the core)."""
    import pyrhonn.population as population

    calls: list[int] = []
    real = population.run_identifiers_outcomes

    def counted(identifiers, *args, **kwargs):  # type: ignore[no-untyped-def]
        calls.append(len(identifiers))
        return real(identifiers, *args, **kwargs)

    monkeypatch.setattr(population, "run_identifiers_outcomes", counted)
    return calls
