"""hil's report says what was measured and only that:

- a firmware time at the top of its Diagnostics signal is printed as the
  lower bound it is (">= X us, saturated"), never as a measurement; the
  firmware carries step times far beyond the 655.35 us the 16-bit signal
  could (StepTimeMax is 24 bits since rhonn_id 2.1), and logs recorded in
  rhonn_id 2.0 still decode;
- the table's labels never run into their values;
- the figures have an error panel, zooms on the hold and its end, units on
  every y axis, the hold in the legend, and the latency's p99 and p99.9 and
  its course over the run.
"""
from __future__ import annotations

import functools

import numpy as np
import pytest

can = pytest.importorskip("can")
pytest.importorskip("cantools")

from pyrhonn import atomic  # noqa: E402
from pyrhonn import firmware  # noqa: E402
from pyrhonn.configfile import load_shipped  # noqa: E402
from pyrhonn.firmware import FirmwareApp  # noqa: E402

from hil import diagnostics, report  # noqa: E402
from hil.scenario import Scenario  # noqa: E402
from hil.score import score  # noqa: E402
from hil.transport import lim_config, run_replay  # noqa: E402

DB = firmware.database()
DIAG = DB.get_message_by_name("Diagnostics")


@functools.cache
def _run():
    """A 0.3 s virtual replay through the end of the paper's hold (2.1 s), with 1 % frame loss."""
    return run_replay(Scenario(duration=0.3, start=1.95, frame_loss=0.01, seed=5), "virtual")


def _with_final_diagnostics(rec, **signals):
    """``rec`` with its last Diagnostics frame's ``signals`` replaced (raw values)."""
    events = list(rec.events)
    i = max(i for i, (_, d, m) in enumerate(events) if d == "rx" and m.arbitration_id == DIAG.frame_id)
    t, d, m = events[i]
    values = DIAG.decode(bytes(m.data), scaling=False, decode_choices=False)
    values.update(signals)
    events[i] = (t, d, can.Message(arbitration_id=m.arbitration_id, is_extended_id=False, is_fd=True,
                                   is_rx=True, timestamp=m.timestamp,
                                   data=DIAG.encode(values, scaling=False, strict=False)))
    return type(rec)(scenario=rec.scenario, events=events, meta=dict(rec.meta))


# -- saturation -----------------------------------------------------------------------------------


def _step_time_max_after_a_step_of(step_ns: int) -> dict:
    app = FirmwareApp(None, load_shipped("firmware-lim").config, host_clock=False)
    app.tick_ns = step_ns  # the simulated clock: each step takes this long
    app.handle(firmware.measurement_message(0, np.zeros(6), np.zeros(2)))
    diag = app.send_diagnostics()[0]
    return diagnostics.decode(bytes(diag.data))


def test_the_firmware_reports_a_12_ms_step_as_12_ms_not_as_the_16_bit_ceiling() -> None:
    d = _step_time_max_after_a_step_of(12_447_800)
    assert d["StepTimeMax"] == pytest.approx(12_447.8) and "StepTimeMax" not in d["saturated"]
    assert d["StepTime"] == pytest.approx(655.35) and "StepTime" in d["saturated"]  # the 16-bit last step


def test_a_step_beyond_the_24_bit_range_is_sent_saturated_and_decoded_as_such() -> None:
    d = _step_time_max_after_a_step_of(400_000_000)  # 0.4 s: a process frozen by the host
    assert d["StepTimeMax"] == pytest.approx(167_772.15) and "StepTimeMax" in d["saturated"]
    assert DIAG.get_signal_by_name("StepTimeMax").length == 24 and DIAG.length == 32
    assert DB.version == "rhonn_id 2.2"


def test_the_diagnostics_frame_uses_every_bit_once_and_keeps_the_other_frames() -> None:
    bits = sorted(b for s in DIAG.signals for b in range(s.start, s.start + s.length))
    assert bits == list(range(256))  # 32 bytes, no overlap, nothing left over
    assert [DB.get_message_by_name(n).length for n in ("Measurement", "Estimate", "Control", "WeightLoad",
                                                       "ControlAck", "Health")] == [20, 16, 16, 64, 8, 48]


def test_a_saturated_step_time_max_is_printed_as_a_lower_bound_never_as_a_measurement() -> None:
    top = (1 << 24) - 1
    r = score(_with_final_diagnostics(_run(), StepTimeMax=top, StepTime=0xFFFF))
    fw = r["firmware"]
    assert fw["step_time_max_saturated"] and fw["last_step_time_saturated"]
    text = report.table(r)
    assert "step max >= 167,772.1 us, saturated" in text
    assert "step max 167" not in text
    r = score(_with_final_diagnostics(_run(), StepTimeMax=1_244_780))   # 12,447.8 us: measured
    assert not r["firmware"]["step_time_max_saturated"]
    assert "step max 12,447.8 us\n" in report.table(r)


