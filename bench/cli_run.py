"""One ``pyrhonn`` command run by a benchmark, as a user runs it: a fresh Python process
(``python -m pyrhonn.cli``), its output captured and its wall time measured around it."""
from __future__ import annotations

import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class CliRun:
    """What one ``pyrhonn`` command did: its arguments, exit status, output and wall time."""

    args: tuple[str, ...]
    returncode: int
    stdout: str
    stderr: str
    seconds: float

    def failure(self, lines: int = 5) -> str:
        """``pyrhonn ARGS exited with status N: ...`` with the last ``lines`` of its error output."""
        tail = (self.stderr.strip() or self.stdout.strip()).splitlines()[-lines:]
        return f"pyrhonn {' '.join(self.args)} exited with status {self.returncode}: " + " | ".join(tail)

    def check(self) -> CliRun:
        """This run, or ``SystemExit`` naming the command and its error when it failed."""
        if self.returncode != 0:
            raise SystemExit(self.failure())
        return self


def run_cli(*args: str, cwd: Path | None = None) -> CliRun:
    """Run ``pyrhonn ARGS`` in ``cwd`` with the interpreter running the benchmark."""
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "pyrhonn.cli", *args], cwd=cwd, capture_output=True, text=True)
    return CliRun(tuple(args), proc.returncode, proc.stdout, proc.stderr, time.perf_counter() - t0)
