"""Gaps in the Measurement stream and the filter's health on the bus, in the
firmware application (firmware_sim/app, compiled into pyrhonn._fwapp).

- After a gap of N frames the firmware never learns the next sample against
  the prediction made before the gap: the first frame accepted after it
  moves no weight, and the identifier is, bit for bit, one run on the same
  samples and restarted by hand (Identifier.restart) at the break. The
  Estimate says Resync; lost_frames counts N, across the Seq wrap too.
- A repeat or a backward jump is rejected and loses nothing; a forward gap
  beyond half the counter's range cannot be told from a backward jump.
- Diagnostics carries LostFrames and RxDrops; every Diagnostics frame is
  followed by one Health frame per neuron carrying rhonn_get_health, and a
  value that does not fit is flagged saturated, never sent as a value.
"""
from __future__ import annotations

import dataclasses
import functools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

can = pytest.importorskip("can")
pytest.importorskip("cantools")

from pyrhonn import Identifier, IdentifierConfig  # noqa: E402
from pyrhonn import firmware  # noqa: E402
from pyrhonn.configfile import load_shipped  # noqa: E402
from pyrhonn.firmware import FirmwareApp  # noqa: E402
from pyrhonn.plants import lim  # noqa: E402

DB = firmware.database()
MEAS = DB.get_message_by_name("Measurement")
DIAG_ID = DB.get_message_by_name("Diagnostics").frame_id
HEALTH = DB.get_message_by_name("Health")
HEALTH_ID = HEALTH.frame_id
CONFIG: IdentifierConfig = load_shipped("firmware-lim").config.replace(dtype="float32")


