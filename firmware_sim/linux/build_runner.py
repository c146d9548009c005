"""Build rhonn_runner with the host C compiler, without CMake: for the
benchmark, the tests and ``pyrhonn hil`` when no CMake build is at hand.

    python firmware_sim/linux/build_runner.py OUT_DIR

The sources and flags are those of the CMake target ``rhonn_runner``
(firmware_sim/CMakeLists.txt): the application on the float core, with the
udp_multicast codec. :func:`cached` builds once per content of the sources
(and compiler, flags) into a cache directory and reuses that build after.
"""
from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
FW = ROOT / "firmware_sim"
INCLUDE_DIRS = [ROOT / "csrc" / "include", FW / "app", FW / "generated", FW / "config", FW / "linux"]
SOURCES = [FW / "linux" / "rhonn_runner.c", FW / "linux" / "udp_can.c", FW / "app" / "fw_app.c",
           FW / "app" / "fw_protocol.c", FW / "app" / "fw_secoc.c", FW / "app" / "fw_aes_cmac.c", FW / "app" / "fw_xcp.c",
           FW / "generated" / "rhonn_id.c", ROOT / "csrc" / "src" / "rhonn.c"]
FLAGS = ["-std=c99", "-O2", "-ffp-contract=off", "-DRHONN_SINGLE"]


def _compiler() -> str:
    cc = shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        raise RuntimeError("no C compiler (cc) on PATH")
    return cc


def build(out_dir: Path) -> Path:
    """Compile the runner into ``out_dir``; its path. RuntimeError without cc,
    subprocess.CalledProcessError when the compiler fails (its messages on
    stderr)."""
    cc = _compiler()
    Path(out_dir).mkdir(parents=True, exist_ok=True)
    exe = Path(out_dir) / "rhonn_runner"
    cmd = [cc, *FLAGS, *(f"-I{d}" for d in INCLUDE_DIRS), *map(str, SOURCES), "-lm", "-o", str(exe)]
    subprocess.run(cmd, check=True)
    return exe


def _fingerprint(cc: str) -> str:
    h = hashlib.sha256()
    h.update(os.path.realpath(cc).encode())
    h.update(" ".join(FLAGS).encode())
    files = sorted({*SOURCES, *(p for d in INCLUDE_DIRS for p in d.glob("*.h"))})
    for path in files:
        h.update(str(path.relative_to(ROOT)).encode())
        h.update(path.read_bytes())
    return h.hexdigest()[:20]


def default_cache_dir() -> Path:
    """$PYRHONN_CACHE_DIR, else $XDG_CACHE_HOME/pyrhonn, else ~/.cache/pyrhonn."""
    if os.environ.get("PYRHONN_CACHE_DIR"):
        return Path(os.environ["PYRHONN_CACHE_DIR"])
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "pyrhonn"


def cached(cache_dir: Path | None = None) -> Path:
    """The runner built from the current sources: reused from ``cache_dir``
    (default :func:`default_cache_dir`) when a build of exactly these sources
    is there, else built into it (atomically: parallel callers are safe)."""
    cc = _compiler()
    cache = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    final = cache / f"rhonn_runner-{_fingerprint(cc)}"
    exe = final / "rhonn_runner"
    if exe.is_file():
        return exe
    cache.mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix=".building-", dir=cache))
    try:
        build(work)
        try:
            os.rename(work, final)
        except OSError:  # another process finished first: use its build
            if not exe.is_file():
                raise
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return exe


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit("usage: build_runner.py OUT_DIR")
    print(build(Path(sys.argv[1])))
