"""The installed pyrhonn's version, as pyproject.toml sets it (the one
place it is set): ``pyrhonn --version``, ``pyrhonn info``, state files and
exported headers all report this."""
from __future__ import annotations

from importlib.metadata import PackageNotFoundError
from importlib.metadata import version as _distribution_version

__all__ = ["__version__"]

try:
    __version__: str = _distribution_version("pyrhonn")
except PackageNotFoundError:  # imported from a source tree that was never installed
    __version__ = "0+unknown"
