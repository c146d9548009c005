"""The rig: replays a scenario's Measurement frames on an absolute 0.3 ms
schedule, receives the firmware's frames, and records everything.

Timing. Frame k is due at the absolute deadline t0 + k*T + delay on
``time.perf_counter_ns`` (never "sleep T after the previous one", so errors
do not accumulate). The rig waits by blocking in ``bus.recv`` (which also
collects the estimates as they arrive) until ``spin_ns`` before the deadline, then polls
``recv(timeout=0)`` until the deadline (a busy spin: the kernel's timer slack
makes blocking wake-ups tens of microseconds late). Single-threaded on
purpose: a second Python thread would wait for the GIL. The timed loop runs
with the garbage collector off (no collection pauses; what it allocates is
freed by reference counting).

Arrival times. On socketcan and udp_multicast python-can gives each received
frame the kernel's receive timestamp, so an estimate is stamped with the
moment it reached the rig's socket (on the perf_counter clock), not the
moment this process got round to ``recv``; that pick-up delay, the rig's own
scheduling, is kept apart (``meta["rx_pickup_us"]``). On the virtual bus the
stamp is when ``recv`` returned.

Recording. Every frame sent and received is kept in memory during the run
and written to the log after it, so the log writer's compression never
disturbs the schedule. The Recording holds the frames in time order (a
received frame by its arrival at the socket, which may precede a frame the
rig sent while that one waited to be picked up), each at its time relative
to the earliest frame, and ``meta["wall_time_ns"]``, the wall clock
(CLOCK_REALTIME) of that relative 0. :func:`write_log` writes BLF, ASC or MDF4
through python-can's writers with absolute times: the file's start (the BLF
header's start time, the ASC's ``Begin Triggerblock``) is the run's wall
clock truncated to the millisecond, and each frame's time is its offset
from it, to the nanosecond in BLF and the microsecond in ASC. MDF4 (a bus
logging file, ``CAN_DataFrame`` channels, as CANape and asammdf read it):
python-can's writer takes the time it opens the file as the header's start
and stores each frame's absolute time less that start, a float64 of the
wall clock's magnitude, so frames keep their offsets to about a microsecond;
plus a
``LOG.json`` sidecar with the scenario and the run's metadata.
:func:`read_log` reads a log back into the same :class:`Recording` (the
relative times, which is all :mod:`hil.score` needs; logs of the format
before, whose times start at 0 and whose frames are in pick-up order, are
read as they are).

Integrity. The log is written to a temporary file and renamed into place
(:mod:`pyrhonn.atomic`), then its sidecar, which records the log's frame
count and SHA-256: an interrupted write leaves the previous log or none,
and :func:`read_log` refuses a log that falls short of its sidecar (naming
the frames missing), that does not match its checksum, or that has no
sidecar. A run stopped by SIGINT or SIGTERM (:class:`Interrupted`, which
:meth:`Rig.run` raises with every frame up to then) or by a lost bus is
written as a whole, readable log marked ``partial`` in its sidecar, which
:func:`read_log` refuses unless asked for it (``hil score --partial``).
"""
from __future__ import annotations

import datetime
import errno
import gc
import hashlib
import json
import os
import signal
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import can
import numpy as np

from .diagnostics import LEGACY_PROTOCOL, SAME_DIAGNOSTICS
from .scenario import Plan, Scenario

__all__ = ["BusLost", "FirmwareTimeout", "Interrupted", "LogWriteError", "Recording", "Rig", "ids", "read_log",
           "write_log"]


DRAIN_CAP = 20  #: the drain after the replay reads for at most this many times ``drain``
MAX_WAIT_S = 3600.0  #: the longest ``reply_timeout`` or ``drain`` a Rig takes
SIDECAR_MAX_BYTES = 1 << 20  #: a log's JSON sidecar holds the scenario and a few counters: a few kB
#: 2: the sidecar records the log's frame count, SHA-256 and whether it is partial; 3: the log's frames are in
#: time order at absolute wall-clock times (``wall_time_ns``), and the sidecar names the protocol (the DBC's version)
LOG_FORMAT_VERSION = 3
LOG_FORMAT = f"pyrhonn-hil-log {LOG_FORMAT_VERSION}"


def check_seconds(name: str, value: object, *, zero: bool) -> float:
    """A wait in seconds: finite, > 0 (``zero``: >= 0) and <= MAX_WAIT_S; else
    a ValueError naming ``name``."""
    from pyrhonn.validation import check_real, fail

    v = check_real(name, value, positive=not zero, nonnegative=zero)
    if v > MAX_WAIT_S:
        raise fail(name, f"must be <= {MAX_WAIT_S:g} s, got {v!r}")
    return v


class FirmwareTimeout(TimeoutError):
    """The firmware did not answer (not running, wrong channel, bus down)."""


class LogWriteError(OSError):
    """Writing the log failed part way (nothing is left of it: the previous log, if any, is unchanged)."""


