"""hil/: the LIM rig replayed against the firmware over python-can,
on the host transports (virtual in-process, udp_multicast between processes,
where the firmware is the C runner or the Python node).

- The estimates that come back equal, bit for bit after the DBC's scaling,
  Identifier.run (float32) on the decoded Measurement frames the firmware
  accepted; injected frame loss is accounted for frame by frame, and agrees
  with the firmware's own Diagnostics.
- A recorded log re-scores to the same numbers.
- Faults: firmware not running, a burst of malformed frames, a sequence
  jump, a full log disk. Bad CLI input exits 2.
"""
from __future__ import annotations

import errno
import io
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from source_scripts import load_script  # noqa: E402

can = pytest.importorskip("can")
pytest.importorskip("cantools")

from pyrhonn import Identifier  # noqa: E402
from pyrhonn import firmware  # noqa: E402
from pyrhonn.cli import main as pyrhonn_main  # noqa: E402

from hil import report  # noqa: E402
from hil.rig import BusLost, FirmwareTimeout, LogWriteError, Rig, read_log, write_log  # noqa: E402
from hil.scenario import ENCODER_SENC50, Scenario  # noqa: E402
from hil.score import score  # noqa: E402
from hil.transport import lim_config, open_transport, run_replay  # noqa: E402

DB = firmware.database()
MEAS, EST = DB.get_message_by_name("Measurement"), DB.get_message_by_name("Estimate")
# 0.9 s .. 1.35 s: the input switches on at 1.0 s (not the paper's 2 s: the motor moves into the hold)
# and the position hold starts at 1.1 s
SCENARIO = Scenario(duration=0.45, start=0.9, input_start=1.0, frame_loss=0.02, seed=11)


def _independent_bit_exact(rec, *, every_sent: bool = False) -> int:
    """Not hil.score's check: pair the logged frames by Seq here and run the
    offline identifier on the Measurements the firmware stepped on, restarted
    where the Seq breaks as the firmware does: the answered ones, or
    (``every_sent``) every one that follows the one sent before it, i.e. all
    the firmware got when only Estimates were lost on the way back; compare
    the answered."""
    sent, answers = {}, {}
    for _, d, m in rec.events:
        if d == "tx" and m.arbitration_id == MEAS.frame_id and len(m.data) == MEAS.length:
            sent.setdefault(int.from_bytes(bytes(m.data[:2]), "little"), []).append(bytes(m.data))
        elif d == "rx" and m.arbitration_id == EST.frame_id:
            e = firmware.decode_estimate(m, scaling=False)
            answers[e.seq] = e.xhat
    first = next(iter(sent))
    # insertion order = sending order (no wrap in these runs)
    seqs = [s for s in sent if (s == first or s - 1 in sent)] if every_sent else [s for s in sent if s in answers]
    X, U, V = [], [], []
    for s in seqs:
        d = MEAS.decode(sent[s][-1], decode_choices=False)
        X.append([d[n] for n in firmware.STATE_SIGNALS])
        U.append([d[n] for n in firmware.INPUT_SIGNALS])
        V.append([bool(d[n]) for n in firmware.VALID_SIGNALS])
    X, U, V = np.array(X, np.float32), np.array(U, np.float32), np.array(V, bool)
    # a Seq that does not follow the last stepped one: the firmware restarted its identifier there
    ident, parts = Identifier(lim_config()), []
    for i, seg in enumerate(np.split(np.arange(len(seqs)), np.flatnonzero(np.diff(seqs) != 1) + 1)):
        if i:
            ident.restart()
        parts.append(ident.run(X[seg], U[seg], V[seg]))
    xhat = np.concatenate(parts)
    on = np.array([s in answers for s in seqs])
    seqs, xhat = [s for s in seqs if s in answers], xhat[on]
    for j, name in enumerate(firmware.ESTIMATE_SIGNALS):
        sig = EST.get_signal_by_name(name)
        lo, hi = int(sig.scaled_to_raw(sig.minimum)), int(sig.scaled_to_raw(sig.maximum))
        want = [min(max(sig.scaled_to_raw(float(v)), lo), hi) for v in xhat[:, j]]
        assert want == [int(answers[s][j]) for s in seqs], name
    return len(seqs)


