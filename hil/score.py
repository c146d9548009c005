"""Scoring a run from its frames alone (a live :class:`~hil.rig.Recording` or
one read back from a log): the same function, so re-scoring a log gives the
same numbers.

- Matching: each Measurement frame the rig sent is identified as cycle k of
  the scenario's plan by its Seq (unwrapped past 65535) and its bytes; any
  other frame the rig sent is *foreign* (fault injection: malformed frames, a
  sequence jump). Each Estimate is matched to the latest cycle with its Seq
  sent before it arrived (an Estimate stamped before every such cycle, by a
  clock-pairing error of a few us, to the first of them): the same whether
  the frames are in time order (logs since format 3) or in the order the
  rig picked them up (logs before). An Estimate for no sent cycle is
  *unexpected*, a second one a *duplicate*.
- Accounting: cycles = sent + lost (lost: the scenario's injected frame
  loss, never sent); sent = answered + rejected + missing, where *rejected*
  are the cycles the protocol must refuse (a Seq jump: the first frame after
  a loss or after a foreign Measurement); *missing* is anything else
  unanswered. The firmware's own Diagnostics (requested before and after the
  run) give its count of rejections, which must equal rejected + foreign.
  Over udp_multicast a busy host's kernel may drop datagrams at a full
  receive queue: such losses, corroborated by the firmware's counts and the
  kernel's drop counters, are counted apart (lost to / from the firmware,
  rejected after a loss; hil.accounting) instead of missing.
- Identification: RMSE and absolute deviation (pyrhonn.metrics) of position
  and velocity, Estimate k (x̂(k+1), after the DBC's scaling) against the
  noise-free x(k+1), over the answered cycles; Table 7 alongside; the same
  outside the measurement hold, and against the next Measurement frame (see
  :func:`_identification`).
- Timing: latency Measurement sent -> Estimate received (at the rig's
  socket: the kernel's receive timestamp on socketcan and udp_multicast, see
  hil.rig), and apart from it the rig process's delay in picking received
  frames up; the rig's lateness against its absolute deadlines and its
  period jitter (interval between consecutive frames minus T).
"""
from __future__ import annotations

import bisect
import dataclasses
import math
from typing import Any

import numpy as np

from . import diagnostics
from .accounting import kernel_losses, stepped
from .latency import stats_us
from .rig import Recording, ids
from .scenario import TABLE7

__all__ = ["FATES", "fates", "score", "scored_states", "stats_us"]


def _ns(t: float) -> int:
    return int(round(t * 1e9))


def _diag(msg, protocol: str | None) -> dict[str, Any]:
    """A Diagnostics frame in the protocol its run spoke (hil.diagnostics)."""
    return diagnostics.decode(bytes(msg.data), protocol)


