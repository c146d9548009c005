"""The figures a command draws, kept for a test to read their axes, titles and legends."""
from __future__ import annotations

from pathlib import Path
from types import ModuleType
from typing import Any

import pytest


def capture_figures(monkeypatch: pytest.MonkeyPatch, command: ModuleType) -> dict[str, Any]:
    """Every figure ``command`` (a ``pyrhonn.cli`` module) saves through ``atomic.save_figure``
    from now on, by its file's stem; each is still written as usual."""
    saved: dict[str, Any] = {}
    real = command.atomic.save_figure

    def capture(fig: Any, path: Any, **kwargs: Any) -> Any:
        saved[Path(path).stem] = fig
        return real(fig, path, **kwargs)

    monkeypatch.setattr(command.atomic, "save_figure", capture)
    return saved
