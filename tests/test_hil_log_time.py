"""hil logs carry the run's wall-clock time and keep their frames in time order:

- a BLF's header and an ASC's Triggerblock hold the moment of the run, and
  python-can's readers give every frame its absolute time, non-decreasing in
  file order;
- the relative times the score uses come back exactly (BLF, to the ns);
- a received frame stamped by the kernel before a frame the rig sent while
  it waited to be picked up goes before it, and the score still pairs each
  Estimate with its Measurement;
- logs of the format before (times from 0, frames in pick-up order,
  rhonn_id 2.0 Diagnostics) are still read and score the same, and a
  sidecar of a newer format or an unknown protocol is refused by name.
"""
from __future__ import annotations

import datetime
import functools
import json
import re
import time
from pathlib import Path

import numpy as np
import pytest

can = pytest.importorskip("can")
pytest.importorskip("cantools")

from pyrhonn import firmware  # noqa: E402

from hil import diagnostics  # noqa: E402
from hil.rig import Recording, Rig, read_log, sidecar, write_log  # noqa: E402
from hil.scenario import Scenario  # noqa: E402
from hil.score import score  # noqa: E402
from hil.transport import run_replay  # noqa: E402

DB = firmware.database()
MEAS, EST, DIAG = (DB.get_message_by_name(n) for n in ("Measurement", "Estimate", "Diagnostics"))
SCENARIO = Scenario(duration=0.1, start=1.95, frame_loss=0.02, seed=9)


@functools.cache
def _run() -> tuple[Recording, float, float]:
    before = time.time()
    rec = run_replay(SCENARIO, "virtual")
    return rec, before, time.time()


def _times(reader) -> list[float]:
    try:
        return [m.timestamp for m in reader]
    finally:
        reader.stop()


def test_a_blf_log_holds_the_runs_wall_clock_and_its_frames_in_time_order(tmp_path) -> None:
    rec, before, after = _run()
    path = write_log(rec, tmp_path / "run.blf")
    wall = json.loads(sidecar(path).read_text())["wall_time_ns"] / 1e9
    assert before - 1 <= wall <= after
    reader = can.BLFReader(path)
    assert reader.start_timestamp == pytest.approx(wall, abs=1e-3) and reader.start_timestamp <= wall
    ts = _times(reader)
    assert before - 1 <= ts[0] <= after and ts[-1] <= after + 1
    assert np.all(np.diff(ts) >= 0)
    assert ts[0] == pytest.approx(wall + rec.events[0][0], abs=1e-6)


def test_an_asc_log_starts_its_triggerblock_at_the_run_not_in_1970(tmp_path) -> None:
    rec, before, after = _run()
    path = write_log(rec, tmp_path / "run.asc")
    text = path.read_text()
    block = re.search(r"^Begin Triggerblock \w+ (.+)$", text, re.M).group(1)
    assert str(datetime.datetime.fromtimestamp(before).year) in block and "1970" not in block
    ts = _times(can.ASCReader(path, relative_timestamp=False))
    assert before - 1 <= ts[0] <= after and np.all(np.diff(ts) >= 0)


@pytest.mark.parametrize("ms", [0, 7, 53, 530, 999])
def test_an_asc_log_started_early_in_a_second_keeps_its_milliseconds(tmp_path, ms: int) -> None:
    # python-can's own ASC header writes the milliseconds unpadded (53 ms as ".53", read back as
    # 530 ms): every absolute frame time of such a log came out late by up to 0.9 s
    import dataclasses

    rec, before, _ = _run()
    wall_ns = (int(before) - 5) * 1_000_000_000 + ms * 1_000_000 + 123_456
    moved = dataclasses.replace(rec, meta={**rec.meta, "wall_time_ns": wall_ns})
    path = write_log(moved, tmp_path / "run.asc")
    block = re.search(r"^Begin Triggerblock \w+ (.+)$", path.read_text(), re.M).group(1)
    assert f":{ms:03d} " in block.replace(".", ":")
    ts = _times(can.ASCReader(path, relative_timestamp=False))
    first = wall_ns / 1e9 + moved.events[0][0]
    assert ts[0] == pytest.approx(first, abs=2e-6)


