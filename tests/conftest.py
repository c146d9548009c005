"""Shared test settings: a hypothesis profile for CI (fixed seed, derandomised
so a red run can be reproduced) and one for local runs."""
from __future__ import annotations

import os
from pathlib import Path

import pytest
from source_scripts import load_script  # noqa: E402

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

    root = Path(__file__).resolve().parent.parent
    built = Path(os.environ.get("RHONN_RUNNER", root / "build" / "release" / "firmware_sim" / "rhonn_runner"))
    if built.exists():
        return built
    module = load_script(root / "firmware_sim" / "linux" / "build_runner.py", "_build_runner")
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


def write_two_state_plant(path: Path, n: int = 2000, period: float = 3e-4) -> None:
    """A recording of a small plant for the any-identifier tests (2 states, 1 input acting 2 samples
    late): x1(k+1) = 0.95 x1 + 0.05 x2, x2(k+1) = 0.9 x2 + 0.1 tanh(u(k-2)), u a random staircase.
    By default the data.csv of docs/hil-any-identifier.md, so that the twin and the runner built by the
    tests are the ones the page's commands find in the build cache."""
    import numpy as np

    rng = np.random.default_rng(1)
    u = np.repeat(rng.uniform(-1, 1, n // 100 + 1), 100)[:n]
    x = np.zeros((n, 2))
    for k in range(n - 1):
        x[k + 1, 0] = 0.95 * x[k, 0] + 0.05 * x[k, 1]
        x[k + 1, 1] = 0.9 * x[k, 1] + 0.1 * np.tanh(u[k - 2] if k >= 2 else 0.0)
    rows = [f"{float(k * period)!r},{float(x[k, 0])!r},{float(x[k, 1])!r},{float(u[k])!r}" for k in range(n)]
    path.write_text("t,y1,y2,u\n" + "\n".join(rows) + "\n")


@pytest.fixture(scope="module")
def exported(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Another identifier than the LIM, as a user makes it: a config (float32) selected from the
    recording of :func:`write_two_state_plant`, exported with its DBC (pyrhonn export --dbc)."""
    from pyrhonn.cli import main as pyrhonn_main

    d = tmp_path_factory.mktemp("identifier")
    write_two_state_plant(d / "data.csv")
    assert pyrhonn_main(["select", str(d / "data.csv"), "--states", "y1,y2", "--inputs", "u",
                         "--input-max-delay", "3", "--dtype", "float32", "--out", str(d / "cfg.toml")]) == 0
    assert pyrhonn_main(["export", "--config", str(d / "cfg.toml"), "--data", str(d / "data.csv"),
                         "--dbc", str(d / "id.dbc"), "--out", str(d / "id.h")]) == 0
    return {"dir": d, "config": d / "cfg.toml", "dbc": d / "id.dbc", "data": d / "data.csv"}
