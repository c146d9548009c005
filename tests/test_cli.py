"""The ``pyrhonn`` command line: dispatch, exit codes, and the info command."""
from __future__ import annotations

import json
import subprocess
import sys

import pytest

from pyrhonn.cli import COMMANDS, main


def test_info_reports_the_compiled_capacities(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["info", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["capacities"]["RHONN_MAX_STATES"] >= 6
    assert data["sizeof_rhonn_t"]["float64"] > data["sizeof_rhonn_t"]["float32"]
    from pyrhonn.population import max_population

    assert data["max_population"] == max_population() >= 1
    # each build states the lanes' workspace step() allocates per identifier it keeps there
    from pyrhonn import Identifier, presets

    ident = Identifier(presets.example1("float64"))
    sizes = {b["module"]: b["sizeof_population_work"] for b in data["builds"]}
    assert sizes[ident._build.__name__] == ident._ffi.sizeof("rhonn_population_work")


def test_missing_or_unknown_command_exits_2_with_usage() -> None:
    for argv in ([], ["no-such-command"]):
        with pytest.raises(SystemExit) as info:
            main(argv)
        assert info.value.code == 2


def test_console_module_runs() -> None:
    out = subprocess.run([sys.executable, "-m", "pyrhonn.cli", "info"], capture_output=True, text=True, check=True)
    assert "RHONN_MAX_TERMS" in out.stdout


def test_a_command_imports_its_own_module_only_and_help_lists_them_all() -> None:
    """``pyrhonn show-config`` starts without importing the other commands (nor the packages that add
    commands, whose imports take longer than a short run); ``pyrhonn --help`` still lists every command."""
    probe = ("import sys\nfrom pyrhonn.cli import main\nmain(['show-config', 'example1'])\n"
             "print(sorted(m for m in sys.modules if m.startswith(('pyrhonn.cli.', 'hil'))))")
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    assert out.stdout.strip().splitlines()[-1] == "['pyrhonn.cli.show_config']"
    usage = subprocess.run([sys.executable, "-m", "pyrhonn.cli", "--help"], capture_output=True, text=True, check=True)
    assert all(name.replace("_", "-") in usage.stdout for name in COMMANDS)


def test_a_reader_that_goes_away_ends_the_command_quietly() -> None:
    # `pyrhonn show-config example1 | head -0`: the reader is gone before the first write (the
    # interpreter's start-up alone outlasts closing the pipe here)
    proc = subprocess.Popen([sys.executable, "-m", "pyrhonn.cli", "show-config", "example1"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    assert proc.stdout is not None and proc.stderr is not None
    proc.stdout.close()
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=60) == 141 and err == "", err  # 128 + SIGPIPE, as a shell tool; no traceback