def score(rec: Recording, *, reference: Any = None) -> dict[str, Any]:
    """The report of a run as a JSON-able dict. ``reference``: an
    IdentifierConfig to also check the estimates bit for bit against
    ``Identifier.run`` on the accepted Measurement frames (None: skipped)."""
    from pyrhonn.firmware import decode_health

    sc = rec.scenario
    plan = sc.build()
    proto = sc.protocol()
    n_states = len(proto.states)
    N = plan.cycles
    T = int(round(sc.period * 1e9))
    delay = int(round(sc.transport_delay * 1e9))
    ident = ids()
    MEAS, EST, DIAG = ident["Measurement"], ident["Estimate"], ident["Diagnostics"]
    meas_len = proto.measurement_length
    first_run = int(rec.meta.get("first_run_event", 0))
    protocol = rec.meta.get("protocol")

    sent_ns = np.full(N, -1, dtype=np.int64)
    recv_ns = np.full(N, -1, dtype=np.int64)
    picked_ns = np.full(N, -1, dtype=np.int64)   # when the rig process had it (kernel stamp + pick-up)
    pickup = rec.meta.get("_rx_pickup_ns")     # live runs only: a log keeps the arrival stamps, not these
    if pickup is not None and (len(pickup) != len(rec.events) or rec.meta.get("rx_stamp") != "kernel"):
        pickup = None
    raw = np.zeros((N, n_states), dtype=np.int64)
    phys = np.zeros((N, n_states), dtype=np.float64)
    status = np.zeros(N, dtype=np.int64)
    resync = np.zeros(N, dtype=bool)
    expect_reject = np.zeros(N, dtype=bool)
    meas_data: dict[int, bytes] = {}
    by_seq: dict[int, list[int]] = {}    # Seq -> the cycles sent with it, in sending order
    estimates: list[tuple[int, int, Any]] = []   # (event index, arrival ns, Estimate frame)
    last_k = -1
    prev_seq: int | None = None
    foreign: dict[str, int] = {}
    unexpected = duplicates = mismatched = 0
    diags: list[dict[str, Any]] = []
    health: dict[int, dict[str, Any]] = {}
    HEALTH = ident["Health"]
    plan_bytes: dict[int, bytes] = {}

    def plan_frame(k: int) -> bytes:
        if k not in plan_bytes:
            plan_bytes[k] = bytes(proto.measurement_message(k & 0xFFFF, plan.X[k], plan.U[k], plan.valid[k]).data)
        return plan_bytes[k]

    for i, (t, d, m) in enumerate(rec.events):
        if i < first_run:                       # the handshake before the run
            if d == "rx" and m.arbitration_id == DIAG:
                diags.append(_diag(m, protocol))
            continue
        if d == "tx":
            if m.arbitration_id == MEAS and not m.is_extended_id and len(m.data) == meas_len:
                s = int.from_bytes(bytes(m.data[:2]), "little")
                k = last_k + 1 + ((s - (last_k + 1)) & 0xFFFF)
                if k < N and bytes(m.data) == plan_frame(k):
                    sent_ns[k] = _ns(t)
                    meas_data[k] = bytes(m.data)
                    by_seq.setdefault(s, []).append(k)
                    first_accept = prev_seq is None and not (diags and diags[0].get("Synced"))
                    if prev_seq is None and diags and diags[0].get("Synced"):
                        prev_seq = diags[0]["LastSeq"]
                    expect_reject[k] = not first_accept and prev_seq is not None and s != ((prev_seq + 1) & 0xFFFF)
                    prev_seq = s
                    last_k = k
                    continue
                prev_seq = s if s != prev_seq else prev_seq   # a foreign 20-byte Measurement moves the anchor
                foreign["measurement, foreign Seq"] = foreign.get("measurement, foreign Seq", 0) + 1
            elif m.arbitration_id == ident["Control"]:
                continue
            else:
                kind = "measurement, bad length" if m.arbitration_id == MEAS else "unknown id"
                foreign[kind] = foreign.get(kind, 0) + 1
            continue
        if m.arbitration_id == DIAG:
            diags.append(_diag(m, protocol))
            continue
        if m.arbitration_id == HEALTH:
            try:
                h = decode_health(m)
            except ValueError:
                continue
            health[h.neuron] = dataclasses.asdict(h)   # the last one per neuron: after the final Diagnostics
            continue
        if m.arbitration_id == EST:
            estimates.append((i, _ns(t), m))

    for i, t_ns, m in estimates:   # after every frame sent is known: in time order, its answer may come first
        try:
            e = proto.decode_estimate(m, scaling=False)
        except ValueError:
            mismatched += 1
            continue
        cycle = _answered_cycle(by_seq.get(e.seq), sent_ns, t_ns)
        if cycle is None:
            unexpected += 1
        elif recv_ns[cycle] >= 0:
            duplicates += 1
        else:
            recv_ns[cycle] = t_ns
            picked_ns[cycle] = recv_ns[cycle] + (int(pickup[i]) if pickup is not None else 0)
            raw[cycle] = e.xhat
            phys[cycle] = proto.decode_estimate(m).xhat
            status[cycle] = e.step_status
            resync[cycle] = e.resync

    lost = np.asarray(plan.lost)
    was_sent = sent_ns >= 0
    answered = recv_ns >= 0
    unanswered = was_sent & ~answered
    rejected = unanswered & expect_reject
    missing = unanswered & ~expect_reject
    latency = recv_ns[answered] - sent_ns[answered]
    late = int(np.sum(latency > T))
    deadlines = int(rec.meta.get("t0_ns", 0)) + np.arange(N, dtype=np.int64) * T + delay
    lateness = sent_ns[was_sent] - deadlines[was_sent]
    ks = np.flatnonzero(was_sent)
    consecutive = np.diff(ks) == 1
    intervals = np.diff(sent_ns[ks])[consecutive] - T

    out: dict[str, Any] = {
        "transport": rec.meta.get("transport"), "channel": rec.meta.get("channel"),
        "scenario": sc.to_dict(), "cycles": N, "states": list(proto.states),
        "frames": {"sent": int(was_sent.sum()), "lost_injected": int(lost.sum()),
                   "lost_unaccounted": int(np.sum(~was_sent & ~lost)), "answered": int(answered.sum()),
                   "rejected_seq_jump": int(rejected.sum()), "missing": int(missing.sum()), "late": late,
                   "duplicates": duplicates, "unexpected": unexpected, "undecodable": mismatched,
                   "foreign_sent": dict(sorted(foreign.items())), "step_errors": int(np.sum(answered & (status != 0))),
                   "answered_after_expected_reject": int(np.sum(answered & expect_reject))},
    }
    f = out["frames"]
    f["sent_plus_lost_is_cycles"] = f["sent"] + f["lost_injected"] == N and f["lost_unaccounted"] == 0
    # the firmware's own count, from the Diagnostics before and after the run
    if len(diags) >= 2:
        a, b = diags[0], diags[-1]
        fw = {"rejected": (b["Rejected"] - a["Rejected"]) & 0xFFFF,
              "seq_errors": (b["SeqErrors"] - a["SeqErrors"]) & 0xFFFF,
              "measurements": (b["Measurements"] - a["Measurements"]) & 0xFFFFFFFF,
              "step_errors": (b["StepErrors"] - a["StepErrors"]) & 0xFFFF,
              "overruns": (b["Overruns"] - a["Overruns"]) & 0xFFFF,
              "lost_frames": (b["LostFrames"] - a["LostFrames"]) & 0xFFFFFFFF,
              "rx_drops": (b["RxDrops"] - a["RxDrops"]) & 0xFFFFFFFF,
              "step_time_max_us": b["StepTimeMax"], "last_step_time_us": b["StepTime"],
              # at the top of its signal's range: at least that long, not a measurement
              "step_time_max_saturated": "StepTimeMax" in b["saturated"],
              "last_step_time_saturated": "StepTime" in b["saturated"],
              "protocol": protocol or None}
        out["firmware"] = fw
        n_foreign = sum(foreign.values())
        f.update(_kernel_losses(f, fw, n_foreign, rec.meta))
        f["accounted"] = bool(fw["measurements"] == f["answered"] + f["lost_from_firmware"]
                              and fw["rejected"] == f["rejected_seq_jump"] + n_foreign + f["rejected_after_loss"]
                              and f["missing"] == 0 and f["sent_plus_lost_is_cycles"])
    else:
        out["firmware"] = None
        f.update(_kernel_losses(f, None, 0, rec.meta))
        f["accounted"] = bool(f["missing"] == 0 and f["sent_plus_lost_is_cycles"])
    out["identification"] = _identification(plan, answered, phys) if answered.sum() >= 2 else None
    out["not_valid"] = plan.not_valid          # Valid flags the rig cleared, per state and reason
    out["health"] = [health[i] for i in sorted(health)]   # the firmware's filter health at the end, per neuron
    out["latency_us"] = stats_us(latency)
    out["latency_us"]["within_period"] = float(np.mean(latency <= T)) if latency.size else math.nan
    out["latency_us"]["stamp"] = rec.meta.get("rx_stamp", "recv")
    if pickup is not None and latency.size:
        out["latency_us"]["within_period_picked_up"] = float(np.mean(picked_ns[answered] - sent_ns[answered] <= T))
    out["rig_pickup_us"] = rec.meta.get("rx_pickup_us", {"n": 0})
    out["rig_lateness_us"] = stats_us(lateness)
    jit = stats_us(np.abs(intervals))
    jit["max_abs"] = jit.pop("max", 0.0) if jit.get("n") else 0.0
    out["rig_period_jitter_us"] = jit
    out["rig_overruns"] = rec.meta.get("rig_overruns")
    out["drain"] = {"s": rec.meta.get("drain_s"), "capped": bool(rec.meta.get("drain_capped", False))}
    steps, unknown_from = stepped(was_sent, answered, resync, expect_reject, f,
                                  out["firmware"]["measurements"] if out["firmware"] else None)
    health_series = None
    if reference is not None:
        out["bit_exact"], health_series = _reference_check(reference, meas_data, steps, answered, raw, unknown_from,
                                                           proto)
    out["_series"] = {"k": np.flatnonzero(answered), "est": phys[answered], "truth": np.asarray(plan.truth_next),
                      "latency_ns": latency, "t": np.asarray(plan.t), "X": np.asarray(plan.X),
                      "valid": np.asarray(plan.valid),
                      "fate": fates(answered, lost, was_sent, expect_reject, steps, unknown_from, f["missing"] > 0),
                      "kernel_drops": rec.meta.get("kernel_drops_series"), "health": health_series}
    return out


