"""`cmake --install` ships the headers, both libraries, a CMake package and
pkg-config files: a separate project finds it with find_package(rhonn) and
links rhonn::rhonn (double) or rhonn::rhonn_f32 (float, RHONN_SINGLE
propagated), or builds with `pkg-config --cflags --libs rhonn_f32`; the
capacities the libraries were built with reach both. Added to another
project with add_subdirectory, pyrhonn builds no tests of its own unless
asked."""
from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import pytest

from docs_blocks import blocks_by, commands

ROOT = Path(__file__).resolve().parent.parent
CMAKE = shutil.which("cmake")
CC = shutil.which("cc")
pytestmark = pytest.mark.skipif(CMAKE is None or CC is None, reason="needs cmake and cc")
# Capacities other than the defaults, so that a consumer missing them would see another rhonn_t.
CAPACITIES = "RHONN_MAX_STATES=6;RHONN_MAX_TERMS=7"

USE_C = ('#include <stdio.h>\n#include "rhonn.h"\n'
         "int main(void) { static rhonn_t net;\n"
         "  if (rhonn_reset(&net) != RHONN_E_NOT_INIT) return 1;\n"
         '  printf("%u %u %lu\\n", (unsigned)sizeof(rhonn_real), (unsigned)RHONN_MAX_STATES,'
         " (unsigned long)sizeof(rhonn_t));\n  return 0; }\n")


