"""The clone works as the package: with pyrhonn installed in editable mode
(`make venv`), Python started in the repository's root imports the clone,
its compiled extensions built in place; a source tree that was never built
refuses to import with an error that says what to run."""
from __future__ import annotations

import json
import shutil
import subprocess
import sys
from importlib.metadata import distribution
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def _editable() -> bool:
    text = distribution("pyrhonn").read_text("direct_url.json")
    return bool(text) and bool(json.loads(text).get("dir_info", {}).get("editable"))


def _python(code: str, cwd: Path, *options: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, *options, "-c", code], cwd=cwd, capture_output=True, text=True,
                          timeout=120)


@pytest.mark.skipif(not _editable(), reason="pyrhonn is installed from a wheel here, not from this clone (make venv)")
def test_python_started_in_the_repository_imports_the_clone() -> None:
    proc = _python("import pyrhonn, pyrhonn.identifier as i; print(pyrhonn.__file__); print(i.Identifier)", ROOT)
    assert proc.returncode == 0, proc.stderr
    assert Path(proc.stdout.splitlines()[0]).resolve() == ROOT / "pyrhonn" / "__init__.py"


def test_a_source_tree_without_its_extensions_says_what_to_run(tmp_path: Path) -> None:
    shutil.copytree(ROOT / "pyrhonn", tmp_path / "pyrhonn", ignore=shutil.ignore_patterns("*.so", "__pycache__"))
    # -S: no site-packages, as on a machine where this tree was never installed (an installed pyrhonn
    # could otherwise lend the tree its extensions); the check runs before anything else is imported
    proc = _python("import pyrhonn", tmp_path, "-S")
    assert proc.returncode != 0
    last = proc.stderr.strip().splitlines()[-1]
    assert last.startswith("ImportError: pyrhonn in ") and "no compiled extensions (_rhonn_f64, " in last, proc.stderr
    assert "make venv" in last and "pip install -e ." in last
    assert "circular import" not in proc.stderr and "partially initialized" not in proc.stderr