@pytest.mark.parametrize("name, tol", [("run.blf", 1e-9), ("run.asc", 1e-6)])
def test_the_relative_times_come_back_as_recorded(tmp_path, name, tol) -> None:
    rec, _, _ = _run()
    back = read_log(write_log(rec, tmp_path / name))
    assert len(back.events) == len(rec.events)
    assert [(d, bytes(m.data)) for _, d, m in back.events] == [(d, bytes(m.data)) for _, d, m in rec.events]
    assert np.max(np.abs(np.array([t for t, _, _ in back.events]) - [t for t, _, _ in rec.events])) <= tol
    assert back.meta["first_run_event"] == rec.meta["first_run_event"]
    assert back.meta["wall_time_ns"] == rec.meta["wall_time_ns"] and back.meta["protocol"] == DB.version


def _estimate(seq: int) -> can.Message:
    fields = {s.name: 0 for s in EST.signals}
    fields["Seq"] = seq
    return can.Message(arbitration_id=EST.frame_id, is_extended_id=False, is_fd=True,
                       data=EST.encode(fields, scaling=False))


def test_a_frame_the_kernel_stamped_before_a_later_send_is_recorded_before_it() -> None:
    plan = SCENARIO.replace(frame_loss=0.0).build()
    rig = Rig(None, plan, transport="udp_multicast", channel="test")
    frames = plan.frames()
    ms = 1_000_000
    # pick-up order: Measurement 0 sent at 1 ms, 1 at 1.3 ms; the Estimate of 0 reached the socket at
    # 1.1 ms but was picked up after the second send; the Estimate of 1 at 1.5 ms
    rig._events = [(1 * ms, "tx", frames[0]), (1_300_000, "tx", frames[1]), (1_100_000, "rx", _estimate(0)),
                   (1_500_000, "rx", _estimate(1))]
    rig._run_start = 0
    rec = rig._recording({})
    assert [(round(t * 1e9), d) for t, d, _ in rec.events] == [(0, "tx"), (100_000, "rx"), (300_000, "tx"),
                                                               (500_000, "rx")]
    assert [t for t, _, _ in rec.events] == sorted(t for t, _, _ in rec.events)


def test_an_estimate_stamped_a_few_us_before_its_measurement_is_still_its_answer() -> None:
    rec, _, _ = _run()
    live = score(rec)
    events = list(rec.events)
    i = next(i for i, (_, d, m) in enumerate(events) if d == "rx" and m.arbitration_id == EST.frame_id)
    seq = firmware.decode_estimate(events[i][2]).seq
    j = next(j for j, (_, d, m) in enumerate(events) if d == "tx" and m.arbitration_id == MEAS.frame_id
             and int.from_bytes(bytes(m.data[:2]), "little") == seq)
    t, d, m = events.pop(i)
    events.insert(j, (events[j][0] - 3e-6, d, m))   # 3 us before its Measurement: a clock-pairing error
    shifted = score(Recording(scenario=rec.scenario, events=events, meta=dict(rec.meta)))
    assert shifted["frames"]["answered"] == live["frames"]["answered"]
    assert shifted["frames"]["unexpected"] == 0 and shifted["frames"]["missing"] == live["frames"]["missing"]


def _as_format_2(rec: Recording, path: Path) -> tuple[Path, bool]:
    """``rec`` written as the format before wrote it: times from 0, no wall clock, no protocol, rhonn_id 2.0
    Diagnostics, frames in pick-up order (here: two frames swapped out of time order). Also whether a
    value had to be saturated to its rhonn_id 2.0 signal, as that firmware did: StepTimeMax, 16 bits
    there (655.35 us), reaches that on a loaded machine."""
    legacy = diagnostics._message(diagnostics.LEGACY_PROTOCOL)
    top = {sig.name: (1 << sig.length) - 1 for sig in legacy.signals}
    events, saturated = [], False
    for t, d, m in rec.events:
        if d == "rx" and m.arbitration_id == DIAG.frame_id:
            values = DIAG.decode(bytes(m.data), scaling=False, decode_choices=False)
            saturated |= any(values[name] > top[name] for name in top)
            values = {name: min(values[name], top[name]) for name in top}
            m = can.Message(arbitration_id=m.arbitration_id, is_extended_id=False, is_fd=True, is_rx=True,
                            data=legacy.encode(values, scaling=False))
        events.append((t, d, m))
    k = next(k for k in range(len(events) - 1) if events[k][1] == "tx" and events[k + 1][1] == "rx"
             and events[k + 1][2].arbitration_id == EST.frame_id and k > rec.meta["first_run_event"] + 50)
    events[k], events[k + 1] = events[k + 1], events[k]   # an Estimate stamped before a frame sent after it
    meta = {key: v for key, v in rec.meta.items() if key not in ("wall_time_ns", "protocol")}
    write_log(Recording(scenario=rec.scenario, events=events, meta=meta), path)
    side = json.loads(sidecar(path).read_text())
    side["format"] = "pyrhonn-hil-log 2"
    for key in ("wall_time_ns", "protocol"):
        del side[key]
    sidecar(path).write_text(json.dumps(side))
    return path, saturated