def test_a_log_recorded_in_rhonn_id_2_0_decodes_its_16_bit_step_time_max_and_flags_its_ceiling() -> None:
    legacy = diagnostics._message(diagnostics.LEGACY_PROTOCOL)
    rec = _run()
    events = []
    for t, d, m in rec.events:  # every Diagnostics frame re-encoded in the old layout
        if d == "rx" and m.arbitration_id == DIAG.frame_id:
            values = DIAG.decode(bytes(m.data), scaling=False, decode_choices=False)
            values["StepTimeMax"] = 0xFFFF
            m = can.Message(arbitration_id=m.arbitration_id, is_extended_id=False, is_fd=True, is_rx=True,
                            data=legacy.encode(values, scaling=False))
        events.append((t, d, m))
    old = type(rec)(scenario=rec.scenario, events=events, meta={**rec.meta, "protocol": "rhonn_id 2.0"})
    live, again = score(rec), score(old)
    assert again["frames"] == live["frames"]   # the counts after StepTimeMax are where 2.0 had them
    assert {k: v for k, v in again["firmware"].items() if "step_time_max" not in k and k != "protocol"} == \
        {k: v for k, v in live["firmware"].items() if "step_time_max" not in k and k != "protocol"}
    assert again["firmware"]["step_time_max_us"] == pytest.approx(655.35)
    assert "step max >= 655.4 us, saturated" in report.table(again)


# -- the table's layout ----------------------------------------------------------------------------


def test_every_label_of_the_table_ends_before_its_value_starts() -> None:
    r = score(_run(), reference=lim_config())
    text = report.table(r, timing_note="a note")
    labels = ["frames", "firmware (Diagnostics)", "filter health", "identification", "bit exact vs offline",
              "timing (us)", "  latency send->est.", "  (stamped at)", "  rig lateness", "  position (m)"]
    lines = text.splitlines()
    for label in labels:
        row = next(ln for ln in lines if ln.startswith(label))
        assert row[:report.LABEL_WIDTH].rstrip() == label, row
        assert row == label or row[report.LABEL_WIDTH - 1] == " ", row
    assert "firmware (Diagnostics)  measurements " in text
    assert all(ln == ln.rstrip() for ln in lines)
    # the continuation lines start in the value column
    for ln in lines:
        if ln.startswith(" " * report.LABEL_WIDTH) and ln.strip():
            assert ln[report.LABEL_WIDTH] != " " or ln.lstrip().startswith("(")


# -- the figures -----------------------------------------------------------------------------------


@pytest.fixture
def saved_figures(monkeypatch, tmp_path):
    """The matplotlib figures report.figures saves, by file name (still open)."""
    figs = {}

    def keep(fig, path, **kwargs):
        figs[path.name] = fig
        return path

    import matplotlib.pyplot as plt
    monkeypatch.setattr(atomic, "save_figure", keep)
    monkeypatch.setattr(plt, "close", lambda fig=None: None)
    report.figures(score(_run()), tmp_path)
    yield figs
    monkeypatch.undo()
    for fig in figs.values():
        plt.close(fig)


def _all_axes_have_units(fig) -> None:
    for ax in fig.axes:
        label = ax.get_ylabel()
        assert label.endswith(")") and "(" in label, label


def test_state_figures_have_an_error_panel_and_zooms_on_the_hold_and_its_end(saved_figures) -> None:
    sc = _run().scenario
    hold_end = sc.hold_start + sc.hold_duration
    for name, unit in (("position", "m"), ("velocity", "m/s")):
        fig = saved_figures[f"{name}.png"]
        _all_axes_have_units(fig)
        top, _frames, err, zoom_hold, zoom_end = fig.axes
        assert err.get_ylabel() == f"error ({unit})"
        assert "zoom: the hold" in zoom_hold.get_title() and "end of the hold" in zoom_end.get_title()
        lo, hi = zoom_end.get_xlim()
        assert lo < hold_end < hi and hi - lo < 0.1
        lo, hi = zoom_hold.get_xlim()
        assert lo < sc.hold_start and hi > hold_end
        legend = [t.get_text() for t in top.get_legend().get_texts()]
        assert any("held" in s for s in legend), legend              # the hold's shading is in the legend
        # the real trace is drawn over the identified one, not hidden under it
        real = next(ln for ln in top.get_lines() if ln.get_label().startswith("real"))
        ident = next(ln for ln in top.get_lines() if ln.get_label().startswith("identified"))
        assert real.get_zorder() > ident.get_zorder()


def test_the_latency_figure_marks_p99_and_p999_and_shows_latency_over_time(saved_figures) -> None:
    fig = saved_figures["latency.png"]
    _all_axes_have_units(fig)
    hist, over = fig.axes
    lat = np.asarray(score(_run())["_series"]["latency_ns"]) / 1e3
    p99, p999 = np.percentile(lat, [99, 99.9])
    for ax in (hist, over):
        labels = [t.get_text() for t in ax.get_legend().get_texts()]
        assert f"p99 {p99:.1f} us" in labels and f"p99.9 {p999:.1f} us" in labels
    assert over.get_xlabel().startswith("time") and over.get_ylabel() == "latency (us)"
    points = next(ln for ln in over.get_lines() if ln.get_label() == "one estimate")
    assert len(points.get_xdata()) == lat.size