#: what became of each cycle's Measurement (``_series["fate"]``), by code
FATES = ("answered", "lost (injected)", "rejected (Seq jump)", "lost to the firmware", "lost from the firmware",
         "lost, which way not known", "missing", "never sent")


def fates(answered: np.ndarray, lost: np.ndarray, was_sent: np.ndarray, expect_reject: np.ndarray,
          steps: np.ndarray, unknown_from: int | None, unexplained: bool) -> np.ndarray:
    """Per cycle, the index in :data:`FATES` of what became of its Measurement: answered; lost by the
    scenario; rejected as a Seq jump; sent but unanswered, then (hil.accounting) lost on the way to the
    firmware (or rejected after such a loss), its Estimate lost on the way back (the firmware stepped on
    it), lost one way or the other from ``unknown_from`` on, or missing when the losses are not
    corroborated (``unexplained``); not sent (an interrupted run)."""
    out = np.full(answered.shape, FATES.index("never sent"), dtype=np.int8)
    out[answered] = 0
    out[lost] = FATES.index("lost (injected)")
    gone = was_sent & ~answered
    out[gone & expect_reject] = FATES.index("rejected (Seq jump)")
    other = gone & ~expect_reject
    if unexplained:
        out[other] = FATES.index("missing")
        return out
    out[other & steps] = FATES.index("lost from the firmware")
    out[other & ~steps] = FATES.index("lost to the firmware")
    if unknown_from is not None:
        out[unknown_from:][other[unknown_from:]] = FATES.index("lost, which way not known")
    return out


