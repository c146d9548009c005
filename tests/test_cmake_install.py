"""`cmake --install` ships the headers, both libraries and a CMake package:
a separate project finds it with find_package(rhonn) and links rhonn::rhonn
(double) or rhonn::rhonn_f32 (float, RHONN_SINGLE propagated)."""
from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
CMAKE = shutil.which("cmake")
pytestmark = pytest.mark.skipif(CMAKE is None or shutil.which("cc") is None, reason="needs cmake and cc")


def cmake(*args: str) -> None:
    subprocess.run([CMAKE, *args], check=True, capture_output=True, text=True)


@pytest.fixture(scope="module")
def prefix(tmp_path_factory: pytest.TempPathFactory) -> Path:
    tmp = tmp_path_factory.mktemp("install")
    cmake("-S", str(ROOT), "-B", str(tmp / "build"), "-DRHONN_BUILD_TESTS=OFF")
    cmake("--build", str(tmp / "build"), "-j", "2")
    cmake("--install", str(tmp / "build"), "--prefix", str(tmp / "prefix"))
    return tmp / "prefix"


def test_install_ships_both_headers_and_both_libraries(prefix: Path) -> None:
    assert (prefix / "include" / "rhonn.h").exists() and (prefix / "include" / "rhonn_capacity.h").exists()
    libs = {p.name for p in prefix.rglob("*.a")}
    assert {"librhonn.a", "librhonn_f32.a"} <= libs


@pytest.mark.parametrize("target,real_size", [("rhonn", 8), ("rhonn_f32", 4)])
def test_installed_package_links_into_another_cmake_project(tmp_path: Path, prefix: Path, target: str,
                                                            real_size: int) -> None:
    consumer = tmp_path / "consumer"
    consumer.mkdir()
    (consumer / "CMakeLists.txt").write_text(
        "cmake_minimum_required(VERSION 3.16)\nproject(consumer C)\nfind_package(rhonn REQUIRED CONFIG)\n"
        f"add_executable(use use.c)\ntarget_link_libraries(use PRIVATE rhonn::{target})\n")
    (consumer / "use.c").write_text(
        '#include <stdio.h>\n#include "rhonn.h"\n'
        "int main(void) { static rhonn_t net; return rhonn_reset(&net) == RHONN_E_NULL ? 1 : (int)sizeof(rhonn_real); }\n")
    cmake("-S", str(consumer), "-B", str(consumer / "b"), f"-DCMAKE_PREFIX_PATH={prefix}")
    cmake("--build", str(consumer / "b"))
    # an uninitialised rhonn_t is refused (RHONN_E_NOT_INIT), then the exit code carries sizeof(rhonn_real)
    proc = subprocess.run([str(consumer / "b" / "use")])
    assert proc.returncode == real_size
