"""The results file a benchmark writes: ``bench/results/NAME.json``.

Every benchmark that produces figures the documentation quotes takes
``--results`` and then writes them here, committed beside the code, so the
docs site takes its figures from the last run instead of a hand copy (see
``docs_hooks.py``: a page writes ``{{ bench("NAME", "a.b.c") }}``). A file
holds::

    {"bench": NAME, "date": when the run ended (ISO, UTC), "command": how it was run,
     "machine": {"cpu": model, "nproc": CPUs, "machine": arch, "python": version},
     "load": {"start": [1, 5, 15 min load averages], "end": [...]},
     "figures": {...}}

``load`` says how busy the machine was: instruction counts (callgrind, QEMU)
do not depend on it, timings do. The file is replaced in one step
(:mod:`pyrhonn.atomic`): an interrupted run leaves the previous results.
"""
from __future__ import annotations

import datetime
import json
import math
import os
import platform
import shlex
import sys
from pathlib import Path
from typing import Any

from pyrhonn import atomic

FOLDER = Path(__file__).resolve().parent / "results"
_START_LOAD = os.getloadavg()


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text(encoding="utf-8").splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def machine() -> dict[str, Any]:
    return {"cpu": _cpu_model(), "nproc": os.cpu_count(), "machine": platform.machine(),
            "python": platform.python_version()}


def _finite(value: Any) -> Any:
    """``value`` with every float that is not finite written as text ("inf", "-inf", "nan"):
    JSON has no such numbers, and a diverged free run is a result to keep."""
    if isinstance(value, float) and not math.isfinite(value):
        return repr(value)
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(v) for v in value]
    return value


def _portable(arg: str) -> str:
    """A command-line argument as the results file records it: an absolute path (a scratch folder of
    the machine that ran it) as DIR, so that the file names no machine's folders."""
    key, eq, value = arg.partition("=")
    if eq and value.startswith("/"):
        return f"{key}=DIR"
    return "DIR" if arg.startswith("/") else arg


def save(name: str, figures: dict[str, Any], argv: list[str] | None = None, folder: Path = FOLDER) -> Path:
    """Write ``figures`` (JSON values; a float that is not finite as its text, ``"inf"``) as
    ``folder/NAME.json`` with the run's date, machine, load and command (``bench/bench_NAME.py``
    with ``argv``, by default this process's arguments); returns the path."""
    if not name or not name.replace("_", "").isalnum():
        raise ValueError(f"name: letters, digits and underscores only, got {name!r}")
    if not isinstance(figures, dict) or not figures:
        raise ValueError("figures: a non-empty mapping")
    args = sys.argv[1:] if argv is None else argv
    record = {
        "bench": name,
        "date": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "command": shlex.join(["python", f"bench/bench_{name}.py", *map(_portable, args)]),
        "machine": machine(),
        "load": {"start": [round(v, 2) for v in _START_LOAD], "end": [round(v, 2) for v in os.getloadavg()]},
        "figures": _finite(figures),
    }
    text = json.dumps(record, indent=1, allow_nan=False, sort_keys=False) + "\n"
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{name}.json"
    atomic.write_text(path, text)
    print(f"results written: {path}")
    return path