def _answered_cycle(cycles: list[int] | None, sent_ns: np.ndarray, t_ns: int) -> int | None:
    """The cycle an Estimate with these ``cycles``' Seq that arrived at ``t_ns``
    answers: the latest sent before it, else (stamped a few us early: the
    kernel's clock paired with the rig's) the first; None: its Seq was never sent."""
    if not cycles:
        return None
    j = bisect.bisect_right([int(sent_ns[k]) for k in cycles], t_ns)
    return cycles[j - 1] if j else cycles[0]


def _errors(target: np.ndarray, est: np.ndarray) -> dict[str, Any]:
    """RMSE and absolute deviation (pyrhonn.metrics) of one state's errors."""
    from pyrhonn import metrics

    if target.size < 2:
        return {"cycles": int(target.size), "rmse": None, "absolute_deviation": None}
    return {"cycles": int(target.size), "rmse": float(metrics.rmse(target[:, None], est[:, None])[0]),
            "absolute_deviation": float(metrics.absolute_deviation(target[:, None], est[:, None])[0])}


def _identification(plan: Any, answered: np.ndarray, phys: np.ndarray) -> dict[str, Any]:
    """Position and velocity errors of the answered estimates, three ways:

    - against the noise-free truth x(k+1), over every answered cycle (the
      issue's measure; Table 7 beside it);
    - the same outside the measurement hold (cycles whose sample x(k) and
      target x(k+1) are both measured), which separates the identifier's
      one-step accuracy from how well it bridges the hold; the estimate made
      at a hold's last sample ends the free run through the hold and is in
      neither figure: ``hold.end_error_max`` is its error;
    - against the next Measurement frame as the rig sent it (quantised
      position, differenced velocity), over the cycles whose next frame
      carries a fresh value of the state: the one-step error the firmware
      itself could compute, the only kind a real rig without a reference
      sensor can report;
    - and, as the yardstick for all three, the Measurement frames' own error
      against the truth (the encoder's quantisation, the differencing noise
      of the velocity): an identifier fed these signals beats that figure
      only by filtering;
    - ``hold``: how far the state moved while its measurement was held (the
      largest gap between the held value and the truth) and the RMSE of the
      frames themselves against the truth over the answered cycles, held
      ones included: what following the rig's signal scores in this
      scenario, the scale against which to read Table 7's figure; and
      inside the hold alone (the cycles whose target is held), the
      identifier's RMSE beside the held frames' own: how much of the
      dropout it bridges.
    """
    truth_all = np.asarray(plan.truth_next)
    X, V = np.asarray(plan.X), np.asarray(plan.valid)
    next_fresh = np.ones(V.shape, dtype=bool)     # the last target lies after the run: counted as fresh
    next_fresh[:-1] = V[1:]
    has_next = answered.copy()
    has_next[-1] = False
    ident: dict[str, Any] = {}
    lim = not plan.scenario.identifier
    for name, j, _unit in scored_states(plan.scenario):
        est, truth = phys[answered, j], truth_all[answered, j]
        out_hold = next_fresh[answered, j] & V[answered, j]
        vs_meas = (has_next & next_fresh[:, j])[:-1]
        sensed = next_fresh[:-1, j]
        t7 = TABLE7[name] if lim else {"rmse": None, "absolute_deviation": None}
        ident[name] = {
            **_errors(truth, est),
            "table7_rmse": t7["rmse"], "table7_absolute_deviation": t7["absolute_deviation"],
            "outside_hold": _errors(truth[out_hold], est[out_hold]),
            "vs_measurement": _errors(X[1:, j][vs_meas], phys[:-1, j][vs_meas]),
            "measurement_vs_truth": _errors(truth_all[:-1, j][sensed], X[1:, j][sensed]),
            "signal_peak": float(np.max(np.abs(truth))), "signal_rms": float(np.sqrt(np.mean(truth ** 2))),
            "hold": _hold(truth_all[:-1, j], X[1:, j], next_fresh[:-1, j], answered[:-1], phys[:-1, j],
                          V[:-1, j])}
        if lim:
            ident[name]["at_or_below_table7"] = bool(ident[name]["rmse"] <= t7["rmse"])
    ident["scored"] = [[name, unit] for name, _j, unit in scored_states(plan.scenario)]
    if not lim:
        ident["truth"] = "the recording's x(k+1)"
        ident["note"] = (f"identifier {plan.scenario.identifier}; truth: the recorded trajectory "
                         f"{plan.scenario.trajectory}")
    elif plan.scenario.trajectory:
        ident["truth"] = "the trajectory file's x(k+1)"
        ident["note"] = (f"truth: the recorded trajectory {plan.scenario.trajectory}; compare with Table 7 through "
                         "the signals' scale")
    else:
        ident["truth"] = "the noise-free x(k+1)"
        ident["note"] = (
            "the LIM parameters are pyrhonn's PROPOSED set (the Lab-Volt table was not found): compare with "
            "Table 7 through the signals' scale, not as the same motor")
    return ident


