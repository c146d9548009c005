"""The figures of ``pyrhonn reproduce``: a unit on every y axis, the hold shading named in the legend."""
from __future__ import annotations

import re
from typing import Any

import pytest

from pyrhonn import reproduce
from pyrhonn.plants import lim, oscillator, robot


@pytest.fixture
def figures(monkeypatch) -> dict[str, Any]:
    """Every figure write_outputs saves, by file name (the PNGs are still written)."""
    saved: dict[str, Any] = {}
    real = reproduce.atomic.save_figure

    def capture(fig: Any, path: Any, **kwargs: Any) -> Any:
        saved[str(path).rsplit("/", 1)[-1]] = fig
        return real(fig, path, **kwargs)

    monkeypatch.setattr(reproduce.atomic, "save_figure", capture)
    return saved


def test_state_units_cover_every_state_of_every_example():
    names = {"example1": oscillator.STATE_NAMES, "example2": robot.STATE_NAMES, "example3": lim.STATE_NAMES}
    assert set(reproduce.STATE_UNITS) == set(reproduce.EXAMPLES)
    for example, units in reproduce.STATE_UNITS.items():
        assert len(units) == len(names[example]) and all(units), example


@pytest.mark.parametrize("scenario, horizon, has_holds", [("example2", None, True), ("example3", 2.5, True),
                                                          ("example1-dt0.2", 10.0, False)])
def test_every_y_axis_has_a_unit_and_the_legend_names_the_hold_shading(tmp_path, figures, scenario, horizon,
                                                                        has_holds):
    result = reproduce.run_scenario(scenario, horizon=horizon, horizons=())
    reproduce.write_outputs(result, tmp_path)
    units = reproduce.STATE_UNITS[result.scenario.example]
    assert figures and all(name.endswith(".png") for name in figures)
    for name, fig in figures.items():
        axes = fig.get_axes()
        assert len(axes) == len(result.state_names), name
        for j, ax in enumerate(axes):
            label = ax.get_ylabel()
            assert re.search(rf"\b{re.escape(result.state_names[j])} \({re.escape(units[j])}\)$", label), \
                (name, label)
        legend = axes[0].get_legend()
        texts = [t.get_text() for t in legend.get_texts()]
        assert (reproduce.HOLD_LABEL in texts) == has_holds, (name, texts)