@functools.cache
def _samples() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The LIM example at 0.3 ms from just before its inputs switch on, all
    states valid: (X, U, valid), 700 samples."""
    traj = lim.simulate(dt=3e-4, horizon=2.4)
    k0 = int(round(2.0 / traj.dt))
    X, U = traj.X[k0:k0 + 700].copy(), traj.U[k0:k0 + 700].copy()
    return X, U, np.ones(X.shape, dtype=bool)


def _frame(seq: int, t: int) -> can.Message:
    X, U, valid = _samples()
    return firmware.measurement_message(seq & 0xFFFF, X[t], U[t], valid[t])


def _decoded(msg: can.Message) -> tuple[np.ndarray, np.ndarray]:
    d = MEAS.decode(bytes(msg.data), decode_choices=False)
    return (np.array([d[s] for s in firmware.STATE_SIGNALS], dtype=np.float32),
            np.array([d[s] for s in firmware.INPUT_SIGNALS], dtype=np.float32))


def _bits(a: np.ndarray) -> bytes:
    return np.ascontiguousarray(a, dtype=np.float32).tobytes()


def _weights(obj) -> list[bytes]:
    return [_bits(obj.get_weights(i)) for i in range(6)]


def _run_with_gap(seq0: int, before: int, lost: int, after: int):
    """Send `before` frames from seq0, lose `lost`, send the revealing frame
    and `after` more. Returns (app, reference identifier, estimates of the
    frames after the gap, weights before the gap)."""
    app = FirmwareApp(None, CONFIG)
    ref = Identifier(CONFIG)
    for t in range(before):
        msg = _frame(seq0 + t, t)
        (est,) = app.handle(msg)
        assert app.last_status == "FW_OK" and not firmware.decode_estimate(est).resync or t == 0
        ref.step(*_decoded(msg))
    w_before = _weights(app)
    assert w_before == _weights(ref)
    t0 = before + lost
    # the frame that reveals the gap: rejected, nothing touched
    snapshot = app.identifier_bytes()
    assert app.handle(_frame(seq0 + t0, t0)) == [] and app.last_status == "FW_E_SEQ_JUMP"
    assert app.identifier_bytes() == snapshot
    ests = []
    ref.restart()  # by hand, at the break
    for k in range(1, after + 1):
        msg = _frame(seq0 + t0 + k, t0 + k)
        (est,) = app.handle(msg)
        assert app.last_status == "FW_OK"
        ests.append(firmware.decode_estimate(est, scaling=False))
        ref.step(*_decoded(msg))
        if k == 1:
            assert _weights(app) == w_before, "a weight moved on the first frame after the gap"
    return app, ref, ests, w_before


@settings(max_examples=25, deadline=None)
@given(lost=st.integers(1, 300), seq0=st.integers(0, 65535))
def test_after_a_gap_of_n_frames_no_weight_moves_and_the_identifier_is_one_restarted_by_hand(lost, seq0) -> None:
    app, ref, ests, w_before = _run_with_gap(seq0, before=40, lost=lost, after=5)
    assert _weights(app) == _weights(ref), "not bit for bit an identifier restarted at the break"
    assert _bits(app.prediction) == _bits(ref.prediction)
    assert [e.resync for e in ests] == [True, False, False, False, False]
    assert [e.seq for e in ests] == [(seq0 + 40 + lost + k) & 0xFFFF for k in range(1, 6)]
    assert _weights(app) != w_before  # learning resumed on the second frame
    c = app.counters
    assert c["lost_frames"] == lost and c["seq_gaps"] == 1 and c["restarts"] == 1
    assert c["rejected_seq_jump"] == 1 and c["measurements"] == 45
    # every frame sent is accepted, lost, or rejected
    assert 40 + lost + 1 + 5 == c["measurements"] + c["lost_frames"] + c["rejected_seq_jump"]


@pytest.mark.parametrize("seq0, lost", [(65500, 30), (65490, 46), (65535 - 40, 1), (65000, 600)])
def test_a_gap_across_the_seq_wrap_counts_its_frames_and_restarts(seq0, lost) -> None:
    app, ref, ests, _ = _run_with_gap(seq0, before=40, lost=lost, after=3)
    assert (seq0 + 40) & 0xFFFF < (seq0 + 40 + lost) & 0xFFFF or (seq0 + 40 + lost) >> 16  # crosses or ends past 0
    assert app.counters["lost_frames"] == lost and ests[0].resync
    assert _weights(app) == _weights(ref)


def test_a_repeat_or_a_backward_jump_loses_nothing_and_restarts_the_identifier() -> None:
    app = FirmwareApp(None, CONFIG)
    ref = Identifier(CONFIG)
    for t in range(30):
        msg = _frame(1000 + t, t)
        app.handle(msg)
        ref.step(*_decoded(msg))
    assert app.handle(_frame(1029, 29)) == [] and app.last_status == "FW_E_SEQ_REPEAT"
    assert app.handle(_frame(10, 30)) == [] and app.last_status == "FW_E_SEQ_JUMP"  # a restarted sender
    w = _weights(app)
    (est,) = app.handle(_frame(11, 31))
    ref.restart()
    ref.step(*_decoded(_frame(11, 31)))
    assert firmware.decode_estimate(est).resync and _weights(app) == w == _weights(ref)
    c = app.counters
    assert c["lost_frames"] == 0 and c["seq_gaps"] == 0 and c["restarts"] == 1
    assert c["rejected_seq_repeat"] == 1 and c["rejected_seq_jump"] == 1


def test_a_gap_beyond_half_the_counter_reads_as_a_backward_jump() -> None:
    app = FirmwareApp(None, CONFIG)
    for t in range(5):
        app.handle(_frame(t, t))
    app.handle(_frame(4 + 32768, 5))  # d = 32768: 32767 frames lost, the largest gap counted
    assert app.counters["lost_frames"] == 32767
    app.handle(_frame(4 + 32768 + 1, 6))
    app.handle(_frame(4 + 32768 + 1 + 32769, 7))  # d = 32769: a backward jump of 32767
    c = app.counters
    assert c["lost_frames"] == 32767 and c["seq_gaps"] == 1 and c["rejected_seq_jump"] == 2


def test_the_first_frames_after_start_and_after_reset_need_no_restart() -> None:
    app = FirmwareApp(None, CONFIG)
    ref = Identifier(CONFIG)
    for t in range(10):
        msg = _frame(500 + t, t)
        app.handle(msg)
        ref.step(*_decoded(msg))
    assert app.counters["restarts"] == 0 and _weights(app) == _weights(ref)
    app.handle(firmware.control_message("Reset", 1, sender=firmware.SecOCSender(firmware.TEST_KEY)))
    app.handle(_frame(7, 10))
    assert app.counters["restarts"] == 0 and app.counters["lost_frames"] == 0


# -- Diagnostics and Health on the bus -------------------------------------------------------------


def _diag_and_health(frames: list[can.Message]) -> tuple[dict, list[firmware.Health]]:
    assert [f.arbitration_id for f in frames] == [DIAG_ID] + [HEALTH_ID] * 6
    return firmware.decode_diagnostics(frames[0]), [firmware.decode_health(f) for f in frames[1:]]


def test_diagnostics_carry_lost_frames_and_receive_queue_drops() -> None:
    app = FirmwareApp(None, CONFIG)
    for t in range(10):
        app.handle(_frame(t, t))
    app.handle(_frame(10 + 17, 27))
    app.note_rx_drops(17)
    app.note_rx_drops(2 ** 32 - 1)  # a 32-bit total wraps, as the kernel's count does
    d, _ = _diag_and_health(app.send_diagnostics())
    assert d["LostFrames"] == 17 and d["RxDrops"] == 16 and d["SeqErrors"] == 1
    assert app.counters["rx_drops"] == 16
    for bad in (-1, 2 ** 32, 1.5, True, "3"):
        with pytest.raises(ValueError, match="dropped"):
            app.note_rx_drops(bad)  # type: ignore[arg-type]
    assert app.counters["rx_drops"] == 16


def test_health_frames_follow_every_diagnostics_frame_with_the_cores_health() -> None:
    app = FirmwareApp(None, CONFIG, diag_period=20)
    ref = Identifier(CONFIG)
    sent = []
    for t in range(40):
        msg = _frame(t, t)
        sent += app.handle(msg)[1:]
        ref.step(*_decoded(msg))
    assert len(sent) == 2 * 7
    _, health = _diag_and_health(sent[7:])
    for i, h in enumerate(health):
        want = ref.health(i)
        assert h.neuron == i and h.updates == want.updates == 39 and h.rejected == want.rejected
        assert h.resets == want.resets and h.bounded == want.bounded and h.fail_run == want.fail_run
        assert h.gated == want.gated == 0     # no innovation gate in the LIM's config
        # float32 on the wire: the firmware's float32 values exactly
        assert (h.innovation, h.nis, h.trace_p) == (want.innovation, want.nis, want.trace_p)
        assert h.trace_p is not None and h.trace_p > 0 and h.nis is not None and h.nis >= 0


def _trace_p0(neuron) -> float:
    p0 = np.asarray(neuron.p0, dtype=np.float64)
    return float(np.trace(p0)) if p0.ndim == 2 else float(np.sum(np.broadcast_to(p0, (neuron.n_terms,))))


def _stepped(config: IdentifierConfig, frames: int) -> tuple[FirmwareApp, Identifier]:
    """The firmware twin and the offline Identifier of ``config``, both stepped on the first ``frames`` frames."""
    app = FirmwareApp(None, config)
    ref = Identifier(config)
    for t in range(frames):
        msg = _frame(t, t)
        app.handle(msg)
        ref.step(*_decoded(msg))
    return app, ref


def test_health_frames_carry_the_bounded_covariance_count_of_a_trace_ceiling() -> None:
    # a large Q piles up in P_i each step (forgetting stops at the ceiling, rhonn.h); the
    # ceiling scales P_i back: "bounded" counts it
    config = CONFIG.replace(neurons=tuple(dataclasses.replace(n, forgetting=0.9, p_trace_max=1.5 * _trace_p0(n),
                                                              q=_trace_p0(n) / n.n_terms)
                                          for n in CONFIG.neurons))
    app, ref = _stepped(config, 60)
    _, health = _diag_and_health(app.send_diagnostics())
    assert sum(h.bounded for h in health) > 0
    for i, h in enumerate(health):
        want = ref.health(i)
        assert (h.bounded, h.resets, h.updates, h.trace_p) == (want.bounded, want.resets, want.updates, want.trace_p)


def test_health_frames_carry_the_updates_the_innovation_gate_skipped() -> None:
    # the LIM's filter sees e^2/s of 1e-5..1e-2 on this stretch (its R is generous): a gate of 1e-5 skips most
    config = CONFIG.replace(neurons=tuple(dataclasses.replace(n, gate=1e-5) for n in CONFIG.neurons))
    app, ref = _stepped(config, 60)
    frames = app.send_diagnostics()
    _, health = _diag_and_health(frames)
    assert all(len(m.data) == HEALTH.length == 48 for m in frames[1:])
    assert all(h.gated is not None and h.gated > 0 for h in health)
    for i, h in enumerate(health):
        want = ref.health(i)
        assert (h.gated, h.updates, h.nis) == (want.gated, want.updates, want.nis)
        assert h.gated + h.updates == 59     # every step but the first learns or is gated


def test_a_health_frame_of_rhonn_id_2_1_decodes_without_the_gated_count_and_other_lengths_are_refused() -> None:
    app, _ = _stepped(CONFIG.replace(neurons=tuple(dataclasses.replace(n, gate=1e-5) for n in CONFIG.neurons)), 60)
    health = app.send_diagnostics()[5]    # neuron 4's
    now = firmware.decode_health(health)
    assert now.gated is not None and now.gated > 0
    old = firmware.decode_health(can.Message(arbitration_id=HEALTH.frame_id, data=bytes(health.data[:32]),
                                             is_extended_id=False, is_fd=True))
    assert old.gated is None and dataclasses.replace(old, gated=now.gated) == now
    with pytest.raises(ValueError, match="a Health frame is 48 bytes .32 before rhonn_id 2.2., got 24"):
        firmware.decode_health(can.Message(arbitration_id=HEALTH.frame_id, data=bytes(health.data[:24]),
                                           is_extended_id=False, is_fd=True))


def test_a_health_value_that_does_not_fit_is_flagged_saturated_never_sent_as_a_value() -> None:
    # P0 = 3e38 I: trace P_i = L 3e38 overflows float32 to inf
    config = CONFIG.replace(neurons=tuple(dataclasses.replace(n, p0=3e38) for n in CONFIG.neurons))
    app = FirmwareApp(None, config)
    (diag, *frames) = app.send_diagnostics()
    raw = [HEALTH.decode(bytes(f.data), decode_choices=False) for f in frames]
    assert all(r["TracePSat"] == 1 and r["TraceP"] == np.float32(3.4e38) for r in raw)
    assert all(r["InnovationSat"] == 0 and r["NisSat"] == 0 for r in raw)
    health = [firmware.decode_health(f) for f in frames]
    assert all(h.trace_p is None and h.innovation == 0.0 and h.nis == 0.0 for h in health)
    with pytest.raises(ValueError, match="not a Health frame"):
        firmware.decode_health(diag)
    with pytest.raises(ValueError, match="not a Diagnostics frame"):
        firmware.decode_diagnostics(frames[0])


def test_step_status_tables_name_not_pd() -> None:
    for msg in ("Estimate", "Diagnostics"):
        sig = DB.get_message_by_name(msg).get_signal_by_name("StepStatus")
        assert sig.choices[10] == "NOT_PD", msg
    assert int(firmware._lib.RHONN_E_NOT_PD) == 10