@pytest.mark.parametrize("name", ["old.blf", "old.asc"])
def test_a_log_of_the_format_before_is_read_and_scores_the_same(tmp_path, name) -> None:
    rec, _, _ = _run()
    path, saturated = _as_format_2(rec, tmp_path / name)
    if name.endswith(".blf"):
        assert can.BLFReader(path).start_timestamp == 0  # as those logs were: no wall clock
    old = read_log(path)
    assert old.meta["protocol"] == "rhonn_id 2.0" and old.meta.get("wall_time_ns") is None
    live, again = score(rec), score(old)
    assert again["frames"]["answered"] == live["frames"]["answered"] and again["frames"]["accounted"]
    # a step slower than 655.35 us (a loaded machine) reads as that ceiling in the old layout, flagged
    differ = {"protocol", "step_time_max_us", "step_time_max_saturated"} if saturated else {"protocol"}
    assert {k: v for k, v in again["firmware"].items() if k not in differ} == \
        {k: v for k, v in live["firmware"].items() if k not in differ}
    if saturated:
        assert again["firmware"]["step_time_max_saturated"]
        assert again["firmware"]["step_time_max_us"] == pytest.approx(655.35)


def test_a_sidecar_of_a_newer_format_or_an_unknown_protocol_is_refused_by_name(tmp_path, cli_error) -> None:
    rec, _, _ = _run()
    path = write_log(rec, tmp_path / "run.blf")
    side = json.loads(sidecar(path).read_text())
    sidecar(path).write_text(json.dumps({**side, "format": "pyrhonn-hil-log 99"}))
    assert "format 'pyrhonn-hil-log 99' is newer than this pyrhonn reads" in cli_error(["hil", "score", str(path)])
    sidecar(path).write_text(json.dumps({**side, "protocol": "rhonn_id 9.9"}))
    err = cli_error(["hil", "score", str(path)])
    assert 'recorded in protocol "rhonn_id 9.9"; this hil decodes' in err and "refused" in err
    sidecar(path).write_text(json.dumps({**side, "wall_time_ns": "yesterday"}))
    assert "not a hil log sidecar (wall_time_ns:" in cli_error(["hil", "score", str(path)])


def test_a_log_of_rhonn_id_2_1_scores_the_same_with_its_32_byte_health_frames_and_no_gated_count(tmp_path) -> None:
    from hil.report import table

    rec, _, _ = _run()
    health_id = DB.get_message_by_name("Health").frame_id
    events = [(t, d, m if m.arbitration_id != health_id else
               can.Message(arbitration_id=health_id, is_extended_id=False, is_fd=True, is_rx=True,
                           data=bytes(m.data[:32])))            # Gated (bits 256-287) was not there
              for t, d, m in rec.events]
    path = tmp_path / "old.blf"
    write_log(Recording(scenario=rec.scenario, events=events, meta={**rec.meta, "protocol": "rhonn_id 2.1"}), path)
    old = read_log(path)
    assert old.meta["protocol"] == "rhonn_id 2.1"
    live, again = score(rec), score(old)
    assert again["frames"] == live["frames"] and again["firmware"]["measurements"] == live["firmware"]["measurements"]
    assert [h["gated"] for h in live["health"]] == [0] * 6 and [h["gated"] for h in again["health"]] == [None] * 6
    assert [{**h, "gated": 0} for h in again["health"]] == live["health"]
    assert "gated 0" in table(live) and "gated" not in table(again)