def _assert_accounted(r: dict, rec, plan) -> None:
    """Every cycle accounted for, whatever a busy host's kernel dropped:
    sent = answered + rejected by the protocol + counted losses, agreeing
    with the firmware's Diagnostics and the kernel's drop counters; and every
    answered estimate exact, bit for bit (hil.score's check and this file's)."""
    f = r["frames"]
    assert f["lost_injected"] == int(plan.lost.sum()) and f["lost_unaccounted"] == 0
    assert f["sent"] == plan.cycles - f["lost_injected"]
    assert f["rejected_seq_jump"] == _expected_rejections(plan.lost)
    assert f["sent"] == (f["answered"] + f["rejected_seq_jump"] + f["lost_to_firmware"] + f["rejected_after_loss"]
                         + f["lost_from_firmware"])
    assert f["missing"] == 0 and f["accounted"]
    assert f["duplicates"] == f["unexpected"] == f["step_errors"] == 0
    assert r["firmware"]["measurements"] == f["answered"] + f["lost_from_firmware"]
    assert r["firmware"]["rejected"] == r["firmware"]["seq_errors"] == f["rejected_seq_jump"] + f["rejected_after_loss"]
    drops = f["kernel_drops"] or {"rig": 0, "firmware": 0}
    assert f["lost_to_firmware"] <= drops["firmware"] and f["lost_from_firmware"] <= drops["rig"]
    be = r["bit_exact"]
    assert be["equal"] and be["mismatches"] == 0
    if f["lost_to_firmware"] and f["lost_from_firmware"]:   # lost both ways: exact up to where it is known
        assert be["checked"] == int(np.sum(r["_series"]["k"] < (be["unknown_from"] or plan.cycles)))
    else:
        assert be["unknown_from"] is None and be["checked"] == f["answered"]
        assert _independent_bit_exact(rec, every_sent=f["lost_from_firmware"] > 0) == f["answered"]


def _expected_rejections(lost: np.ndarray) -> int:
    """A lost frame makes the next sent one a Seq jump (rejected); a run of losses, one."""
    return int(np.sum(lost[:-1] & ~lost[1:]))


# -- the scenario -------------------------------------------------------------------------------


def test_the_scenario_is_validated_seeded_and_models_the_rig() -> None:
    for bad in ({"period": 0}, {"duration": -1}, {"frame_loss": 0.9}, {"quantiser": "ceil"}, {"hold_states": (7,)},
                {"seed": -1}, {"encoder_resolution": float("nan")}, {"transport_delay": "1"}, {"duration": 3e-4}):
        with pytest.raises(ValueError, match=next(iter(bad))):
            Scenario(**bad)
    with pytest.raises(ValueError, match="unknown fields"):
        Scenario.from_dict({"bogus": 1})
    assert Scenario.from_dict(json.loads(SCENARIO.to_json())) == SCENARIO
    plan = SCENARIO.build()
    again = Scenario(**SCENARIO.to_dict() | {"hold_states": (0,)}).build()
    assert np.array_equal(plan.lost, again.lost) and plan.lost.sum() > 5
    assert ENCODER_SENC50 == 10e-6
    q = plan.X[:, 0]
    assert np.allclose(q / 10e-6, np.round(q / 10e-6), atol=1e-6)  # whole encoder counts
    moving = slice(400, 600)  # 1.02 s .. 1.08 s: before the hold, the motor moving
    np.testing.assert_allclose(plan.X[moving, 1][1:], np.diff(plan.X[moving, 0]) / 3e-4, atol=1e-9)
    counts = plan.X[moving, 1] * 3e-4 / 10e-6  # whole counts per period: 0, 1, ... (the high-frequency content)
    assert np.allclose(counts, np.round(counts), atol=1e-6) and len(set(np.round(counts))) >= 2
    held = (plan.t >= 1.1 - 1e-9)
    assert not plan.valid[held, 0].any() and plan.valid[~held, 0].all() and plan.valid[:, 2:].all()
    assert np.array_equal(plan.valid[:, 1], plan.valid[:, 0])   # the velocity is differenced from the position
    assert np.all(plan.X[held, 0] == plan.X[np.argmax(held) - 1, 0])  # the last valid reading, held
    assert np.abs(plan.truth_next[:, 0] - plan.X[:, 0]).max() > 1e-3  # the truth is not what was sent


