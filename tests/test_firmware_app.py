"""The firmware application (firmware_sim/app, compiled into pyrhonn._fwapp)
driven from Python frame by frame.

- Bad frames are rejected and counted, and leave the identifier bit for bit
  unchanged (the whole rhonn_t compared), also for random frames.
- End to end over python-can's virtual bus: the rig sends the LIM example's
  measurements, the firmware answers with estimates, and they are, bit for
  bit, Identifier.run on the decoded measurements, scaled as the DBC says.
- Control frames (learning, weight transfer, diagnostics) on a live bus,
  with the application serving from a thread.
"""
from __future__ import annotations

import functools
import math
import threading
import time
import uuid
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

can = pytest.importorskip("can")
pytest.importorskip("cantools")

from pyrhonn import Identifier, IdentifierConfig, terms  # noqa: E402
from pyrhonn import firmware  # noqa: E402
from pyrhonn.configfile import load_shipped  # noqa: E402
from pyrhonn.firmware import FirmwareApp  # noqa: E402
from pyrhonn.plants import lim  # noqa: E402
from pyrhonn.plants.trajectory import Corruption  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
DB = firmware.database()
MEAS = DB.get_message_by_name("Measurement")
EST = DB.get_message_by_name("Estimate")


def _lim_config(dtype: str = "float32") -> IdentifierConfig:
    """The LIM identifier firmware_sim runs: the shipped config firmware-lim."""
    config = load_shipped("firmware-lim").config
    return config if config.dtype == dtype else config.replace(dtype=dtype)


CONFIG = _lim_config()


def _virtual_pair():
    channel = f"fw-{uuid.uuid4().hex}"
    rig = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
    fw = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
    return rig, fw


@functools.cache
def _simulation():
    return lim.simulate(dt=3e-4, horizon=2.55, corruption=Corruption(dropout=0.01, seed=5))


def _trajectory(samples: int = 1500, start: float = 1.98):
    """The LIM example at the real-time period (0.3 ms), by default from just
    before the inputs switch on (2 s) through the start of the position hold
    (2.1 s), with 1 % random dropouts: (X measured, U, valid)."""
    traj = _simulation()
    k0 = int(round(start / traj.dt))
    sl = slice(k0, k0 + samples)
    X, U, valid = traj.X_meas[sl].copy(), traj.U[sl].copy(), traj.valid[sl].copy()
    X[~np.isfinite(X)] = 0.0
    return X, U, valid


def _decoded(frames: list) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What the firmware sees: the frames decoded by cantools, in float32."""
    X, U, V = [], [], []
    for msg in frames:
        d = MEAS.decode(bytes(msg.data), decode_choices=False)
        X.append([d[s] for s in firmware.STATE_SIGNALS])
        U.append([d[s] for s in firmware.INPUT_SIGNALS])
        V.append([bool(d[s]) for s in firmware.VALID_SIGNALS])
    return np.array(X, dtype=np.float32), np.array(U, dtype=np.float32), np.array(V, dtype=bool)


def _expected_raw(xhat: np.ndarray) -> np.ndarray:
    """x̂ scaled as the DBC says: round(x / scale) (ties to even, as cantools),
    saturated to the signal's range."""
    out = np.empty(xhat.shape, dtype=np.int64)
    for j, name in enumerate(firmware.ESTIMATE_SIGNALS):
        s = EST.get_signal_by_name(name)
        lo, hi = int(s.scaled_to_raw(s.minimum)), int(s.scaled_to_raw(s.maximum))
        for t in range(xhat.shape[0]):
            out[t, j] = min(max(s.scaled_to_raw(float(xhat[t, j])), lo), hi)
    return out


def _measurements(X, U, valid, seq0: int = 0) -> list:
    return [firmware.measurement_message(seq0 + t, X[t], U[t], valid[t]) for t in range(X.shape[0])]


# -- configuration ------------------------------------------------------------------------------


