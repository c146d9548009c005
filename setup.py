"""Build hook: compiles the C core into the cffi extensions (two precisions,
each in a large and a small build, see pyrhonn/_build.py), and ships the
core's public headers inside the package (``pyrhonn/core_include``), so that
an installed pyrhonn can measure ``sizeof(rhonn_t)`` for an exported
identifier (``pyrhonn.export``) without the source tree, and the core's
source (``pyrhonn/core_src``), which an exported FMU compiles
(``pyrhonn.fmu``).

All project metadata lives in pyproject.toml; setuptools reads cffi_modules
and cmdclass only from setup(), so this file carries those two arguments.
"""
import os
import shutil
import threading
from pathlib import Path

from setuptools import setup
from setuptools.command.build_ext import build_ext
from setuptools.command.build_py import build_py


class BuildPyWithCoreHeaders(build_py):
    """build_py, then csrc/include/*.h and the core's sources (rhonn.c with its
    private header, rhonn_warm.c) copied into the built package."""

    def run(self) -> None:
        super().run()
        copies = {"core_include": sorted(Path("csrc/include").glob("*.h")),
                  "core_src": [Path("csrc/src/rhonn.c"), Path("csrc/src/rhonn_internal.h"),
                               Path("csrc/src/rhonn_warm.c")]}
        for folder, files in copies.items():
            dst = Path(self.build_lib) / "pyrhonn" / folder
            dst.mkdir(parents=True, exist_ok=True)
            for path in files:
                shutil.copyfile(path, dst / path.name)


class BuildExtSideBySide(build_ext):
    """build_ext with the extensions compiled side by side, one per CPU, each
    into an object folder of its own.

    The extensions share source files (the core), compiled with each one's own
    capacities and precision; in one object folder they would land at the same
    path, and built side by side one extension could link another's core.
    build_ext reads its object folder from ``build_temp`` and runs the
    extensions in threads, so ``build_temp`` is per thread here: the shared
    folder, or the running extension's subfolder of it."""

    def initialize_options(self) -> None:
        self._own_temp = threading.local()
        super().initialize_options()
        if self.parallel is None:
            self.parallel = os.cpu_count() or 1

    @property
    def build_temp(self) -> str | None:
        return getattr(self._own_temp, "folder", None) or self._shared_temp

    @build_temp.setter
    def build_temp(self, folder: str | None) -> None:
        self._shared_temp = folder

    def build_extension(self, ext) -> None:  # noqa: ANN001 (a setuptools Extension)
        self._own_temp.folder = os.path.join(self._shared_temp, ext.name)
        try:
            super().build_extension(ext)
        finally:
            self._own_temp.folder = None


setup(cmdclass={"build_py": BuildPyWithCoreHeaders, "build_ext": BuildExtSideBySide},
      cffi_modules=["pyrhonn/_build.py:ffi_f64", "pyrhonn/_build.py:ffi_f32", "pyrhonn/_build.py:ffi_small_f64",
                    "pyrhonn/_build.py:ffi_small_f32", "pyrhonn/_build.py:ffi_fwapp",
                    "pyrhonn/_build.py:ffi_csv"])