def test_a_velocity_differenced_from_a_held_or_missing_position_is_marked_not_valid() -> None:
    # 0 .. 0.9 s: the motor moves from 0.1 s, the position is held 0.5 .. 0.6 s
    plan = Scenario(duration=0.9, input_start=0.1, hold_start=0.5, hold_duration=0.1).build()
    k = np.arange(plan.cycles)
    held = (k >= round(0.5 / 3e-4)) & (k < round(0.6 / 3e-4))
    assert np.array_equal(plan.valid[:, 0], ~held)
    first_after = int(np.flatnonzero(held)[-1]) + 1
    stale_v = held.copy()
    stale_v[first_after] = True          # its difference spans the whole hold
    stale_v[0] = True                    # no reading before the first one
    assert np.array_equal(plan.valid[:, 1], ~stale_v) and plan.valid[:, 2:].all()
    assert np.array_equal(plan.derived[:, 1], stale_v) and not plan.derived[:, [0, 2, 3, 4, 5]].any()
    assert plan.not_valid == {"Qm": {"held": int(held.sum()), "derived": 0},
                              "V": {"held": 0, "derived": int(stale_v.sum())}}
    # a fresh velocity is the difference of two fresh positions; a stale one goes out as the last fresh value
    fresh = np.flatnonzero(plan.valid[:, 1])
    np.testing.assert_allclose(plan.X[fresh, 1], (plan.X[fresh, 0] - plan.X[fresh - 1, 0]) / 3e-4, atol=1e-9)
    assert np.all(plan.X[first_after, 1] == plan.X[np.flatnonzero(held)[0] - 1, 1])
    # a velocity held on its own is held, not derived; without differencing nothing is derived
    alone = Scenario(duration=0.9, input_start=0.1, hold_start=0.5, hold_duration=0.1, hold_states=(1,)).build()
    assert alone.valid[:, 0].all() and alone.not_valid["V"]["held"] == int(held.sum())
    sensed = Scenario(duration=0.9, hold_start=0.5, hold_duration=0.1, velocity_from_position=False).build()
    assert sensed.valid[:, 1].all() and not sensed.derived.any() and list(sensed.not_valid) == ["Qm"]