def test_the_application_takes_a_float32_lim_shaped_config() -> None:
    with pytest.raises(ValueError, match="float32"):
        FirmwareApp(None, CONFIG.replace(dtype="float64"))
    small = IdentifierConfig.uniform(terms.first_order(4, 2), n_states=4, n_inputs=2, dtype="float32")
    with pytest.raises(ValueError, match="6 states and 2 inputs"):
        FirmwareApp(None, small)
    with pytest.raises(ValueError, match="config"):
        FirmwareApp(None, "lim")
    with pytest.raises(ValueError, match="diag_period"):
        FirmwareApp(None, CONFIG, diag_period=70000)
    with pytest.raises(ValueError, match="bus"):
        FirmwareApp(object(), CONFIG)
    app = FirmwareApp(None, Identifier(CONFIG))  # an Identifier: its weights become w0
    with pytest.raises(ValueError, match="no bus"):
        app.serve(1)
    np.testing.assert_array_equal(app.prediction, np.zeros(6, dtype=np.float32))


# -- rejection ------------------------------------------------------------------------------------


def _warm(app: FirmwareApp, n: int = 20) -> int:
    X, U, valid = _trajectory(n, start=2.0)
    for msg in _measurements(X, U, valid):
        assert len(app.handle(msg)) == 1 and app.last_status == "FW_OK"
    return n  # the next expected Seq


def _std(can_id: int, data: bytes = b"", **kw) -> can.Message:
    """A frame with an 11-bit identifier (python-can defaults to 29-bit)."""
    return can.Message(arbitration_id=can_id, is_extended_id=False, data=data, **kw)


def _raw_measurement(seq: int, **override) -> can.Message:
    raw = {"Seq": seq, **{f: 1 for f in firmware.VALID_SIGNALS},
           **{s: 1000 for s in firmware.STATE_SIGNALS + firmware.INPUT_SIGNALS}}
    raw.update(override)
    return _std(MEAS.frame_id, MEAS.encode(raw, scaling=False, strict=False), is_fd=True, bitrate_switch=True)


def _bad_frames(seq: int) -> list[tuple[str, can.Message, str]]:
    good = bytes(_raw_measurement(seq).data)
    mid = MEAS.frame_id
    tx = firmware.SecOCSender(firmware.TEST_KEY)  # authentic commands that are refused for what they say
    out = [
        ("unknown id", _std(0x123, good, is_fd=True), "FW_E_UNKNOWN_ID"),
        ("estimate id", _std(EST.frame_id, good, is_fd=True), "FW_E_UNKNOWN_ID"),
        ("29-bit id", can.Message(arbitration_id=mid, is_extended_id=True, data=good, is_fd=True), "FW_E_UNKNOWN_ID"),
        ("remote frame", can.Message(arbitration_id=mid, is_extended_id=False, is_remote_frame=True, dlc=8),
         "FW_E_UNKNOWN_ID"),
        ("error frame", _std(mid, good[:8], is_error_frame=True), "FW_E_UNKNOWN_ID"),
        ("classic 8 bytes", _std(mid, good[:8]), "FW_E_LENGTH"),
        ("19 bytes", _std(mid, good[:19], is_fd=True), "FW_E_LENGTH"),
        ("24 bytes", _std(mid, good + bytes(4), is_fd=True), "FW_E_LENGTH"),
        ("empty", _std(mid, b"", is_fd=True), "FW_E_LENGTH"),
        ("repeat", _raw_measurement(seq - 1), "FW_E_SEQ_REPEAT"),
        ("control 2 bytes", _std(0x110, b"\x01\x00", is_fd=True), "FW_E_LENGTH"),
        ("command 0", firmware.control_message(0, sender=tx), "FW_E_RANGE"),
        ("command 8", firmware.control_message(8, sender=tx), "FW_E_RANGE"),
        ("commit, nothing open", firmware.control_message("WeightsCommit", sender=tx), "FW_E_STATE"),
        ("abort, nothing open", firmware.control_message("WeightsAbort", sender=tx), "FW_E_STATE"),
        ("weights, nothing open", firmware.weight_load_messages([np.ones(2)], sender=tx)[0], "FW_E_STATE"),
    ]
    for name, sig in zip(firmware.STATE_SIGNALS + firmware.INPUT_SIGNALS,
                         [MEAS.get_signal_by_name(n) for n in firmware.STATE_SIGNALS + firmware.INPUT_SIGNALS]):
        lo, hi = int(sig.scaled_to_raw(sig.minimum)), int(sig.scaled_to_raw(sig.maximum))
        out.append((f"{name} = max + 1", _raw_measurement(seq, **{name: hi + 1}), "FW_E_RANGE"))
        out.append((f"{name} = min - 1", _raw_measurement(seq, **{name: lo - 1}), "FW_E_RANGE"))
        out.append((f"{name} negative end of field", _raw_measurement(seq, **{name: -(2 ** (sig.length - 1))}),
                    "FW_E_RANGE"))
    return out


