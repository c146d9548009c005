"""hil replay's figures for a test engineer: the Measurement frames under the
estimate, the filter's health over the run, frame loss and kernel drops over
time, and a warning printed on figures whose timing comes from the virtual bus.
Checked on the matplotlib figure objects (Agg), not on pixels."""
from __future__ import annotations

import itertools

import numpy as np
import pytest

pytest.importorskip("can")
pytest.importorskip("cantools")

from hil import figures as hil_figures  # noqa: E402
from hil.rig import DROP_SAMPLES_EVERY, Rig  # noqa: E402
from hil.scenario import Scenario  # noqa: E402
from hil.score import FATES, score  # noqa: E402
from hil.transport import lim_config, open_transport, run_replay  # noqa: E402

# through the start of the paper's hold (1.1 s), 2 % frame loss
SCENARIO = Scenario(duration=0.3, start=0.95, frame_loss=0.02, seed=7)


@pytest.fixture(scope="module")
def scored() -> dict:
    return score(run_replay(SCENARIO, "virtual"), reference=lim_config())


@pytest.fixture(scope="module")
def figs(scored):
    import matplotlib.pyplot as plt

    out = hil_figures.build_figures(scored)
    yield out
    for fig in out.values():
        plt.close(fig)


def _labels(ax) -> list[str]:
    return ax.get_legend_handles_labels()[1]


def _texts(fig) -> str:
    return " ".join(t.get_text() for t in fig.texts)


def test_the_frames_the_firmware_got_are_drawn_under_the_estimate_measured_held_and_missing(scored, figs) -> None:
    fate = scored["_series"]["fate"]
    valid = scored["_series"]["valid"]
    used = (fate == FATES.index("answered")) | (fate == FATES.index("lost from the firmware"))
    for j, name in enumerate(("position", "velocity")):
        top, frames = figs[f"{name}.png"].axes[:2]
        assert frames.get_title() == "Measurement frames sent to the firmware"
        assert frames.get_position().y1 < top.get_position().y0          # the panel is under the estimate
        lines = {ln.get_label().split(" (")[0]: ln for ln in frames.get_lines()}
        measured, held, missing = (lines[k] for k in ("measured", "held / not valid", "missing: lost or refused"))
        assert len(measured.get_xdata()) == int((used & valid[:, j]).sum()) > 0
        assert len(held.get_xdata()) == int((used & ~valid[:, j]).sum()) > 0    # the hold began at 1.1 s
        assert len(missing.get_xdata()) == int((~used).sum()) > 0               # 2 % of the frames were lost
        assert f"missing: lost or refused ({int((~used).sum())})" in _labels(frames)


def test_the_health_figure_shows_nis_in_its_chi_square_band_trace_p_refusals_and_resets(scored, figs) -> None:
    fig = figs["health.png"]
    nis_ax, p_ax, n_ax = fig.axes
    assert "95 % band of chi-square(1)" in _labels(nis_ax)
    band = next(p for p in nis_ax.patches if p.get_label() == "95 % band of chi-square(1)")
    lo, hi = band.get_y(), band.get_y() + band.get_height()
    assert (lo, hi) == pytest.approx(hil_figures.NIS_BAND)
    assert nis_ax.get_yscale() == "log" and p_ax.get_yscale() == "log"
    neurons = len(lim_config().neurons)
    assert [f"neuron {i}" for i in range(neurons)] == [s for s in _labels(p_ax) if s.startswith("neuron")]
    assert {f"refused, neuron {i}" for i in range(neurons)} | {f"resets, neuron {i}" for i in range(neurons)} \
        <= set(_labels(n_ax))
    # the twin's health at the last sample is the firmware's own (its Health frames after the run)
    h = scored["_series"]["health"]
    last = {int(e["neuron"]): e for e in scored["health"]}
    for i in range(neurons):
        assert h["updates"][-1, i] == last[i]["updates"]
        assert h["trace_p"][-1, i] == pytest.approx(last[i]["trace_p"], rel=1e-6)