class Interrupted(KeyboardInterrupt):
    """SIGINT or SIGTERM stopped the run (``signum``; hil's command line turns
    SIGTERM into this exception). Raised by :meth:`Rig.run` with
    ``recording``: every frame sent and received up to that moment, marked
    partial, to be written as a log."""

    def __init__(self, signum: int = signal.SIGINT, recording: Recording | None = None) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = int(signum)
        self.recording = recording


class BusLost(OSError):
    """The bus went away mid-run (interface down, bus closed). ``recording``
    holds every frame sent and received up to that moment, so nothing that
    happened before is lost: it can be written as a log and scored."""

    def __init__(self, message: str, recording: Recording) -> None:
        super().__init__(message)
        self.recording = recording


HEALTH_FRAMES = 6  #: one Health frame per neuron of the LIM firmware follows each Diagnostics frame
BEHIND_READS = 8  #: a replay loop behind its schedule takes at most this many waiting frames per cycle
PROGRESS_EVERY = 256  #: the replay loop offers its progress every this many cycles (77 ms at 0.3 ms)
DROP_SAMPLES_EVERY = 2 * PROGRESS_EVERY  #: a replay reads the kernel's drop counters every this many cycles
DROP_SAMPLES_MAX = 500  #: ... or less often, to keep at most about this many samples in a run