def test_bad_frames_are_rejected_counted_and_leave_the_identifier_bit_for_bit_unchanged() -> None:
    app = FirmwareApp(None, CONFIG)
    seq = _warm(app)
    before = app.identifier_bytes()
    weights = [app.get_weights(i) for i in range(6)]
    cases = _bad_frames(seq)
    for k, (what, msg, status) in enumerate(cases):
        replies = app.handle(msg)
        assert app.last_status == status, what
        assert app.identifier_bytes() == before, what
        c = app.counters
        assert c["rejected"] == k + 1 and c["last_reject"] == int(getattr(firmware._lib, status)), what
        if status == "FW_E_STATE" and msg.arbitration_id == 0x110:  # a refused command is answered
            assert [DB.decode_message("ControlAck", bytes(r.data), decode_choices=False)["Result"]
                    for r in replies] == [int(firmware._lib.FW_E_STATE)]
        else:
            assert replies == [], what
    c = app.counters
    assert c["measurements"] == seq and c["rejected_range"] == 3 * 8 + 2 and c["rejected_unknown_id"] == 5
    assert all(np.array_equal(w, app.get_weights(i)) for i, w in enumerate(weights))
    # a jump is rejected too, and re-anchors the counter
    assert app.handle(_raw_measurement(seq + 3)) == [] and app.last_status == "FW_E_SEQ_JUMP"
    assert app.identifier_bytes() == before
    (est,) = app.handle(_raw_measurement(seq + 4))
    e = firmware.decode_estimate(est)
    assert app.last_status == "FW_OK" and e.seq == seq + 4 and e.resync and app.counters["measurements"] == seq + 1


_ids = st.sampled_from([0x100, 0x110, 0x120, 0x101, 0x000, 0x7FF, 0x100 | 0x80000000])
_frame = st.tuples(_ids, st.binary(min_size=0, max_size=64))


@settings(max_examples=60, deadline=None)
@given(frames=st.lists(st.one_of(_frame, st.tuples(st.just("next"), st.integers(-32767, 32767))), max_size=25))
def test_random_frames_never_change_the_identifier_unless_accepted(frames) -> None:
    app = FirmwareApp(None, CONFIG)
    seq = _warm(app, 3)
    for kind, payload in frames:
        before = app.identifier_bytes()
        counters = app.counters
        if kind == "next":  # a well-formed measurement with the next counter: accepted
            app.handle_frame(0x100, bytes(_raw_measurement(seq, Ia=payload, Ib=-payload).data))
            if app.last_status in ("FW_OK", "FW_E_STEP"):
                seq += 1
        else:
            app.handle_frame(kind, payload)
        status = app.last_status
        after = app.counters
        if status in ("FW_OK", "FW_E_STEP", "FW_E_HAL"):
            continue
        assert app.identifier_bytes() == before, status
        assert after["rejected"] == counters["rejected"] + 1
        if kind == 0x100 and status == "FW_E_SEQ_JUMP":
            seq = (int.from_bytes(payload[:2], "little") + 1) & 0xFFFF  # re-anchored


# -- end to end on a python-can bus ----------------------------------------------------------------