def scored_states(sc: Any) -> list[tuple[str, int, str]]:
    """The states a scenario's report scores, as (name, state index, unit): the LIM's position and velocity
    (Table 7's), or every state of another identifier, by its config's name (unit unknown: "")."""
    if not sc.identifier:
        return [("position", 0, "m"), ("velocity", 1, "m/s")]
    return [(name, j, "") for j, name in enumerate(sc.identifier_file().state_names)]


def _hold(truth: np.ndarray, frame: np.ndarray, fresh: np.ndarray, answered: np.ndarray,
          est: np.ndarray, sampled: np.ndarray) -> dict[str, Any]:
    """For cycles k = 0..N-2: the next frame's value ``frame`` (held or
    fresh) and the estimate ``est`` against the truth x(k+1); ``sampled``:
    whether x(k) itself was measured; see :func:`_identification`."""
    held = answered & ~fresh
    end = answered & fresh & ~sampled         # made at a hold's last sample: the free run's end
    gap = np.abs(frame - truth)
    rms = (lambda a: float(np.sqrt(np.mean(a ** 2)))) if held.any() else (lambda a: math.nan)
    return {"cycles": int(held.sum()), "travel_max": float(gap[held].max()) if held.any() else 0.0,
            "frames_rmse": float(np.sqrt(np.mean(gap[answered] ** 2))) if answered.any() else math.nan,
            "frames_rmse_inside": rms(gap[held]), "estimate_rmse_inside": rms(est[held] - truth[held]),
            "end_error_max": float(np.max(np.abs(est[end] - truth[end]))) if end.any() else None}