def test_resets_are_marked_on_every_health_panel(scored) -> None:
    import matplotlib.pyplot as plt

    r = {**scored, "_series": dict(scored["_series"])}
    h = {k: np.array(v) for k, v in r["_series"]["health"].items()}
    h["resets"][len(h["cycle"]) // 2:, 1] += 1           # a covariance reset of neuron 1 half-way through
    r["_series"]["health"] = h
    fig = hil_figures.build_figures(r)["health.png"]
    try:
        t_reset = r["_series"]["t"][h["cycle"][len(h["cycle"]) // 2]]
        for ax in fig.axes:
            marks = [ln for ln in ax.get_lines() if ln.get_linestyle() == ":" and ln.get_color() == "tab:red"]
            assert [m.get_xdata()[0] for m in marks] == [pytest.approx(t_reset)]
        assert "covariance reset" in _labels(fig.axes[0])
    finally:
        plt.close("all")


def test_the_losses_figure_counts_each_kind_of_loss_over_time(scored, figs) -> None:
    fig = figs["losses.png"]
    loss_ax, drops_ax = fig.axes
    fate = scored["_series"]["fate"]
    injected = int((fate == FATES.index("lost (injected)")).sum())
    line = next(ln for ln in loss_ax.get_lines() if ln.get_label().startswith("lost (injected)"))
    assert line.get_label() == f"lost (injected) ({injected})" and int(np.sum(line.get_ydata())) == injected
    assert any(s.startswith("estimate later than one period") for s in _labels(loss_ax))
    assert "not counted" in " ".join(t.get_text() for t in drops_ax.texts)   # the virtual bus drops nothing


def test_figures_with_virtual_bus_timing_carry_a_warning_on_them(scored, figs) -> None:
    for name in ("latency.png", "losses.png"):
        assert hil_figures.VIRTUAL_WARNING in _texts(figs[name]), name
    assert hil_figures.VIRTUAL_WARNING not in _texts(figs["position.png"])
    real = hil_figures.build_figures({**scored, "transport": "udp_multicast"})
    try:
        assert hil_figures.VIRTUAL_WARNING not in _texts(real["latency.png"])
    finally:
        import matplotlib.pyplot as plt

        for fig in real.values():
            plt.close(fig)


def test_the_kernel_drop_counters_are_sampled_during_the_run_and_plotted_over_time() -> None:
    import matplotlib.pyplot as plt

    sc = Scenario(duration=0.25, start=0.0, hold_duration=0.0, seed=1)
    counter = itertools.count()

    def drops() -> dict[str, int]:   # a counter that grows on every read: each sample shows a new value
        n = next(counter)
        return {"rig": n, "firmware": 2 * n}

    with open_transport("virtual") as (bus, where, _side):
        rec = Rig(bus, sc.build(), transport="virtual", channel=where, spin_ns=0, kernel_drops=drops,
                  sample_drops=True).run()
    series = rec.meta["kernel_drops_series"]
    assert series["cycle"] == list(range(0, sc.cycles, DROP_SAMPLES_EVERY))
    assert series["rig"] == list(range(1, len(series["cycle"]) + 1))      # since the read before the run
    assert series["firmware"] == [2 * n for n in series["rig"]]
    with open_transport("virtual") as (bus, where, _side):   # a timing run (hil bench) reads them before and after
        quiet = Rig(bus, sc.build(), transport="virtual", channel=where, spin_ns=0, kernel_drops=drops).run()
    assert quiet.meta["kernel_drops_series"] == {"cycle": [], "rig": [], "firmware": []}
    r = score(rec)
    fig = hil_figures.build_figures(r)["losses.png"]
    try:
        labels = _labels(fig.axes[1])
        assert any(s.startswith("kernel drops, rig socket") for s in labels)
        assert any(s.startswith("kernel drops, firmware socket") for s in labels)
    finally:
        plt.close("all")


def test_cli_replay_out_writes_every_figure(tmp_path) -> None:
    from pyrhonn.cli import main

    out = tmp_path / "out"
    assert main(["hil", "replay", "--transport", "virtual", "--duration", "0.2", "--start", "1.0", "--quiet",
                 "--out", str(out)]) == 0
    for name in ("position.png", "velocity.png", "health.png", "losses.png", "latency.png"):
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", name