def test_virtual_bus_estimates_are_identifier_run_on_the_decoded_measurements_bit_for_bit() -> None:
    X, U, valid = _trajectory()
    T = X.shape[0]
    assert (~valid[:, 0]).sum() > 100 and not valid.all()  # the position hold and dropouts
    frames = _measurements(X, U, valid, seq0=65000)  # wraps through 0
    rig, bus = _virtual_pair()
    try:
        app = FirmwareApp(bus, CONFIG)
        for msg in frames:
            rig.send(msg)
        assert app.serve(n_frames=T, until=time.monotonic() + 60) == T
        replies = []
        while len(replies) < T:
            msg = rig.recv(timeout=5)
            assert msg is not None, f"only {len(replies)} estimates"
            replies.append(msg)
        assert rig.recv(timeout=0.05) is None
    finally:
        rig.shutdown()
        bus.shutdown()
    assert all(r.arbitration_id == EST.frame_id and r.is_fd and r.bitrate_switch for r in replies)
    est = [firmware.decode_estimate(r, scaling=False) for r in replies]
    assert [e.seq for e in est] == [(65000 + t) & 0xFFFF for t in range(T)]
    assert [e.resync for e in est] == [True] + [False] * (T - 1)
    assert all(e.step_status == 0 and e.learning for e in est)

    Xd, Ud, Vd = _decoded(frames)
    ident = Identifier(CONFIG)
    Xhat = ident.run(Xd, Ud, Vd)
    np.testing.assert_array_equal(np.array([e.xhat for e in est]), _expected_raw(Xhat))
    assert np.array_equal(app.prediction.view(np.uint32), Xhat[-1].view(np.uint32))
    for i in range(6):
        assert np.array_equal(app.get_weights(i).view(np.uint32), ident.get_weights(i).view(np.uint32))
    assert len({tuple(e.xhat) for e in est}) > T // 2  # a live trajectory, not a constant
    c = app.counters
    assert c["measurements"] == T and c["rejected"] == 0 and c["frames_out"] == T and c["step_errors"] == 0