def test_during_a_hold_the_firmware_bridges_on_its_own_predictions_instead_of_learning_stale_values() -> None:
    # the motor moves from 1.0 s; the position is held 2.5 .. 3.0 s, where it travels about 0.12 m
    sc = Scenario(duration=3.2, input_start=1.0, hold_start=2.5, hold_duration=0.5)
    plan = sc.build()
    rec = run_replay(sc, "virtual")
    r = score(rec, reference=lim_config())
    assert r["frames"]["answered"] == sc.cycles and r["bit_exact"]["equal"]
    # what went over the bus: position and velocity not valid through the hold, the velocity also on the
    # first frame after it (and on frame 0, which has no reading before it)
    sent = {}
    for _, d, m in rec.events[rec.meta["first_run_event"]:]:
        if d == "tx" and m.arbitration_id == MEAS.frame_id:
            f = MEAS.decode(bytes(m.data), decode_choices=False)
            sent[int(f["Seq"])] = (int(f["ValidQm"]), int(f["ValidV"]))
    inside = [k for k in range(sc.cycles) if 2.5 - 1e-9 <= plan.t[k] < 3.0 - 1e-9]
    after = inside[-1] + 1
    assert len(inside) == 1666 and all(sent[k] == (0, 0) for k in inside)
    assert sent[after] == (1, 0) and sent[after + 1] == (1, 1) and sent[inside[0] - 1] == (1, 1)
    assert sum(v == 0 for k in sent for v in sent[k]) == 1666 + 1666 + 2
    assert r["not_valid"] == {"Qm": {"held": 1666, "derived": 0}, "V": {"held": 0, "derived": 1668}}
    # inside the hold the identifier's position is within 10 % of the held frames' error (the target):
    # the position neuron's weights stay near the integrator (Q = 0) and the velocity neuron's free run
    # follows the motor without its position (the thrust in measured currents)
    hold = r["identification"]["position"]["hold"]
    assert hold["cycles"] == 1666
    assert hold["estimate_rmse_inside"] <= 0.10 * hold["frames_rmse_inside"]
    assert r["identification"]["velocity"]["hold"]["estimate_rmse_inside"] <= \
        0.10 * r["identification"]["velocity"]["hold"]["frames_rmse_inside"]
    # after it, the weights are intact: outside the hold the position is within 10x the encoder's own error
    # (the end of the free run, x(k+1) predicted at the last held sample, is not learned by the position neuron)
    pos = r["identification"]["position"]
    assert pos["outside_hold"]["rmse"] <= 10 * pos["measurement_vs_truth"]["rmse"]
    assert hold["end_error_max"] > 100 * pos["outside_hold"]["rmse"]  # the free run's end, reported apart
    text = report.table(r)
    assert "not valid: Qm 1666 (1666 held); V 1668 (1668 derived from a held or missing reading)" in text
    assert f"the held frames {hold['frames_rmse_inside']:.3e}" in text


# -- end to end -----------------------------------------------------------------------------------


@pytest.fixture(scope="session")
def udp_runner_exe(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """rhonn_runner built from the current sources (the same cache as tests/test_runner_udp.py)."""
    if shutil.which("cc") is None and shutil.which("gcc") is None:
        pytest.skip("no C compiler to build rhonn_runner")
    path = Path(__file__).resolve().parent.parent / "firmware_sim" / "linux" / "build_runner.py"
    return load_script(path, "_build_runner_replay").cached(tmp_path_factory.getbasetemp() / "runner-cache")


@pytest.mark.parametrize("transport, fw", [("virtual", True), ("udp_multicast", "python"), ("udp_multicast", "runner")])
def test_estimates_over_the_bus_are_identifier_run_bit_for_bit_and_every_lost_frame_is_accounted(
        transport, fw, request) -> None:
    sc = SCENARIO if transport == "virtual" else SCENARIO.replace(duration=0.3, seed=12)
    runner = str(request.getfixturevalue("udp_runner_exe")) if fw == "runner" else None
    plan = sc.build()
    rec = run_replay(sc, transport, firmware=fw, runner=runner, reply_timeout=30.0)
    r = score(rec, reference=lim_config())
    f = r["frames"]
    n_lost = int(plan.lost.sum())
    assert n_lost > 0
    _assert_accounted(r, rec, plan)
    if transport == "virtual":                        # in one process nothing else can be lost
        assert f["answered"] == f["sent"] - f["rejected_seq_jump"] and f["kernel_drops"] is None
        # the firmware counts every injected loss a later frame revealed (none before its first frame or after
        # its last)
        lead, trail = int(np.argmax(~plan.lost)), int(np.argmax(~plan.lost[::-1]))
        assert r["firmware"]["lost_frames"] == n_lost - lead - trail and r["firmware"]["rx_drops"] == 0
        assert f"lost {n_lost - lead - trail}  kernel drops 0" in report.table(r)
        # the firmware's filter health, from the Health frames after its final Diagnostics
        assert [h["neuron"] for h in r["health"]] == list(range(6))
        assert all(h["updates"] > 0 and h["rejected"] == 0 for h in r["health"])
        assert f"{'filter health':<{report.LABEL_WIDTH}}neuron 0  e^2/s " in report.table(r)
    ident = r["identification"]
    assert all(np.isfinite(ident[s]["rmse"]) for s in ("position", "velocity"))
    assert r["latency_us"]["n"] == f["answered"] and r["latency_us"]["min"] > 0
    assert r["rig_lateness_us"]["n"] == f["sent"]


@pytest.mark.parametrize("transport, fw", [("virtual", True), ("udp_multicast", "python"), ("udp_multicast", "runner")])
def test_a_full_replay_of_the_paper_scenario_is_bit_exact_and_accounted_on_every_host_transport(
        transport, fw, request) -> None:
    # the whole default scenario (4 s, 13,333 cycles: rest, the 1.1-2.1 s hold, the motor from 2.0 s), with losses
    sc = Scenario(frame_loss=0.005, seed=31)
    assert sc.cycles == 13333 and sc.hold_start == 1.1 and sc.input_start == 2.0
    runner = str(request.getfixturevalue("udp_runner_exe")) if fw == "runner" else None
    plan = sc.build()
    rec = run_replay(sc, transport, firmware=fw, runner=runner, reply_timeout=30.0)
    r = score(rec, reference=lim_config())
    assert int(plan.lost.sum()) > 20
    _assert_accounted(r, rec, plan)
    if transport == "virtual":
        assert r["frames"]["answered"] == r["frames"]["sent"] - r["frames"]["rejected_seq_jump"]


def _udp_firmware_node(port: int, receive_buffer: int | None):
    """The Python firmware node as its own process on ``port`` (the test stops and resumes it)."""
    import os
    import subprocess
    import sys
    import tempfile

    argv = [sys.executable, "-m", "hil.firmware_node", "--channel", "239.74.163.2", "--port", str(port)]
    if receive_buffer is not None:
        argv += ["--receive-buffer", str(receive_buffer)]
    # the hil and pyrhonn this interpreter imports (installed: the source tree has no compiled core), run
    # from a folder that cannot shadow them
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=dict(os.environ),
                            cwd=tempfile.gettempdir())
    assert proc.stdout is not None and proc.stdout.readline().strip() == "ready", proc.stderr.read()
    return proc