def drop_sampling(cycles: int) -> int:
    """Every how many cycles a replay samples the kernel's drop counters (udp_multicast): every
    DROP_SAMPLES_EVERY (154 ms at 0.3 ms; a read of /proc/net/udp and udp6 takes about 130 us in Python,
    within the slack after a send), or a multiple of it so that a long run keeps at most about
    DROP_SAMPLES_MAX samples (the sidecar keeps them)."""
    return DROP_SAMPLES_EVERY * max(1, -(-cycles // (DROP_SAMPLES_EVERY * DROP_SAMPLES_MAX)))


def ids() -> dict[str, int]:
    from pyrhonn.firmware import database

    db = database()
    return {m.name: m.frame_id for m in db.messages}


def _paired_clocks() -> tuple[int, int]:
    """(perf_counter_ns, time_ns) read at one instant: the realtime clock is
    read either side of the perf_counter, and the tightest of three such
    brackets is kept, so that a preemption between two reads (tens of us on
    a busy host) does not shift the pair."""
    best = None
    for _ in range(3):
        r0 = time.time_ns()
        m = time.perf_counter_ns()
        r1 = time.time_ns()
        if best is None or r1 - r0 < best[0]:
            best = (r1 - r0, m, (r0 + r1) // 2)
        if r1 - r0 < 2_000:
            break
    assert best is not None  # the loop ran at least once
    return best[1], best[2]


@dataclass
class Recording:
    """A run as frames: ``events`` is the list of (t seconds, direction
    "tx"/"rx", can.Message) in time order (a received frame's t is its
    arrival at the socket where the bus stamps it, so it may precede a frame
    the rig sent before picking it up; frames sent keep the order they were
    sent in). ``meta`` holds the transport, the period, ``wall_time_ns`` (the
    wall clock of t = 0; absent in logs of the format before) and anything
    the rig measured besides frames. A log of the format before keeps its
    frames in the order the rig sent and picked them up: :mod:`hil.score`
    reads both."""

    scenario: Scenario
    events: list[tuple[float, str, can.Message]] = field(default_factory=list)
    meta: dict[str, Any] = field(default_factory=dict)


class Rig:
    """Replays ``plan`` on ``bus``. ``spin_ns``: busy-wait margin before each
    deadline (0 for the in-process virtual bus, whose firmware thread needs the
    GIL); ``reply_timeout``: seconds without any answer after the first frame
    before :class:`FirmwareTimeout`; ``drain``: seconds to wait for the last
    estimates: the rig keeps reading until no frame has come for that long
    (a slow rig may still be reading a deep receive queue long after the
    firmware answered), at most :data:`DRAIN_CAP` times as long."""

    def __init__(self, bus: can.BusABC, plan: Plan, *, transport: str = "?", channel: str = "?",
                 spin_ns: int = 100_000, reply_timeout: float = 1.0, drain: float = 0.5,
                 extra_frames: Callable[[int], list[can.Message]] | None = None,
                 kernel_drops: Callable[[], dict[str, int]] | None = None,
                 progress: Callable[[int, int, int, int], None] | None = None, sample_drops: bool = False) -> None:
        self.bus = bus
        self.plan = plan
        self.transport = transport
        self.channel = channel
        self.spin_ns = int(spin_ns)
        self.reply_timeout = check_seconds("reply_timeout", reply_timeout, zero=False)
        self.drain = check_seconds("drain", drain, zero=True)
        self.extra_frames = extra_frames  # fault injection: frames sent right after Measurement k
        # udp_multicast: the kernel's count of datagrams dropped on the rig's and the firmware's sockets
        # (a receive queue that overflowed on a busy host), read before and after the run, and with
        # ``sample_drops`` during it every drop_sampling(cycles) cycles (meta["kernel_drops_series"]: the drops
        # since the start, per side; off for timing runs: each read costs some 130 us)
        self.kernel_drops = kernel_drops
        self.sample_drops = bool(sample_drops)
        # called every PROGRESS_EVERY cycles during the replay with (cycles done, frames sent, estimates
        # received, frames lost by the scenario); hil.progress decides whether to show anything
        self.progress = progress
        ident = ids()
        self._estimate_id = ident["Estimate"]
        self._n_est = 0
        self._accept = {ident["Estimate"], ident["ControlAck"], ident["Diagnostics"], ident["Health"]}
        self._t0 = 0
        # socketcan and udp_multicast give each received frame the kernel's receive timestamp: an
        # estimate counts as back when it reached the rig's socket, not when this process got to it
        self._kernel_stamps = transport in ("socketcan", "udp_multicast")
        self._ago: dict[int, int] = {}           # id(kernel-stamped frame) -> its pick-up delay, ns
        self._events: list[tuple[int, str, can.Message]] = []
        self._drop_samples: list[tuple[int, dict[str, int]]] = []   # (cycle, kernel_drops()) during the replay
        self._n_rx = 0
        self._run_start: int | None = None       # perf_counter_ns where the handshake ended

    # -- receiving ---------------------------------------------------------------------------

    @property
    def _pickup(self) -> list[int]:
        """The pick-up delays (ns) of the kernel-stamped frames received so far."""
        return list(self._ago.values())

    def _take(self, msg: can.Message | None, now: int) -> None:
        if msg is None:
            return
        # udp_multicast hands a sender its own frames back: keep the firmware's ids only
        if msg.arbitration_id not in self._accept or msg.is_extended_id or msg.is_error_frame:
            return
        msg.is_rx = True
        ago = 0
        if self._kernel_stamps and msg.timestamp:
            # the kernel stamped the frame on arrival (CLOCK_REALTIME): how long ago, read in that clock
            # and at once on the rig's own (perf_counter), so that a stall since ``now`` does not count
            mono, real = _paired_clocks()
            ago = real - int(round(msg.timestamp * 1e9))
            if 0 <= ago < 1_000_000_000:         # else a clock step: keep the pick-up time
                now = mono
                self._ago[id(msg)] = ago
            else:
                ago = 0
        self._events.append((now - ago, "rx", msg))
        self._n_rx += 1
        if msg.arbitration_id == self._estimate_id:
            self._n_est += 1

    def _recv(self, timeout: float) -> can.Message | None:
        try:
            return self.bus.recv(timeout=timeout)
        except (can.CanError, OSError) as exc:
            raise self._lost("receiving", exc) from exc

    def _wait_until(self, deadline: int) -> None:
        spin, clock = self.spin_ns, time.perf_counter_ns
        while True:
            rem = deadline - clock()
            if rem <= 0:
                # Behind schedule: still take what has already arrived, without waiting (a bounded
                # number, so the next frame goes out), or a rig that never gets ahead on a slow host
                # would read no answer at all and call the firmware silent.
                for _ in range(BEHIND_READS):
                    msg = self._recv(0.0)
                    if msg is None:
                        break
                    self._take(msg, clock())
                return
            msg = self._recv((rem - spin) / 1e9 if rem > spin else 0.0)
            self._take(msg, clock())

    def _send(self, msg: can.Message) -> int:
        now = time.perf_counter_ns()
        try:
            self.bus.send(msg)
        except (can.CanError, OSError) as exc:
            raise self._lost("sending", exc) from exc
        self._events.append((now, "tx", msg))
        return now

    def _lost(self, doing: str, exc: BaseException) -> BusLost:
        sent = sum(1 for _, d, _m in self._events if d == "tx")
        received = sum(1 for _, d, _m in self._events if d == "rx")
        rec = self._recording({"bus_lost": f"{type(exc).__name__}: {exc}"})
        return BusLost(f"the bus ({self.transport} {self.channel}) went away while {doing} after {sent} frames sent "
                       f"and {received} received: {exc}", rec)

    def _control(self, command: str, token: int, timeout: float, *, progress: bool = False) -> bool:
        """Send a Control frame, authenticated with the firmware's public test
        key; True when its ControlAck came back (for a DiagRequest: and the
        Diagnostics frame after it). Sent again every 0.25 s until then, each
        time with the next freshness value (the firmware refuses a replay):
        the firmware may still be binding, and on a busy host a full receive
        queue may drop the request or the answers. ``progress``: any frame
        received restarts the ``timeout`` (a firmware still answering a
        backlog is behind, not gone), up to MAX_WAIT_S."""
        from pyrhonn.firmware import TEST_KEY, SecOCSender, control_message, database

        if not hasattr(self, "_secoc"):  # one freshness counter per rig, as per firmware run
            if TEST_KEY is None:
                raise RuntimeError("pyrhonn._fwapp was built with a provisioned SecOC key: hil knows only the "
                                   "public test key of the simulations")
            self._secoc = SecOCSender(TEST_KEY)
        want = ids()
        ack_id, diag_id, health_id = want["ControlAck"], want["Diagnostics"], want["Health"]
        n_health = len(self.plan.scenario.state_names)   # one Health frame per neuron (the LIM: HEALTH_FRAMES)
        start = time.perf_counter_ns()
        end = start + int(timeout * 1e9)
        seen = len(self._events)
        acked = False
        diag_at: int | None = None
        healths = health_end = 0
        resend = 0
        while time.perf_counter_ns() < end:
            if time.perf_counter_ns() >= resend and diag_at is None:
                self._send(control_message(command, token, sender=self._secoc))
                resend = time.perf_counter_ns() + 250_000_000
            n = self._n_rx
            self._take(self._recv(0.02), time.perf_counter_ns())
            if progress and self._n_rx != n:
                end = min(time.perf_counter_ns() + int(timeout * 1e9), start + int(MAX_WAIT_S * 1e9))
            for _, d, m in self._events[seen:]:
                if d != "rx":
                    continue
                if m.arbitration_id == ack_id:
                    a = database().decode_message("ControlAck", bytes(m.data), decode_choices=False)
                    acked = acked or (a["Token"] == token and a["Command"] == {"DiagRequest": 7, "Reset": 1}[command])
                elif m.arbitration_id == diag_id and acked:
                    diag_at = len(self._events)
                elif m.arbitration_id == health_id and diag_at is not None:
                    healths += 1
            seen = len(self._events)
            # the Diagnostics frame is followed by one Health frame per neuron: read them too, briefly
            if diag_at is not None and health_end == 0:
                health_end = time.perf_counter_ns() + 1_000_000_000
            if diag_at is not None and (healths >= n_health or time.perf_counter_ns() > health_end):
                return True
            if acked and command != "DiagRequest":
                return True
        return False

    # -- the run -----------------------------------------------------------------------------

    def run(self) -> Recording:
        """The run as a Recording; :class:`Interrupted` (with the frames so far) on SIGINT or SIGTERM."""
        try:
            return self._run()
        except KeyboardInterrupt as exc:
            signum = getattr(exc, "signum", signal.SIGINT)
            sent = sum(1 for _, d, _m in self._events if d == "tx")
            received = len(self._events) - sent
            why = f"interrupted by {signal.Signals(signum).name} after {sent} frames sent and {received} received"
            raise Interrupted(signum, self._recording({"partial": why})) from None

    def _run(self) -> Recording:
        sc = self.plan.scenario
        frames = self.plan.frames()
        T = int(round(sc.period * 1e9))
        delay = int(round(sc.transport_delay * 1e9))
        where = f"{self.transport} channel {self.channel}"
        self._t0 = time.perf_counter_ns()
        # handshake: a DiagRequest answered means a firmware is listening (and gives its counters)
        if not self._control("DiagRequest", 0xA5, self.reply_timeout):
            raise FirmwareTimeout(f"no answer from the firmware on {where} within {self.reply_timeout:g} s "
                                  "(is the firmware running, on this channel/port?)")
        drops0 = self.kernel_drops() if self.kernel_drops is not None else None
        wall0 = time.time()
        t0 = time.perf_counter_ns() + 10_000_000
        self._run_start = time.perf_counter_ns()
        self._t0 = t0
        gc_was = gc.isenabled()
        gc.freeze()
        gc.disable()
        try:
            overruns = self._replay(frames, t0, T, delay, where)
        finally:
            if gc_was:
                gc.enable()
            gc.unfreeze()
        drain_s, drain_capped = self._drain_estimates()
        # a firmware still working through a deep receive queue answers once it is through: while its
        # estimates keep coming it is behind, not gone
        diag_ok = self._control("DiagRequest", 0x5A, self.reply_timeout + DRAIN_CAP * self.drain, progress=True)
        drops = series = None
        if drops0 is not None and self.kernel_drops is not None:
            drops1 = self.kernel_drops()
            drops = {side: drops1[side] - drops0[side] for side in drops0}
            series = {"cycle": [k for k, _ in self._drop_samples],
                      **{side: [d[side] - drops0[side] for _, d in self._drop_samples] for side in drops0}}
        return self._recording({"wall_start": wall0, "rig_overruns": overruns, "final_diagnostics": diag_ok,
                                "drain_s": drain_s, "drain_capped": drain_capped, "kernel_drops": drops,
                                "kernel_drops_series": series})

    def _drain_estimates(self) -> tuple[float, bool]:
        """The last estimates: read until the bus has been quiet for ``drain``
        seconds, at most DRAIN_CAP x ``drain``. The time it took, and whether
        the cap cut it short (frames may then still be queued: counted missing)."""
        clock, quiet = time.perf_counter_ns, int(self.drain * 1e9)
        start = clock()
        cap, quiet_end = start + DRAIN_CAP * quiet, start + quiet
        while True:
            now = clock()
            if now >= quiet_end or now >= cap:
                return (now - start) / 1e9, quiet_end > now
            n = self._n_rx
            self._take(self._recv(min(0.01, (quiet_end - now) / 1e9)), clock())
            if self._n_rx != n:
                quiet_end = clock() + quiet

    def _replay(self, frames: list[can.Message], t0: int, T: int, delay: int, where: str) -> int:
        """The timed loop: frame k at its absolute deadline; the count of
        periods the rig itself overran."""
        lost = self.plan.lost
        n_rx_before = self._n_rx
        first_tx = None
        overruns = n_sent = n_lost = 0
        progress = self.progress
        kernel_drops = self.kernel_drops
        drops_every = drop_sampling(self.plan.cycles) if kernel_drops is not None and self.sample_drops else 0
        for k in range(self.plan.cycles):
            deadline = t0 + k * T + delay
            if time.perf_counter_ns() > deadline + T:
                overruns += 1  # the rig itself fell a period behind (counted, frame still sent)
            self._wait_until(deadline)
            if lost[k]:
                n_lost += 1
                continue
            sent = self._send(frames[k])
            n_sent += 1
            if progress is not None and (k % PROGRESS_EVERY == 0 or k == self.plan.cycles - 1):
                progress(k + 1, n_sent, self._n_est, n_lost)  # right after a send: the most slack before the next
            if drops_every and kernel_drops is not None and k % drops_every == 0:  # the same slack; /proc/net/udp
                self._drop_samples.append((k, kernel_drops()))
            if first_tx is None:
                first_tx = sent
            if self.extra_frames is not None:
                for extra in self.extra_frames(k):
                    self._send(extra)
            if self._n_rx == n_rx_before and sent - first_tx > self.reply_timeout * 1e9:
                raise FirmwareTimeout(f"no estimate from the firmware on {where} within {self.reply_timeout:g} s "
                                      f"of the first measurement frame ({k} frames sent; did it stop or the bus "
                                      "go down?)")
        return overruns

    def _recording(self, extra: dict[str, Any]) -> Recording:
        """The frames so far as a Recording, in time order. Time: seconds from
        the earliest frame (the handshake), so every timestamp is >= 0 and BLF
        keeps it to the nanosecond; its wall clock is ``wall_time_ns``; t0
        (deadline of frame 0, without the delay) is in meta. The handshake is
        the frames before ``first_run_event``: those stamped before the
        replay began (an answer to the handshake picked up during the run
        included)."""
        from pyrhonn.firmware import database

        from .latency import stats_us

        sc = self.plan.scenario
        # time order: a frame the kernel stamped on arrival goes before the frames sent while it waited to be
        # picked up (a stable sort: frames sent, stamped in sending order, keep it)
        order = sorted(range(len(self._events)), key=lambda i: self._events[i][0])
        ordered = [self._events[i] for i in order]
        base = ordered[0][0] if ordered else self._t0
        mono, real = _paired_clocks()
        events = [((ns - base) / 1e9, d, m) for ns, d, m in ordered]
        pickup = [self._ago.get(id(m), 0) if d == "rx" else 0 for _, d, m in ordered]
        for ts, _, m in events:
            m.timestamp = ts
            m.channel = None
        first_run = 0 if self._run_start is None else sum(1 for ns, _d, _m in ordered if ns < self._run_start)
        meta = {"transport": self.transport, "channel": self.channel, "period_ns": int(round(sc.period * 1e9)),
                "delay_ns": int(round(sc.transport_delay * 1e9)), "t0_ns": self._t0 - base,
                "wall_time_ns": real - (mono - base), "protocol": database().version,
                "first_run_event": first_run, "rx_stamp": "kernel" if self._kernel_stamps else "recv",
                "rx_pickup_us": stats_us(np.asarray(self._pickup, dtype=np.int64)) if self._ago else {"n": 0},
                "_rx_pickup_ns": pickup, **extra}
        return Recording(scenario=sc, events=events, meta=meta)


# -- logs ------------------------------------------------------------------------------------------


class _ASCWriter(can.ASCWriter):
    """python-can's ASC writer with the Triggerblock's milliseconds written as three digits.

    Its own header writes ``dt.microsecond // 1000`` unpadded: a run that starts 53 ms into a
    second gets ``...:52.53 2026``, which every reader (python-can's included) takes for 530 ms,
    so every absolute frame time of the log is 477 ms late. CANoe and the readers expect the
    three digits this writes."""

    def _format_header_datetime(self, dt: datetime.datetime) -> str:
        return dt.strftime(self.FORMAT_DATE.format(f"{dt.microsecond // 1000:03d}"))


#: The log formats hil writes and reads (with the sidecar): BLF, ASC and MDF4.
LOG_SUFFIXES = (".blf", ".asc", ".mf4")


def check_log_name(path: Path, option: str = "log") -> None:
    """A ValueError naming ``option`` unless ``path`` names a log format hil writes, with what that
    format needs installed (MDF4: asammdf, the ``mdf`` extra)."""
    suffix = path.suffix.lower()
    if suffix not in LOG_SUFFIXES:
        raise ValueError(f"{option}: {path.name}: expected a .blf, .asc or .mf4 file name")
    if suffix == ".mf4":
        import importlib.util

        if importlib.util.find_spec("asammdf") is None:
            raise ValueError(f"{option}: {path.name}: MDF4 logs need asammdf (pip install 'pyrhonn[mdf]')")


def _writer(path: Path, target: Path) -> can.BLFWriter | _ASCWriter | can.MF4Writer:
    """python-can's writer for ``path``'s format, writing to ``target``."""
    suffix = path.suffix.lower()
    if suffix == ".blf":
        return can.BLFWriter(target)
    if suffix == ".asc":
        return _ASCWriter(target)
    if suffix == ".mf4":
        return can.MF4Writer(target)
    raise ValueError(f"log: {path.name}: expected a .blf, .asc or .mf4 file name")


ASC_ORIGIN_EVENT = "pyrhonn hil: frame times from the wall clock of this Triggerblock"


def _log_origin(rec: Recording) -> tuple[int, int]:
    """(origin, lead), in ns: the log file's start on the wall clock, ``wall_time_ns`` truncated to the
    millisecond (what a BLF header and an ASC Triggerblock can hold), and how far the Recording's t = 0
    lies after it. (0, 0) for a Recording without a wall clock (read from a log of the format before):
    its log starts at 0 as it did."""
    wall = rec.meta.get("wall_time_ns")
    if not isinstance(wall, int) or isinstance(wall, bool) or wall <= 0:
        return 0, 0
    origin = wall - wall % 1_000_000
    return origin, wall - origin


class _LogWriter:
    """Feeds python-can's writer the Recording's frames at absolute times.

    BLF: each object's timestamp is its offset in ns from the file's start
    (the header's SYSTEMTIME, millisecond resolution). The writer is given
    the offsets (start 0, so that no float at the wall clock's magnitude,
    0.24 us apart, rounds them) and, before it writes its header, the
    absolute start and stop. ASC: lines are seconds from the Triggerblock,
    microsecond resolution; a first event at the origin sets it, and each
    frame's time is the origin plus its offset rounded to the microsecond
    (the float sum is within 0.12 us of it, so the writer's subtraction and
    6-decimal format give back the exact offset)."""

    def __init__(self, path: Path, target: Path, rec: Recording) -> None:
        self.blf = path.suffix.lower() == ".blf"
        self.mf4 = path.suffix.lower() == ".mf4"
        self.writer = _writer(path, target)
        self.origin, self.lead = _log_origin(rec)
        self.last = 0.0
        if isinstance(self.writer, can.BLFWriter):
            self.writer.start_timestamp = 0.0
        elif isinstance(self.writer, _ASCWriter) and self.origin:
            self.writer.log_event(ASC_ORIGIN_EVENT, self.origin / 1e9)

    def write(self, ts: float, m: can.Message) -> None:
        offset_ns = int(round(ts * 1e9)) + self.lead
        if self.blf:
            m.timestamp = offset_ns / 1e9 + 0.4e-9  # BLF truncates to whole ns: land on ours
        elif self.mf4:  # absolute: the writer subtracts the time it opened the file
            m.timestamp = self.origin / 1e9 + offset_ns / 1e9
        else:
            m.timestamp = self.origin / 1e9 + int(round(offset_ns / 1e3)) / 1e6 if self.origin else ts
        self.last = offset_ns / 1e9
        self.writer.on_message_received(m)

    def stop(self) -> None:
        if isinstance(self.writer, can.BLFWriter) and self.origin:  # the header, written by stop(): start, stop
            self.writer.start_timestamp = self.origin / 1e9
            self.writer.stop_timestamp = self.origin / 1e9 + self.last
        self.writer.stop()


def sidecar(path: Path) -> Path:
    return Path(str(path) + ".json")


def file_sha256(path: Path) -> str:
    """The SHA-256 of the file ``path``, hex."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def partial_reason(rec: Recording) -> str | None:
    """Why ``rec`` is not a whole run (interrupted, the bus lost), or None."""
    if rec.meta.get("partial"):
        return str(rec.meta["partial"])
    if rec.meta.get("bus_lost"):
        return f"the bus went away ({rec.meta['bus_lost']})"
    return None


def write_log(rec: Recording, path: str | os.PathLike) -> Path:
    """Write ``rec`` to ``path`` (BLF, ASC or MDF4), then its sidecar ``path.json``
    with the frame count and the log's SHA-256 (and ``partial``: why the run
    is not whole, or null). Each is written to a temporary file and renamed
    into place: a write that fails or is interrupted leaves the previous log
    (or none), never a part of one; a failure raises :class:`LogWriteError`."""
    from pyrhonn import atomic
    from pyrhonn.firmware import database

    path = Path(path)
    check_log_name(path)
    written = 0
    try:
        with atomic.replacing_path(path) as tmp:
            writer = _LogWriter(path, tmp, rec)
            try:
                for ts, d, m in rec.events:
                    m.is_rx = d == "rx"
                    writer.write(ts, m)
                    written += 1
            finally:
                writer.stop()
            digest = file_sha256(tmp)
    except OSError as exc:
        what = "disk full" if exc.errno == errno.ENOSPC else (exc.strerror or str(exc))
        raise LogWriteError(exc.errno or errno.EIO,
                            f"log: {path}: {what} after {written} of {len(rec.events)} frames; nothing of it is "
                            "kept (a previous log there is unchanged; the run's report is complete)") from exc
    origin, lead = _log_origin(rec)
    meta = {"format": LOG_FORMAT, "scenario": rec.scenario.to_dict(),
            **{k: v for k, v in rec.meta.items() if not k.startswith("_")},
            "protocol": rec.meta.get("protocol") or database().version,
            "wall_time_ns": origin + lead if origin else None,
            "first_timestamp": rec.events[0][0] if rec.events else 0.0, "frames": len(rec.events),
            "sha256": digest, "partial": partial_reason(rec)}
    sc_path = sidecar(path)
    try:  # after the log: a kill in between leaves a log its old sidecar (or none) does not vouch for
        atomic.write_text(sc_path, json.dumps(meta, indent=1, sort_keys=True) + "\n")
    except OSError as exc:
        raise LogWriteError(exc.errno or errno.EIO, f"log: cannot write {sc_path}: {exc.strerror or exc}") from exc
    return path


def _read_sidecar(sc_path: Path) -> tuple[Scenario, dict[str, Any]]:
    """The scenario and the metadata of a log's sidecar ``sc_path``; a
    ValueError naming the sidecar for anything that is not what
    :func:`write_log` writes (not JSON, not an object, no scenario, a bad
    scenario or a field of the wrong type)."""
    from pyrhonn.validation import check_real, read_file

    def bad(why: str) -> ValueError:
        return ValueError(f"log: {sc_path}: not a hil log sidecar ({why})")

    try:  # a sidecar is a few kB: a larger file, a device or a pipe is not one
        meta = json.loads(read_file(sc_path, f"log: {sc_path}", limit=SIDECAR_MAX_BYTES))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise bad(f"not JSON: {exc}") from None
    except RecursionError:
        raise bad("JSON nested too deeply") from None
    except OSError as exc:
        raise ValueError(f"log: {sc_path}: cannot read it ({exc.strerror or exc})") from None
    if not isinstance(meta, dict):
        raise bad(f"expected a JSON object, got {json.dumps(meta)[:40]}")
    _read_protocol(meta, _format_version(meta, sc_path), sc_path)
    if "scenario" not in meta:
        raise bad("no 'scenario' entry")
    try:
        scenario = Scenario.from_dict(meta.pop("scenario"))
    except (KeyError, TypeError) as exc:
        raise bad(f"scenario: {exc}") from None
    except ValueError as exc:  # a field out of range, or the trajectory file changed: said as it is
        raise ValueError(f"log: {sc_path}: {exc}") from None
    for key in ("first_run_event", "t0_ns", "period_ns", "delay_ns", "frames"):  # whole numbers (hil.score)
        v = meta.get(key, 0)
        if isinstance(v, bool) or not isinstance(v, int) or not -2 ** 63 <= v < 2 ** 63:
            raise bad(f"{key}: expected a 64-bit integer, got {json.dumps(v)[:40]}")
    if meta.get("frames", 0) < 0:
        raise bad(f"frames: expected a count >= 0, got {meta['frames']}")
    digest = meta.get("sha256")
    if digest is not None and not (isinstance(digest, str) and len(digest) == 64
                                   and all(c in "0123456789abcdef" for c in digest)):
        raise bad(f"sha256: expected 64 lowercase hex digits, got {json.dumps(digest)[:80]}")
    if not isinstance(meta.get("partial"), (str, type(None))):
        raise bad(f"partial: expected a reason (text) or null, got {json.dumps(meta['partial'])[:40]}")
    pickup = meta.get("rx_pickup_us", {"n": 0})  # stats_us's figures, printed by the report
    if not isinstance(pickup, dict) or not all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                               for v in pickup.values()):
        raise bad(f"rx_pickup_us: expected an object of numbers, got {json.dumps(pickup)[:40]}")
    try:
        meta["first_timestamp"] = check_real("first_timestamp", meta.get("first_timestamp", 0.0))
    except ValueError as exc:
        raise bad(str(exc)) from None
    wall = meta.get("wall_time_ns")
    if wall is not None and (isinstance(wall, bool) or not isinstance(wall, int) or not 0 < wall < 2 ** 63):
        raise bad(f"wall_time_ns: expected nanoseconds since 1970 or null, got {json.dumps(wall)[:40]}")
    # run-time entries write_log never writes (hil.score would take them for a live run's)
    for key in [k for k in meta if k.startswith("_")]:
        del meta[key]
    return scenario, meta


def _format_version(meta: dict[str, Any], sc_path: Path) -> int:
    """N of the sidecar's ``"format": "pyrhonn-hil-log N"``; a ValueError for a format newer than this
    hil's or not one of these."""
    fmt = meta.get("format")
    prefix = "pyrhonn-hil-log "
    if not (isinstance(fmt, str) and fmt.startswith(prefix) and fmt[len(prefix):].isdigit()):
        raise ValueError(f"log: {sc_path}: not a hil log sidecar (format: expected 'pyrhonn-hil-log N', got "
                         f"{json.dumps(fmt)[:60]})")
    version = int(fmt[len(prefix):])
    if version > LOG_FORMAT_VERSION:
        raise ValueError(f"log: {sc_path}: format {fmt!r} is newer than this pyrhonn reads ({LOG_FORMAT!r} and "
                         "before); refused")
    return version


def _read_protocol(meta: dict[str, Any], version: int, sc_path: Path) -> None:
    """``meta["protocol"]``: the DBC version the log's frames were written in (sidecars of format 2 and
    before name none: the protocol of their time, LEGACY_PROTOCOL); a ValueError for one this hil cannot
    decode."""
    from pyrhonn.firmware import database

    current = database().version
    if version < LOG_FORMAT_VERSION:
        meta["protocol"] = LEGACY_PROTOCOL
    proto = meta.get("protocol")
    if proto not in (current, *SAME_DIAGNOSTICS, LEGACY_PROTOCOL):
        raise ValueError(f"log: {sc_path}: recorded in protocol {json.dumps(proto)[:60]}; this hil decodes "
                         f"{current!r}, {', '.join(map(repr, SAME_DIAGNOSTICS))} and {LEGACY_PROTOCOL!r}; refused")


def _read_frames(path: Path, suffix: str) -> tuple[list[can.Message], Exception | None]:
    """The frames of a log, up to where it stops parsing: the frames read,
    and the exception that stopped the reader (None: read to its end)."""
    msgs: list[can.Message] = []
    reader: Any = None  # a BLFReader, an ASCReader or an MF4Reader
    try:  # the BLF and MF4 readers parse the file's header when made: a foreign or empty file fails there
        reader = (can.BLFReader(path) if suffix == ".blf" else can.MF4Reader(path) if suffix == ".mf4" else
                  can.ASCReader(path))
        if suffix == ".blf":
            # each object's offset from the file's start, to the ns: python-can adds the start (the wall
            # clock, where a float's step is 0.24 us) to it; read_log anchors the offsets on the sidecar
            reader.start_timestamp = 0.0
        for m in reader:
            msgs.append(m)
    except Exception as exc:  # noqa: BLE001 - any parse failure of a truncated/foreign file
        return msgs, exc
    finally:
        if reader is not None:
            reader.stop()
    return msgs, None


def read_log(path: str | os.PathLike, *, partial: bool = False) -> Recording:
    """A log written by :func:`write_log` (with its sidecar) as a Recording.
    Anything else is a ValueError naming the file: a missing, foreign or
    empty log, a bad sidecar or none, a log that falls short of the frame
    count its sidecar records (the message names how many frames are
    missing) or whose SHA-256 does not match it, and a log of a run that was
    interrupted or lost its bus (its sidecar's ``partial``), unless
    ``partial`` (the Recording's meta then keeps the reason)."""
    import struct

    path = Path(path)
    if not path.is_file():
        raise ValueError(f"log: {path}: no such file")
    sc_path = sidecar(path)
    if not sc_path.is_file():
        raise ValueError(f"log: {path}: no sidecar {sc_path.name} (its scenario, frame count and checksum): "
                         "refused, nothing says the log is whole")
    scenario, meta = _read_sidecar(sc_path)
    suffix = path.suffix.lower()
    if suffix not in LOG_SUFFIXES:
        raise ValueError(f"log: {path.name}: expected a .blf, .asc or .mf4 file")
    if path.stat().st_size == 0:
        raise ValueError(f"log: {path}: empty file (not a {suffix[1:].upper()} log)")
    if "frames" not in meta or not isinstance(meta.get("sha256"), str):
        raise ValueError(f"log: {path}: its sidecar {sc_path.name} records no frame count and checksum (sha256), "
                         "so nothing says the log is whole: refused (written by an older pyrhonn or by hand)")
    expected = meta["frames"]
    why = meta.get("partial")
    if why and not partial:
        raise ValueError(f"log: {path}: a partial log ({why}; {expected} frames recorded): refused, its run did "
                         "not finish (hil score --partial scores it anyway)")
    if suffix == ".mf4":  # its blocks checked first: asammdf would fail on a cut file and again at exit
        from pyrhonn.mdfsignals import mdf_damage

        damage = mdf_damage(path)
        if damage is not None:
            raise ValueError(f"log: {path}: not a whole MDF4 file ({damage}): cut short after it was written, "
                             "or not the log its sidecar describes; refused")
    msgs, failure = _read_frames(path, suffix)
    if len(msgs) < expected:
        raise ValueError(f"log: {path}: {expected - len(msgs)} of the {expected} frames its sidecar records are "
                         f"missing (it holds {len(msgs)}): cut short after it was written; refused")
    if failure is not None:
        kind = "truncated, or not a BLF log" if isinstance(failure, struct.error) else type(failure).__name__
        raise ValueError(f"log: {path}: cannot read it ({kind}: {failure})")
    if file_sha256(path) != meta["sha256"]:
        raise ValueError(f"log: {path}: its SHA-256 does not match the one its sidecar {sc_path.name} records: "
                         "changed after it was written (or not the log the sidecar describes); refused")
    shift = 0.0
    if msgs:  # offsets from the file's start (the run's wall clock to the ms): anchor on the first frame
        shift = meta["first_timestamp"] - msgs[0].timestamp
    events = [(m.timestamp + shift, "rx" if m.is_rx else "tx", m) for m in msgs]
    meta["frames_read"] = len(events)
    return Recording(scenario=scenario, events=events, meta=meta)