def cmake(*args: str) -> str:
    proc = subprocess.run([CMAKE, *args], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return proc.stdout


LABEL = "test_cmake_install.py::test_the_firmware_pages_commands_install_the_library_and_build_a_program"


def _moved(line: str, tmp: Path) -> str:
    """A command of docs/firmware.md with its `build` folder and its /opt/rhonn prefix in ``tmp``."""
    return line.replace("/opt/rhonn", str(tmp / "prefix")).replace(" build", f" {tmp / 'build'}")


@pytest.fixture(scope="module")
def prefix(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The library built and installed by docs/firmware.md's commands, as written (its build folder and
    prefix moved to a temporary folder), with the page's capacities."""
    tmp = tmp_path_factory.mktemp("install")
    install = blocks_by("docs/firmware.md", LABEL)[0]
    assert CAPACITIES in install, "docs/firmware.md builds with other capacities than this test reads"
    for line in commands(install):
        proc = subprocess.run(["bash", "-ec", _moved(line, tmp)], cwd=ROOT, capture_output=True, text=True)
        assert proc.returncode == 0, f"docs/firmware.md: `{line}`: {proc.stdout}{proc.stderr}"
    return tmp / "prefix"


def library_view(target: str, tmp: Path) -> str:
    """What a program compiled like the library sees: sizeof(rhonn_real), RHONN_MAX_STATES, sizeof(rhonn_t)."""
    (tmp / "probe.c").write_text(USE_C)
    flags = [f"-D{d}" for d in CAPACITIES.split(";")] + (["-DRHONN_SINGLE"] if target == "rhonn_f32" else [])
    subprocess.run([CC, "-std=c99", *flags, f"-I{ROOT / 'csrc' / 'include'}", str(tmp / "probe.c"), "-c", "-o",
                    str(tmp / "probe.o")], check=True)
    exe = tmp / "probe"
    subprocess.run([CC, str(tmp / "probe.o"), str(ROOT / "csrc" / "src" / "rhonn.c"), *flags,
                    f"-I{ROOT / 'csrc' / 'include'}", "-o", str(exe)], check=True)
    return subprocess.run([str(exe)], capture_output=True, text=True, check=True).stdout


def test_install_ships_the_headers_both_libraries_and_pkg_config_files(prefix: Path) -> None:
    for header in ("rhonn.h", "rhonn_capacity.h", "rhonn_warm.h", "rhonn_population.h"):
        assert (prefix / "include" / header).exists(), header
    libs = {p.name for p in prefix.rglob("*.a")}
    assert {"librhonn.a", "librhonn_f32.a"} <= libs
    assert {p.name for p in prefix.rglob("*.pc")} == {"rhonn.pc", "rhonn_f32.pc"}


@pytest.mark.parametrize("target,real_size", [("rhonn", 8), ("rhonn_f32", 4)])
def test_installed_package_links_into_another_cmake_project(tmp_path: Path, prefix: Path, target: str,
                                                            real_size: int) -> None:
    consumer = tmp_path / "consumer"
    consumer.mkdir()
    (consumer / "CMakeLists.txt").write_text(
        "cmake_minimum_required(VERSION 3.16)\nproject(consumer C)\nfind_package(rhonn REQUIRED CONFIG)\n"
        f"add_executable(use use.c)\ntarget_link_libraries(use PRIVATE rhonn::{target})\n")
    (consumer / "use.c").write_text(USE_C)
    cmake("-S", str(consumer), "-B", str(consumer / "b"), f"-DCMAKE_PREFIX_PATH={prefix}")
    cmake("--build", str(consumer / "b"))
    # an uninitialised rhonn_t is refused (RHONN_E_NOT_INIT); the layout is the library's
    out = subprocess.run([str(consumer / "b" / "use")], capture_output=True, text=True, check=True).stdout
    assert out.split()[:2] == [str(real_size), "6"]
    assert out == library_view(target, tmp_path)


@pytest.mark.parametrize("target,real_size", [("rhonn", 8), ("rhonn_f32", 4)])
def test_installed_pkg_config_file_builds_a_program(tmp_path: Path, prefix: Path, target: str,
                                                    real_size: int) -> None:
    pkg_config = shutil.which("pkg-config")
    if pkg_config is None:
        if os.environ.get("PYRHONN_REQUIRE_PKG_CONFIG") == "1":
            pytest.fail("PYRHONN_REQUIRE_PKG_CONFIG=1 but pkg-config is not on PATH")
        pytest.skip("no pkg-config")
    # moved after installing: the .pc files find the prefix from their own folder
    moved = tmp_path / "elsewhere"
    shutil.copytree(prefix, moved)
    pc_dir = next(p.parent for p in moved.rglob(f"{target}.pc"))
    env = {**os.environ, "PKG_CONFIG_PATH": str(pc_dir)}
    flags = subprocess.run([pkg_config, "--cflags", "--libs", target], capture_output=True, text=True, env=env,
                           check=True).stdout.split()
    assert [os.path.normpath(f[2:]) for f in flags if f.startswith("-I")] == [str(moved / "include")]
    (tmp_path / "use.c").write_text(USE_C)
    subprocess.run([CC, "-std=c99", str(tmp_path / "use.c"), *flags, "-o", str(tmp_path / "use")], check=True)
    out = subprocess.run([str(tmp_path / "use")], capture_output=True, text=True, check=True).stdout
    assert out.split()[:2] == [str(real_size), "6"]
    assert out == library_view(target, tmp_path)


def test_as_a_subproject_it_builds_no_tests_unless_asked(tmp_path: Path) -> None:
    parent = tmp_path / "parent"
    parent.mkdir()
    (parent / "CMakeLists.txt").write_text(
        "cmake_minimum_required(VERSION 3.16)\nproject(parent C)\n"
        f'add_subdirectory("{ROOT.as_posix()}" pyrhonn)\n'
        "add_executable(app app.c)\ntarget_link_libraries(app PRIVATE rhonn_f32)\n")
    (parent / "app.c").write_text(USE_C)

    def configure(build: Path, *args: str) -> tuple[str, str]:
        """The cache, and the tests CTest would run in pyrhonn's folder."""
        cmake("-S", str(parent), "-B", str(build), *args)
        tests = subprocess.run([str(Path(CMAKE).with_name("ctest")), "-N"], cwd=build / "pyrhonn",
                               capture_output=True, text=True).stdout
        return (build / "CMakeCache.txt").read_text(), tests

    cache, tests = configure(tmp_path / "b")
    assert "RHONN_BUILD_TESTS:BOOL=OFF" in cache
    assert "core_rhonn" not in tests
    cmake("--build", str(tmp_path / "b"), "--target", "app")
    out = subprocess.run([str(tmp_path / "b" / "app")], capture_output=True, text=True, check=True).stdout
    assert out.startswith("4 ")  # rhonn_f32: float
    cache, tests = configure(tmp_path / "on", "-DRHONN_BUILD_TESTS=ON")
    assert "core_rhonn" in tests
    # on its own (top level) the default stays on
    cmake("-S", str(ROOT), "-B", str(tmp_path / "top"))
    assert "RHONN_BUILD_TESTS:BOOL=ON" in (tmp_path / "top" / "CMakeCache.txt").read_text()


@pytest.mark.skipif(shutil.which("pkg-config") is None, reason="no pkg-config")
def test_the_firmware_pages_commands_install_the_library_and_build_a_program(tmp_path: Path, prefix: Path) -> None:
    # the page's first block built `prefix` (the fixture); its second compiles a program against it
    install, compile_ = blocks_by(
        "docs/firmware.md", "test_cmake_install.py::test_the_firmware_pages_commands_install_the_library_and_build_a_program")
    assert install == blocks_by("docs/firmware.md", LABEL)[0]   # the block the fixture ran
    assert "cmake --install" in install and (prefix / "lib" / "pkgconfig" / "rhonn_f32.pc").exists()
    (tmp_path / "app.c").write_text(USE_C)
    script = "\n".join(_moved(line, prefix.parent) for line in commands(compile_))
    proc = subprocess.run(["bash", "-ec", script], cwd=tmp_path, capture_output=True, text=True)
    assert proc.returncode == 0, f"docs/firmware.md: {script}: {proc.stdout}{proc.stderr}"
    out = subprocess.run([str(tmp_path / "a.out")], capture_output=True, text=True, check=True).stdout
    assert out.split()[:2] == ["4", "6"]   # float (rhonn_f32), the page's RHONN_MAX_STATES