@pytest.mark.parametrize("way", ["to the firmware", "from the firmware"])
def test_frames_a_full_receive_queue_drops_are_counted_and_every_answered_estimate_is_still_exact(
        way, monkeypatch) -> None:
    import signal
    import socket
    import time

    from hil import transport

    # the firmware stops reading for 100 cycles (a descheduled process). "to the firmware": its receive
    # queue holds a few frames, the kernel drops the rest. "from the firmware": its queue is deep, but the
    # rig's is shallow and the rig stops reading while the firmware answers its backlog in one burst
    sc = Scenario(duration=0.3, start=0.9, input_start=1.0, frame_loss=0.01, seed=5)
    port = transport.free_port()
    node = _udp_firmware_node(port, 16384 if way == "to the firmware" else None)
    if way == "from the firmware":
        monkeypatch.setattr(transport, "_deep_receive_buffer",
                            lambda sock: sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096))

    def stall(k: int) -> list:
        if k == 300:
            node.send_signal(signal.SIGSTOP)
        elif k == 400:
            node.send_signal(signal.SIGCONT)
            if way == "from the firmware":
                time.sleep(0.5)
        return []

    try:
        rec = run_replay(sc, "udp_multicast", port=port, firmware=False, extra_frames=stall, reply_timeout=30.0)
    finally:
        node.send_signal(signal.SIGCONT)
        node.terminate()
        node.communicate(timeout=60)
    plan = sc.build()
    r = score(rec, reference=lim_config())
    f = r["frames"]
    _assert_accounted(r, rec, plan)   # sent = answered + refused + counted lost; every answered one exact
    if way == "to the firmware":
        assert f["lost_to_firmware"] >= 50 and 1 <= f["rejected_after_loss"] <= f["lost_to_firmware"]
    else:
        assert f["lost_from_firmware"] >= 50
    assert "full receive queues: lost to the firmware" in report.table(r)


