"""hil.rig's arrival stamps: on socketcan and udp_multicast an estimate is
stamped when the kernel received it, the rig process's pick-up delay kept
apart; a missing or implausible kernel stamp falls back to the pick-up time."""
from __future__ import annotations

import os
import time

import numpy as np
import pytest

can = pytest.importorskip("can")
pytest.importorskip("cantools")

from hil.rig import Rig, ids  # noqa: E402
from hil.scenario import Scenario  # noqa: E402
from hil.score import score  # noqa: E402
from hil.transport import run_replay  # noqa: E402

PLAN = Scenario(duration=0.03).build()


def _estimate(timestamp: float) -> can.Message:
    return can.Message(arbitration_id=ids()["Estimate"], data=bytes(20), is_extended_id=False, is_fd=True,
                       timestamp=timestamp)


@pytest.mark.parametrize("transport", ["udp_multicast", "socketcan"])
def test_a_kernel_stamp_dates_the_arrival_back_to_when_the_socket_got_it(transport) -> None:
    rig = Rig(None, PLAN, transport=transport)
    before = time.perf_counter_ns()
    stamp = time.time() - 0.002                 # the kernel stamped it 2 ms before this line ran
    after = time.perf_counter_ns()
    now = time.perf_counter_ns()
    rig._take(_estimate(stamp), now)
    arrived, direction, _ = rig._events[-1]
    # on the rig's clock: 2 ms before that line (up to 1 ms for pairing the two clocks), however long ago
    assert direction == "rx" and before - 3_000_000 <= arrived <= after - 1_000_000
    (pickup,) = rig._pickup
    assert now - arrived <= pickup <= time.perf_counter_ns() - arrived  # read when the frame was taken


@pytest.mark.parametrize("offset", [None, 5.0, -5.0], ids=["no stamp", "5 s ahead", "5 s behind"])
def test_no_or_an_implausible_kernel_stamp_keeps_the_pick_up_time(offset: float | None) -> None:
    stamp = 0.0 if offset is None else time.time() + offset
    rig = Rig(None, PLAN, transport="udp_multicast")
    now = time.perf_counter_ns()
    rig._take(_estimate(stamp), now)
    assert rig._events[-1][0] == now and rig._pickup == []


def test_the_virtual_bus_is_stamped_when_recv_returns() -> None:
    rig = Rig(None, PLAN, transport="virtual")
    now = time.perf_counter_ns()
    rig._take(_estimate(time.time() - 0.002), now)
    assert rig._events[-1][0] == now and rig._pickup == []


def test_a_udp_replay_reports_socket_arrival_and_pick_up_apart_and_every_estimate_after_its_measurement() -> None:
    from pyrhonn.firmware import decode_estimate

    sc = Scenario(duration=0.15, start=1.95, seed=9)
    rec = run_replay(sc, "udp_multicast", reply_timeout=30.0)
    sent: dict[int, float] = {}
    for t, d, m in rec.events[rec.meta["first_run_event"]:]:
        if d == "tx" and m.arbitration_id == ids()["Measurement"]:
            sent[int.from_bytes(bytes(m.data[:2]), "little")] = t
        elif d == "rx" and m.arbitration_id == ids()["Estimate"]:
            seq = decode_estimate(m, scaling=False).seq
            assert seq in sent and t > sent[seq]          # listed after, and stamped after, its measurement
    r = score(rec)
    lat = r["latency_us"]
    assert lat["stamp"] == "kernel" and r["rig_pickup_us"]["n"] >= r["frames"]["answered"]
    assert lat["within_period"] >= lat["within_period_picked_up"]
    assert r["frames"]["accounted"] and np.isfinite(lat["p99.9"])


def test_a_pinned_firmware_process_runs_on_its_cpu_only() -> None:
    import subprocess

    from hil.transport import _pin

    proc = subprocess.Popen(["sleep", "5"])
    try:
        _pin(proc, 0)
        assert os.sched_getaffinity(proc.pid) == {0}
    finally:
        proc.kill()
        proc.wait()


@pytest.mark.skipif((os.cpu_count() or 1) < 2, reason="needs two CPUs")
def test_bench_cpus_pins_both_sides_and_gives_the_rig_its_cpus_back(capsys, cli_error) -> None:
    from pyrhonn.cli import main as pyrhonn_main

    before = os.sched_getaffinity(0)
    assert pyrhonn_main(["hil", "bench", "--transport", "udp_multicast", "--cycles", "300", "--cpus", "0,1"]) == 0
    assert "rig on CPU 0, firmware on CPU 1" in capsys.readouterr().out
    assert os.sched_getaffinity(0) == before
    for argv in (["--cpus", "0"], ["--cpus", "a,b"], ["--cpus", f"0,{os.cpu_count()}"],
                 ["--transport", "virtual", "--cpus", "0,1"]):
        assert "--cpus" in cli_error(["hil", "bench", "--cycles", "10", *argv]), argv
    for transport in ("virtual", "socketcan"):  # a thread of this process; a runner not started here
        with pytest.raises(ValueError, match="firmware_cpu"):
            run_replay(Scenario(duration=0.03), transport, firmware_cpu=0)


