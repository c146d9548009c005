"""``pyrhonn export --dbc``: the CAN FD protocol of an exported identifier, each
state's and input's signal scaled from the data's range, resolution stated."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

cantools = pytest.importorskip("cantools")

from pyrhonn import dbc  # noqa: E402
from pyrhonn.cli import main  # noqa: E402
from pyrhonn.plants import oscillator  # noqa: E402


def _write(path: Path, X: np.ndarray, U: np.ndarray) -> None:
    rows = ["x1,x2,x3,x4,u"] + [",".join(repr(float(v)) for v in (*x, *u)) for x, u in zip(X, U)]
    path.write_text("\n".join(rows) + "\n")


def test_export_writes_a_dbc_whose_signals_carry_the_data_at_the_stated_resolution(tmp_path, capsys) -> None:
    traj = oscillator.simulate(dt=0.2, horizon=20.0)
    data, out = tmp_path / "data.csv", tmp_path / "osc.dbc"
    _write(data, traj.X_meas, traj.U)
    assert main(["export", "--config", "example1", "--data", str(data), "--out", str(tmp_path / "osc.h"),
                 "--dbc", str(out)]) == 0
    printed = capsys.readouterr().out
    db = cantools.database.load_file(out)
    meas, est = db.get_message_by_name("Measurement"), db.get_message_by_name("Estimate")
    names = ["x1", "x2", "x3", "x4"]
    assert {s.name for s in meas.signals} == {"Seq", *(f"Valid{n}" for n in names), *names, "u"}
    assert {s.name for s in est.signals} == {"Seq", "StepStatus", "Learning", "Saturated", "Resync",
                                             *(f"{n}Hat" for n in names)}
    assert meas.is_fd and meas.length in dbc.FD_LENGTHS and meas.length * 8 >= 24 + 16 * 5
    for msg in ("Control", "ControlAck", "WeightLoad", "Diagnostics", "Health"):
        db.get_message_by_name(msg)                                       # the protocol's other frames
    assert db.get_message_by_name("Health").get_signal_by_name("Neuron").maximum == 3
    data_all = np.column_stack([traj.X_meas, traj.U])
    for j, name in enumerate([*names, "u"]):
        sig = meas.get_signal_by_name(name)
        peak = float(np.max(np.abs(data_all[:, j])))
        assert sig.maximum == -sig.minimum >= peak and sig.maximum <= sig.scale * 32767
        assert f"resolution {sig.scale:g} per LSB" in sig.comment
        line = next(ln for ln in printed.splitlines() if ln.split()[:1] == [name])
        assert f"resolution {sig.scale:g} " in line
        if j < 4:
            assert est.get_signal_by_name(f"{name}Hat").scale == sig.scale
    # every sample of the data goes through the frame within half an LSB
    for k in range(0, len(traj.X_meas), 17):
        values = {"Seq": k, **{f"Valid{n}": 1 for n in names},
                  **{n: float(v) for n, v in zip([*names, "u"], data_all[k])}}
        back = meas.decode(meas.encode(values))
        for n in [*names, "u"]:
            assert abs(back[n] - values[n]) <= meas.get_signal_by_name(n).scale / 2 + 1e-12


def test_writing_a_dbc_leaves_the_firmware_protocol_of_this_process_as_it_was() -> None:
    from pyrhonn import firmware

    before = firmware.database().as_dbc_string()
    dbc.database_text(("a", "b"), ("u",), np.ones((3, 2)), np.ones((3, 1)), name="two")
    assert firmware.database().as_dbc_string() == before
    assert firmware.measurement_message(0, np.zeros(6), np.zeros(2), np.ones(6, dtype=bool)).data


def test_dbc_needs_data_to_scale_from(tmp_path, cli_error) -> None:
    err = cli_error(["export", "--config", "example1", "--out", str(tmp_path / "x.h"), "--dbc",
                     str(tmp_path / "x.dbc")])
    assert "--dbc" in err and "--data" in err
    assert not (tmp_path / "x.dbc").exists()


def test_an_identifier_too_wide_for_a_can_fd_frame_is_refused_naming_the_bytes() -> None:
    names = tuple(f"s{j}" for j in range(32))
    with pytest.raises(ValueError, match=r"Measurement of 32 states and 0 inputs: needs 70 bytes"):
        dbc.database_text(names, (), np.ones((3, 32)), np.zeros((3, 0)))


def test_a_signal_without_a_finite_value_or_out_of_scale_is_refused_naming_it() -> None:
    with pytest.raises(ValueError, match="^omega: no finite value"):
        dbc.scaling_for("omega", np.array([np.nan, np.nan]))
    for peak in (1e-25, 1e35):
        with pytest.raises(ValueError, match="^omega: the data's largest magnitude"):
            dbc.scaling_for("omega", np.array([0.0, peak]))
    zero = dbc.scaling_for("omega", np.zeros(4))          # 0 throughout: a signal of +-1
    assert zero.limit == 1.0 and zero.scale * dbc.RAW_MAX >= 1.0


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(min_value=-1e6, max_value=1e6).filter(lambda v: v == 0 or abs(v) >= 1e-12), min_size=1,
                max_size=20),
       st.floats(min_value=0.0, max_value=4.0))
def test_the_scale_is_the_finest_decimal_step_whose_16_bits_reach_the_range(values, headroom) -> None:
    s = dbc.scaling_for("x", np.array(values), headroom)
    peak = max(abs(v) for v in values)
    assert s.limit >= peak and s.limit <= s.scale * dbc.RAW_MAX * (1 + 1e-12)
    mantissa = s.scale / 10 ** math.floor(math.log10(s.scale))
    assert any(math.isclose(mantissa, m) for m in (1, 2, 5))
    reach = max(peak * (1 + headroom), 0.0) or 1.0
    assert s.scale * dbc.RAW_MAX >= reach * (1 - 1e-9)
    finer = s.scale * 0.4 if round(mantissa) == 5 else s.scale / 2     # 5 -> 2, 2 -> 1, 1 -> 0.5
    assert finer * dbc.RAW_MAX < reach * (1 + 1e-9)          # one step finer would not reach it