def test_a_recorded_log_re_scores_to_the_same_numbers(tmp_path) -> None:
    rec = run_replay(SCENARIO.replace(duration=0.15, seed=3), "virtual")
    live = score(rec)
    for name in ("run.blf", "run.asc"):
        path = write_log(rec, tmp_path / name)
        again = score(read_log(path))
        if name.endswith(".asc"):  # microseconds: a latency within 1 us of the period may land either side
            near = int(np.sum(np.abs(live["_series"]["latency_ns"] - 300_000) <= 1_000))
            assert abs(again["frames"].pop("late") - live["frames"]["late"]) <= near, name
            again["frames"]["late"] = live["frames"]["late"]
        assert again["frames"] == live["frames"] and again["firmware"] == live["firmware"], name
        assert again["identification"] == live["identification"], name
        tol = 1e-6 if name.endswith(".blf") else 1.5  # BLF keeps nanoseconds, ASC microseconds
        for key in ("latency_us", "rig_lateness_us", "rig_period_jitter_us"):
            for stat, v in live[key].items():
                assert again[key][stat] == pytest.approx(v, abs=tol), (name, key, stat)


def test_a_replay_from_a_recorded_run_compares_every_estimate_with_it(tmp_path, capsys, cli_error) -> None:
    log = tmp_path / "reference.blf"
    assert pyrhonn_main(["hil", "replay", "--transport", "virtual", "--duration", "0.15", "--start", "1.98",
                         "--frame-loss", "0.02", "--seed", "6", "--log", str(log)]) == 0
    capsys.readouterr()
    assert pyrhonn_main(["hil", "replay", "--transport", "virtual", "--from-log", str(log), "--json"]) == 0
    r = json.loads(capsys.readouterr().out)
    assert r["scenario"] == read_log(log).scenario.to_dict()         # the recorded run's own scenario
    reg = r["regression"]
    assert reg["equal"] and reg["differ"] == 0 and reg["compared"] == r["frames"]["answered"] > 400
    assert set(reg["max_abs_diff"].values()) == {0.0} and reg["first_difference"] is None

    # one estimate of the recorded run altered: the replay names its cycle and exits 1
    rec = read_log(log)
    est_id = firmware.database().get_message_by_name("Estimate")
    estimates = [m for _, d, m in rec.events if d == "rx" and m.arbitration_id == est_id.frame_id]
    victim = estimates[100]
    fields_ = est_id.decode(bytes(victim.data), decode_choices=False)
    cycle = int(fields_["Seq"])
    fields_["QmHat"] += 0.001
    victim.data = bytearray(est_id.encode(fields_))
    altered = write_log(rec, tmp_path / "altered.blf")
    assert pyrhonn_main(["hil", "replay", "--transport", "virtual", "--from-log", str(altered)]) == 1
    text = capsys.readouterr().out
    assert f"1 DIFFER (first at cycle {cycle}; largest |difference| 0.001 in Qm)" in text

    assert "--duration, --seed" in cli_error(["hil", "replay", "--from-log", str(log), "--duration", "1",
                                              "--seed", "2"])
    assert "no such file" in cli_error(["hil", "replay", "--from-log", str(tmp_path / "none.blf")])
    assert "would overwrite" in cli_error(["hil", "replay", "--from-log", str(log), "--log", str(log)])


# -- faults -----------------------------------------------------------------------------------------


@pytest.mark.parametrize("transport", ["virtual", "udp_multicast"])
def test_firmware_not_running_is_a_clear_timeout(transport) -> None:
    with pytest.raises(FirmwareTimeout, match="no answer from the firmware .* within 0.3 s .*is the firmware running"):
        run_replay(SCENARIO.replace(duration=0.03), transport, firmware=False, reply_timeout=0.3)


def test_a_rig_behind_its_schedule_still_takes_the_frames_already_waiting() -> None:
    # on a slow host the loop may never get ahead of its deadlines: it must read what has arrived anyway,
    # or it would count no answer and call a running firmware silent
    with can.Bus(interface="virtual", channel="behind", receive_own_messages=False) as bus, \
            can.Bus(interface="virtual", channel="behind") as firmware_side:
        rig = Rig(bus, SCENARIO.build(), transport="virtual", channel="behind", spin_ns=0)
        for _ in range(3):
            firmware_side.send(can.Message(arbitration_id=EST.frame_id, is_extended_id=False, is_fd=True,
                                  data=bytes(EST.length)))
        rig._wait_until(0)  # a deadline long past: no waiting, but the waiting frames are taken
        assert rig._n_rx == 3 and rig._n_est == 3