def test_the_udp_bench_compares_the_runner_asleep_and_busy_polling_with_the_python_node_in_rounds() -> None:
    import subprocess
    import sys
    from pathlib import Path

    script = Path(__file__).resolve().parents[1] / "bench" / "bench_hil_udp.py"
    out = subprocess.run([sys.executable, str(script), "--cycles", "400", "--rounds", "2"], capture_output=True,
                         text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    assert "400 cycles per variant" in lines[0] and "2 alternating rounds" in lines[0]
    for row in ("python node (hil.firmware_node)", "runner (rhonn_runner)", "runner busy-poll (rhonn_runner)"):
        assert any(ln.startswith(row) for ln in lines), row
    assert any(ln.startswith("runner / python node: late share x") for ln in lines)
    assert any(ln.startswith("runner busy-poll / python node: late share x") for ln in lines)
    assert lines[-1].startswith("(target: 99.9 % within one period; best here: ")
    bad = subprocess.run([sys.executable, str(script), "--cycles", "3", "--rounds", "2"], capture_output=True,
                         text=True, timeout=60)
    assert bad.returncode == 2 and "--rounds" in bad.stderr


class _Clock:
    """hil.rig's clock, advanced only by the fake bus below: the drain's waits
    are counted, not timed, so a busy host cannot change them."""

    def __init__(self) -> None:
        self.ns = 10**12

    def perf_counter_ns(self) -> int:
        return self.ns


class _QueuedBus:
    """A bus whose rig is slow: each frame still queued takes ``per_frame`` s
    (of ``clock``) to read; an empty queue waits out the timeout."""

    def __init__(self, clock: _Clock, queued: int, per_frame: float) -> None:
        self.clock, self.queued, self.per_frame = clock, queued, per_frame

    def recv(self, timeout: float | None = None) -> can.Message | None:
        if self.queued == 0:
            self.clock.ns += int((timeout or 0.0) * 1e9)
            return None
        self.queued -= 1
        self.clock.ns += int(self.per_frame * 1e9)
        return _estimate(0.0)


@pytest.fixture
def clock(monkeypatch) -> _Clock:
    import hil.rig

    c = _Clock()
    monkeypatch.setattr(hil.rig, "time", c)
    return c


def test_the_drain_reads_a_slow_queue_to_its_end_not_for_a_fixed_time(clock) -> None:
    # 12 frames at 20 ms each: 0.24 s of reading, far beyond the 50 ms of quiet the drain waits for
    rig = Rig(_QueuedBus(clock, 12, 0.02), PLAN, transport="virtual", drain=0.05)
    took, capped = rig._drain_estimates()
    assert rig._n_rx == 12 and not capped and took == pytest.approx(0.24 + 0.05)


def test_a_bus_that_never_goes_quiet_is_drained_for_at_most_the_cap(clock) -> None:
    from hil.rig import DRAIN_CAP

    rig = Rig(_QueuedBus(clock, 10**9, 0.001), PLAN, transport="virtual", drain=0.01)
    took, capped = rig._drain_estimates()
    assert capped and took == pytest.approx(DRAIN_CAP * 0.01) and rig._n_rx == pytest.approx(DRAIN_CAP * 10, abs=1)


def _frame(name: str, **values: int) -> can.Message:
    from pyrhonn.firmware import database

    m = database().get_message_by_name(name)
    data = m.encode({sig.name: values.get(sig.name, 0) for sig in m.signals})
    return can.Message(arbitration_id=m.frame_id, data=data, is_fd=True, is_extended_id=False)


class _BehindBus(_QueuedBus):
    """A firmware ``queued`` estimates behind on a busy host: it answers a
    DiagRequest (its ControlAck, then Diagnostics) once it has sent them."""

    def __init__(self, clock: _Clock, queued: int, per_frame: float) -> None:
        super().__init__(clock, queued, per_frame)
        self.answers: list[can.Message] = []

    def send(self, msg: can.Message) -> None:
        if msg.arbitration_id == ids()["Control"] and not self.answers:
            self.answers = [_frame("ControlAck", Token=msg.data[1], Command=7), _frame("Diagnostics")]

    def recv(self, timeout: float | None = None) -> can.Message | None:
        if self.queued == 0 and self.answers:
            return self.answers.pop(0)
        return super().recv(timeout)


def test_the_final_diagnostics_wait_for_a_firmware_still_answering_its_backlog(clock) -> None:
    from pyrhonn.firmware import TEST_KEY, SecOCSender, control_message

    assert control_message("DiagRequest", 0x5A, sender=SecOCSender(TEST_KEY)).data[1] == 0x5A  # the Token _BehindBus echoes
    # 30 estimates still to come, 0.5 s apart: 15 s in all, far beyond 2 s of silence
    rig = Rig(_BehindBus(clock, 30, 0.5), PLAN, transport="virtual")
    assert rig._control("DiagRequest", 0x5A, 2.0, progress=True)
    assert rig._n_rx == 32                                        # every estimate, the ack, the Diagnostics
    # a firmware that has gone quiet is still given up after the timeout
    quiet = _BehindBus(clock, 0, 0.5)
    quiet.send = lambda msg: None                                # never answers
    t0 = clock.ns
    assert not Rig(quiet, PLAN, transport="virtual")._control("DiagRequest", 0x5A, 2.0, progress=True)
    assert clock.ns - t0 == pytest.approx(2e9, abs=3e7)
    # without progress the same backlog is given up while its estimates still come
    assert not Rig(_BehindBus(clock, 30, 0.5), PLAN, transport="virtual")._control("DiagRequest", 0x5A, 2.0)


@pytest.mark.parametrize("kwargs, match", [({"drain": -1.0}, "drain: must be >= 0"),
                                           ({"drain": float("inf")}, "drain: must be finite"),
                                           ({"reply_timeout": 0.0}, "reply_timeout: must be > 0"),
                                           ({"reply_timeout": 1e6}, "reply_timeout: must be <= 3600"),
                                           ({"drain": 10**400}, "drain: out of the float64 range")])
def test_the_rig_refuses_waits_that_are_not_seconds_it_can_wait(kwargs, match) -> None:
    with pytest.raises(ValueError, match=match):
        Rig(None, PLAN, transport="virtual", **kwargs)