def test_control_frames_on_a_live_bus_with_the_app_serving_from_a_thread() -> None:
    X, U, valid = _trajectory(160, start=2.02)
    frames = _measurements(X, U, valid)
    rig, bus = _virtual_pair()
    stop = threading.Event()
    app = FirmwareApp(bus, CONFIG, diag_period=0)
    tx = firmware.SecOCSender(firmware.TEST_KEY)
    server = threading.Thread(target=app.serve, kwargs={"until": stop.is_set, "timeout": 0.01}, daemon=True)
    server.start()
    trained = Identifier(CONFIG)
    trained.run(*_decoded(_measurements(*_trajectory(300, start=2.2))))
    new_w = [trained.get_weights(i) for i in range(6)]

    def call(msg, n_replies: int) -> list:
        rig.send(msg)
        out = []
        while len(out) < n_replies:
            r = rig.recv(timeout=5)
            assert r is not None, "the firmware did not answer"
            out.append(r)
        return out

    def ack(replies, command: str, token: int) -> dict:
        d = DB.decode_message("ControlAck", bytes(replies[0].data), decode_choices=False)
        assert d["Command"] == firmware.COMMANDS[command] and d["Token"] == token
        return d

    try:
        est = []
        for t in range(160):
            if t == 40:
                d = ack(call(firmware.control_message("LearningOff", 1, sender=tx), 1), "LearningOff", 1)
                assert d["Result"] == 0
            if t == 80:
                d = ack(call(firmware.control_message("LearningOn", 2, sender=tx), 1), "LearningOn", 2)
                assert d["Result"] == 0
                d = ack(call(firmware.control_message("WeightsBegin", 3, sender=tx), 1), "WeightsBegin", 3)
                assert d["Result"] == 0 and d["Missing"] == sum(nr.n_terms for nr in CONFIG.neurons)
                for m in firmware.weight_load_messages(new_w, sender=tx):
                    rig.send(m)  # no answer to a chunk
                d = ack(call(firmware.control_message("WeightsCommit", 4, sender=tx), 1), "WeightsCommit", 4)
                assert d["Result"] == 0 and d["Missing"] == 0
            if t == 120:
                replies = call(firmware.control_message("DiagRequest", 5, sender=tx), 2 + 6)  # and one Health per neuron
                assert ack(replies, "DiagRequest", 5)["Result"] == 0
                assert [firmware.decode_health(r).neuron for r in replies[2:]] == list(range(6))
                diag = DB.decode_message("Diagnostics", bytes(replies[1].data), decode_choices=False)
                assert diag["Measurements"] == 120 and diag["LastSeq"] == 119 and diag["Rejected"] == 0
                assert diag["Synced"] == 1 and diag["Learning"] == 1 and diag["Started"] == 1
                assert 0 < diag["StepTime"] < 655.35  # host clock: a real, sub-millisecond step
            (r,) = call(frames[t], 1)
            est.append(firmware.decode_estimate(r, scaling=False))
    finally:
        stop.set()
        server.join(timeout=5)
        rig.shutdown()
        bus.shutdown()
    assert not server.is_alive()
    assert [e.learning for e in est] == [True] * 40 + [False] * 40 + [True] * 80

    # the reference: the same steps, learning frozen for samples 40..79, weights replaced before 80
    Xd, Ud, Vd = _decoded(frames)
    ref = Identifier(CONFIG)
    parts = [ref.run(Xd[:40], Ud[:40], Vd[:40])]
    ref.learning = False
    parts.append(ref.run(Xd[40:80], Ud[40:80], Vd[40:80]))
    ref.learning = True
    for i, w in enumerate(new_w):
        ref.set_weights(i, w)
    parts.append(ref.run(Xd[80:], Ud[80:], Vd[80:]))
    np.testing.assert_array_equal(np.array([e.xhat for e in est]), _expected_raw(np.concatenate(parts)))
    assert np.array_equal(app.prediction.view(np.uint32), parts[-1][-1].view(np.uint32))


def test_diagnostics_on_a_simulated_clock() -> None:
    app = FirmwareApp(None, CONFIG, deadline_ns=4_000, diag_period=25, host_clock=False)
    app.tick_ns = 5_000  # every step takes 5 us: an overrun at a 4 us deadline
    X, U, valid = _trajectory(60, start=2.0)
    diags = []
    for t, msg in enumerate(_measurements(X, U, valid, seq0=7)):
        app.clock_ns = t * 300_000
        out = app.handle_frame(0x100, bytes(msg.data), now_ns=t * 300_000)
        assert out[0].arbitration_id == EST.frame_id
        diags += [DB.decode_message("Diagnostics", bytes(m.data), decode_choices=False) for m in out[1:]
                  if m.arbitration_id == DB.get_message_by_name("Diagnostics").frame_id]
        if t == 30:
            app.handle(firmware.control_message(99, sender=firmware.SecOCSender(firmware.TEST_KEY)))  # out of range
    assert [d["Counter"] for d in diags] == [0, 1]
    d = diags[1]
    assert d["Measurements"] == 50 and d["LastSeq"] == 56 and d["CycleTime"] == pytest.approx(300.0)
    assert d["StepTime"] == pytest.approx(5.0) and d["StepTimeMax"] == pytest.approx(5.0)
    assert d["Overruns"] == 50 and d["Rejected"] == 1 and d["LastReject"] == int(firmware._lib.FW_E_RANGE)
    app.note_overrun()
    extra, *health = app.send_diagnostics()
    assert [firmware.decode_health(h).neuron for h in health] == list(range(6))
    e = DB.decode_message("Diagnostics", bytes(extra.data), decode_choices=False)
    assert e["Counter"] == 2 and e["Overruns"] == 61 and e["StepTimeMax"] == pytest.approx(5.0)
    assert app.counters["step_time_worst_ns"] == 5_000 and math.isclose(app.counters["cycle_time_ns"], 300_000)