def test_a_bus_that_disappears_mid_run_is_a_clear_error_and_the_frames_so_far_are_kept(tmp_path) -> None:
    sc = SCENARIO.replace(duration=0.06, frame_loss=0.0)
    with open_transport("virtual") as (bus, where, _side):
        # the bus is closed right after measurement frame 40 (what an interface going down does to a socket)
        rig = Rig(bus, sc.build(), transport="virtual", channel=where, spin_ns=0, reply_timeout=2.0, drain=0.1,
                  extra_frames=lambda k: (bus.shutdown() or []) if k == 40 else [])
        with pytest.raises(BusLost, match=r"the bus \(virtual .*\) went away while (sending|receiving) after "
                                          r"\d+ frames sent") as info:
            rig.run()
    rec = info.value.recording
    sent = [m for _, d, m in rec.events if d == "tx" and m.arbitration_id == MEAS.frame_id]
    assert len(sent) == 41 and "bus_lost" in rec.meta
    log = write_log(rec, tmp_path / "lost.blf")
    with pytest.raises(ValueError, match=r"a partial log \(the bus went away"):  # not a whole run: refused ...
        read_log(log)
    assert len(read_log(log, partial=True).events) == len(rec.events)  # ... but nothing before the loss is lost


def test_a_burst_of_malformed_frames_is_counted_and_nothing_crashes() -> None:
    rng = np.random.default_rng(7)
    own = {EST.frame_id, 0x111, 0x130}
    burst = []
    for _ in range(60):
        if rng.random() < 0.5:  # the Measurement id with a wrong length
            n = int(rng.choice([0, 1, 8, 12, 16, 24, 32, 48, 64]))
            burst.append(can.Message(arbitration_id=MEAS.frame_id, is_extended_id=False, is_fd=True,
                                     data=rng.integers(0, 256, n, dtype=np.uint8).tobytes()))
        else:  # an id nobody uses, random payload
            cid = int(rng.choice([i for i in range(0x000, 0x7FF, 7) if i not in own and i != MEAS.frame_id]))
            burst.append(can.Message(arbitration_id=cid, is_extended_id=False, is_fd=True,
                                     data=rng.integers(0, 256, 20, dtype=np.uint8).tobytes()))
    sc = SCENARIO.replace(duration=0.15, frame_loss=0.0)
    rec = run_replay(sc, "virtual", extra_frames=lambda k: burst if k == 100 else [])
    r = score(rec, reference=lim_config())
    f = r["frames"]
    assert sum(f["foreign_sent"].values()) == 60 and r["firmware"]["rejected"] == 60
    assert f["answered"] == sc.cycles and f["missing"] == 0 and f["accounted"] and r["bit_exact"]["equal"]


def test_a_sequence_counter_jump_costs_one_frame_and_is_accounted() -> None:
    sc = SCENARIO.replace(duration=0.15, frame_loss=0.0)
    plan = sc.build()

    def jump(k: int):
        if k != 200:
            return []
        return [firmware.measurement_message(k + 1000, plan.X[k], plan.U[k], plan.valid[k])]

    r = score(run_replay(sc, "virtual", extra_frames=jump), reference=lim_config())
    f = r["frames"]
    assert f["foreign_sent"] == {"measurement, foreign Seq": 1}
    # the jumped frame is rejected and re-anchors; cycle 201 is then a jump too; 202 resynchronises
    assert f["rejected_seq_jump"] == 1 and f["answered"] == sc.cycles - 1 and f["missing"] == 0
    assert r["firmware"]["rejected"] == r["firmware"]["seq_errors"] == 2 and f["accounted"]
    assert r["bit_exact"]["equal"]