def compare_runs(recorded: dict[str, Any], replayed: dict[str, Any], log: str) -> dict[str, Any]:
    """Every estimate of a replay against the recorded run it replayed (both
    :func:`score` results of the same scenario), cycle by cycle over the
    cycles answered in both: ``equal`` when every state of every such
    estimate is the same value (the regression check of ``hil replay
    --from-log``); the largest difference per state, the first differing
    cycle, and the cycles answered in one run only (lost or missing in the
    other, which the accounting of each run already explains)."""
    states = replayed.get("states") or ["Qm", "V", "LambdaA", "LambdaB", "Ia", "Ib"]
    ka, ea = recorded["_series"]["k"], np.asarray(recorded["_series"]["est"])
    kb, eb = replayed["_series"]["k"], np.asarray(replayed["_series"]["est"])
    common, ia, ib = np.intersect1d(ka, kb, assume_unique=True, return_indices=True)
    a, b = ea[ia], eb[ib]                  # decoded from Estimate frames: always finite
    diff = np.abs(a - b)
    same = np.all(diff == 0.0, axis=1)
    first = None
    if not same.all():
        i = int(np.argmin(same))
        first = {"cycle": int(common[i]), "recorded": a[i].tolist(), "replayed": b[i].tolist()}
    return {"log": log, "compared": int(common.size), "differ": int((~same).sum()),
            "only_recorded": int(np.setdiff1d(ka, kb).size), "only_replayed": int(np.setdiff1d(kb, ka).size),
            "max_abs_diff": {name: float(diff[:, j].max()) if common.size else 0.0
                             for j, name in enumerate(states)},
            "first_difference": first, "equal": bool(common.size > 0 and same.all())}


def _kernel_losses(f: dict[str, Any], fw: dict[str, Any] | None, n_foreign: int,
                   meta: dict[str, Any]) -> dict[str, Any]:
    """The frames' entries for the losses a busy host's kernel caused
    (hil.accounting): the counted ones no longer missing."""
    split = kernel_losses(f, fw, n_foreign, meta)
    counted = split["lost_to_firmware"] + split["rejected_after_loss"] + split["lost_from_firmware"]
    return {"kernel_drops": split["kernel_drops"], "lost_to_firmware": split["lost_to_firmware"],
            "rejected_after_loss": split["rejected_after_loss"], "lost_from_firmware": split["lost_from_firmware"],
            "missing": f["missing"] - counted}


HEALTH_SAMPLES_MAX = 400  #: the offline twin's filter health is sampled at most about this many times a run


