"""Build rhonn_runner with the host C compiler, without CMake: for the
benchmark and the vcan tests when no CMake build is at hand.

    python firmware_sim/linux/build_runner.py OUT_DIR

The sources and flags are those of the CMake target ``rhonn_runner``
(firmware_sim/CMakeLists.txt): the application on the float core.
"""
from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
FW = ROOT / "firmware_sim"


def build(out_dir: Path) -> Path:
    """Compile the runner into ``out_dir``; its path. RuntimeError without cc."""
    cc = shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        raise RuntimeError("no C compiler (cc) on PATH")
    Path(out_dir).mkdir(parents=True, exist_ok=True)
    exe = Path(out_dir) / "rhonn_runner"
    subprocess.run([cc, "-std=c99", "-O2", "-ffp-contract=off", "-DRHONN_SINGLE",
                    f"-I{ROOT / 'csrc' / 'include'}", f"-I{FW / 'app'}", f"-I{FW / 'generated'}", f"-I{FW / 'config'}",
                    str(FW / "linux" / "rhonn_runner.c"), str(FW / "app" / "fw_app.c"),
                    str(FW / "app" / "fw_protocol.c"), str(FW / "generated" / "rhonn_id.c"),
                    str(ROOT / "csrc" / "src" / "rhonn.c"), "-lm", "-o", str(exe)], check=True)
    return exe


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit("usage: build_runner.py OUT_DIR")
    print(build(Path(sys.argv[1])))