class _FullDisk(io.RawIOBase):
    """A file that takes ``limit`` bytes, then fails like a full disk."""

    def __init__(self, path, limit: int) -> None:
        self._f = open(path, "wb")
        self._left = limit

    def writable(self) -> bool:
        return True

    def write(self, b) -> int:
        if self._left <= 0:
            raise OSError(errno.ENOSPC, "No space left on device")
        b = bytes(b)[:self._left]
        self._left -= len(b)
        return self._f.write(b)

    def seek(self, *a):
        return self._f.seek(*a)

    def tell(self):
        return self._f.tell()

    def flush(self):
        self._f.flush()

    def close(self):
        if not self._f.closed:
            self._f.close()
        super().close()


def test_a_full_log_disk_is_a_clear_error_and_leaves_the_previous_log_whole(tmp_path, monkeypatch) -> None:
    rec = run_replay(SCENARIO.replace(duration=0.6, frame_loss=0.0), "virtual")
    path = tmp_path / "run.blf"
    write_log(run_replay(SCENARIO.replace(duration=0.03, frame_loss=0.0), "virtual"), path)
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}

    class FullDiskBLF(can.BLFWriter):  # the disk fills up 20,000 bytes into the new log
        def __init__(self, file, **kwargs) -> None:
            super().__init__(_FullDisk(file, 20_000), **kwargs)

    monkeypatch.setattr(can, "BLFWriter", FullDiskBLF)
    with pytest.raises(LogWriteError, match=r"disk full after \d+ of \d+ frames; nothing of it is kept") as info:
        write_log(rec, path)
    assert info.value.errno == errno.ENOSPC
    # the previous log and its sidecar as they were, still a valid pair; no temporary file left behind
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before
    monkeypatch.undo()
    assert len(read_log(path).events) == json.loads((tmp_path / "run.blf.json").read_text())["frames"]


# -- the command line -----------------------------------------------------------------------------


@pytest.mark.parametrize("argv", [
    ["hil"], ["hil", "replay", "--transport", "bogus"], ["hil", "replay", "--duration", "-1"],
    ["hil", "replay", "--duration", "x"], ["hil", "replay", "--frame-loss", "2"],
    ["hil", "replay", "--log", "run.txt"], ["hil", "score", "/nonexistent/run.blf"],
    ["hil", "bench", "--cycles", "0"], ["hil", "bench"], ["hil", "replay", "--seed", "-3"],
    ["hil", "bench", "--cycles", "10", "--fifo", "0"], ["hil", "bench", "--cycles", "10", "--fifo", "x"],
    ["hil", "replay", "--input-start", "-1"],
])
def test_bad_cli_input_exits_2(argv, cli_error) -> None:
    cli_error(argv)


def test_cli_replay_writes_report_figures_and_a_log_that_scores_again(tmp_path, capsys) -> None:
    log, out = tmp_path / "run.blf", tmp_path / "report"
    argv = ["hil", "replay", "--transport", "virtual", "--duration", "0.3", "--start", "0.9", "--frame-loss",
            "0.01", "--seed", "4", "--out", str(out), "--log", str(log)]
    assert pyrhonn_main(argv) == 0
    text = capsys.readouterr().out
    assert "all accounted for" in text and "Identifier.run: equal" in text and "Table 7" in text
    for name in ("report.json", "report.txt", "position.png", "velocity.png", "latency.png"):
        assert (out / name).stat().st_size > 0, name
    live = json.loads((out / "report.json").read_text())
    assert pyrhonn_main(["hil", "score", str(log), "--json"]) == 0
    again = json.loads(capsys.readouterr().out)
    assert again["frames"] == live["frames"] and again["identification"] == live["identification"]


def test_bench_reports_the_scheduling_policy_it_ran_under() -> None:
    import subprocess
    import sys

    # in a child process: SCHED_FIFO must not leak into the test session
    out = subprocess.run([sys.executable, "-m", "pyrhonn.cli", "hil", "bench", "--transport", "virtual",
                          "--cycles", "300", "--fifo", "10"], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    first = out.stdout.splitlines()[0]
    assert "SCHED_FIFO 10" in first or "SCHED_FIFO 10 refused" in first
    assert "estimates within one period" in out.stdout