def _reference_check(config: Any, meas_data: dict[int, bytes], accepted: np.ndarray, answered: np.ndarray,
                     raw: np.ndarray, unknown_from: int | None = None, protocol: Any = None
                     ) -> tuple[dict, dict[str, Any] | None]:
    """Identifier.run (float32) on the decoded frames the firmware stepped
    on (``accepted``, hil.accounting.stepped: whether or not their estimate
    reached the rig), restarted at every gap as the firmware does, scaled as
    the DBC, compared on the answered ones before ``unknown_from``, the first
    cycle whose fate the rig cannot tell (``checked`` then stops short of the
    answered count); and the offline twin's filter health over the run
    (:func:`_health_series`), None when it stepped on no frame."""
    from pyrhonn import Identifier
    from pyrhonn.firmware import lim_protocol

    proto = protocol if protocol is not None else lim_protocol()

    if unknown_from is not None:
        accepted, answered = accepted.copy(), answered.copy()
        accepted[unknown_from:] = answered[unknown_from:] = False

    E = proto.database.get_message_by_name("Estimate")
    n, m = len(proto.states), len(proto.inputs)
    ks = np.flatnonzero(accepted)
    if ks.size == 0 or not answered.any():
        return {"checked": 0, "mismatches": 0, "equal": False, "unknown_from": unknown_from}, None
    X = np.empty((ks.size, n), dtype=np.float32)
    U = np.empty((ks.size, m), dtype=np.float32)
    V = np.empty((ks.size, n), dtype=bool)
    for i, k in enumerate(ks):
        X[i], U[i], V[i] = proto.decode_measurement(meas_data[int(k)])
    # the firmware restarts its identifier on the first frame it accepts after a gap (no learning across it)
    ident, parts = Identifier(config), []
    every = max(1, -(-ks.size // HEALTH_SAMPLES_MAX))
    health: list[tuple[int, list[Any]]] = []
    for i, seg in enumerate(np.split(np.arange(ks.size), np.flatnonzero(np.diff(ks) > 1) + 1)):
        if i:
            ident.restart()
        for chunk in np.array_split(seg, -(-seg.size // every)):   # the same bits as one run (streaming)
            parts.append(ident.run(X[chunk], U[chunk], V[chunk]))
            health.append((int(ks[chunk[-1]]), ident.healths))
    xhat = np.concatenate(parts)
    on = answered[ks]
    ks, xhat = ks[on], xhat[on]
    want = np.empty_like(raw[ks])
    for j, name in enumerate(proto.estimate_signals):
        sig = E.get_signal_by_name(name)
        lo, hi = int(sig.scaled_to_raw(sig.minimum)), int(sig.scaled_to_raw(sig.maximum))
        want[:, j] = [min(max(sig.scaled_to_raw(float(v)), lo), hi) for v in xhat[:, j]]
    bad = np.any(want != raw[ks], axis=1)
    return ({"checked": int(ks.size), "mismatches": int(bad.sum()), "equal": bool(not bad.any()),
             "unknown_from": unknown_from, "first_mismatch_cycle": int(ks[np.argmax(bad)]) if bad.any() else None},
            _health_series(health))


def _health_series(samples: list[tuple[int, list[Any]]]) -> dict[str, Any]:
    """The offline twin's filter health (Identifier.healths, the firmware's rhonn_get_health bit for bit)
    after each chunk of frames: ``cycle`` (S,), and per field (S, neurons): ``nis`` (the last update's
    e^2 / s), ``trace_p``, and the counters ``rejected`` (refused updates), ``resets``, ``updates`` and
    ``gated`` (updates the innovation gate skipped)."""
    cycles = np.array([k for k, _ in samples], dtype=np.int64)
    out: dict[str, Any] = {"cycle": cycles}
    counts = ("rejected", "resets", "updates", "gated")
    for name in ("nis", "trace_p", *counts):
        out[name] = np.array([[getattr(h, name) for h in hs] for _, hs in samples],
                             dtype=np.int64 if name in counts else np.float64)
    return out
