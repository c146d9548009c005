"""The compiled extensions pyrhonn runs on (cffi over the C core, built by
``pyrhonn/_build.py``), and the error a source tree without them raises.

A clone is usable after ``make venv`` (an editable install, which builds the
extensions beside the sources); before that, ``import pyrhonn`` from the
clone fails with an ``ImportError`` that says so, not with an error from
deep inside the package."""
from __future__ import annotations

import importlib.util
from pathlib import Path

__all__ = ["EXTENSIONS", "missing", "require"]

#: The extension modules of the package: the core in float64 and float32, in a
#: large and a small build, the firmware application, and the CSV text codec.
EXTENSIONS = ("_rhonn_f64", "_rhonn_f32", "_rhonn_small_f64", "_rhonn_small_f32", "_fwapp", "_csvtext")


def missing(package: str = "pyrhonn") -> list[str]:
    """The extensions of :data:`EXTENSIONS` that ``package`` cannot import."""
    return [name for name in EXTENSIONS if importlib.util.find_spec(f"{package}.{name}") is None]


def require(package: str = "pyrhonn") -> None:
    """Raise ``ImportError`` naming the missing extensions and what builds them."""
    absent = missing(package)
    if absent:
        folder = Path(__file__).resolve().parent
        raise ImportError(
            f"{package} in {folder} has no compiled extensions ({', '.join(absent)}): a source tree that was "
            f"not built. In the repository, run `make venv` (an editable install into .venv that builds them "
            f"in place) or `python -m pip install -e .`; or start Python outside the source tree to use an "
            f"installed {package}.", name=package)
