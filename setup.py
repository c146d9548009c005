"""Build hook: compiles the C core into the cffi extensions (two precisions,
each in a large and a small build, see pyrhonn/_build.py), and ships the
core's public headers inside the package (``pyrhonn/core_include``), so that
an installed pyrhonn can measure ``sizeof(rhonn_t)`` for an exported
identifier (``pyrhonn.export``) without the source tree.

All project metadata lives in pyproject.toml; setuptools reads cffi_modules
and cmdclass only from setup(), so this file carries those two arguments.
"""
import shutil
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py


class BuildPyWithCoreHeaders(build_py):
    """build_py, then csrc/include/*.h copied into the built package."""

    def run(self) -> None:
        super().run()
        dst = Path(self.build_lib) / "pyrhonn" / "core_include"
        dst.mkdir(parents=True, exist_ok=True)
        for header in sorted(Path("csrc/include").glob("*.h")):
            shutil.copyfile(header, dst / header.name)


setup(cmdclass={"build_py": BuildPyWithCoreHeaders},
      cffi_modules=["pyrhonn/_build.py:ffi_f64", "pyrhonn/_build.py:ffi_f32", "pyrhonn/_build.py:ffi_small_f64",
                    "pyrhonn/_build.py:ffi_small_f32", "pyrhonn/_build.py:ffi_fwapp"])
