"""Frames a busy host lost: which Measurements the firmware stepped on, and
where the unanswered ones went.

Over udp_multicast a datagram that reaches a full receive queue is dropped
by the kernel: a Measurement on its way to the firmware, or an Estimate on
its way back to the rig. Both happen when a process is descheduled for long
enough on a loaded host. The run then has cycles the rig sent and never got
an answer for; this module accounts for each of them from evidence, not
from the assumption that nothing was lost:

- **the firmware's own counts** (Diagnostics, requested before and after
  the run): ``measurements`` it stepped on and Measurements it ``rejected``.
  What it received is their sum, so ``sent + foreign - received`` never
  reached it (*lost to the firmware*); its Seq-jump rejections beyond the
  scenario's own (one per injected loss run) are the frames that followed
  such a loss (*rejected after a loss*: the protocol refuses them); and
  ``measurements - answered`` Estimates never reached the rig (*lost from
  the firmware*).
- **the kernel's drop counters** of both sockets (``Recording.meta
  ["kernel_drops"]``, hil.transport): a frame counted lost must have been
  dropped by a kernel, so each loss is at most the drops counted on the
  socket it was bound for (a socket also drops the other frames it gets, so
  the counters are upper bounds). Losses without such a count stay
  *missing*.
- **each Estimate's Seq and Resync flag**: Estimate k says the firmware
  stepped on Measurement k, and its Resync flag says whether it stepped on
  k - 1 too (Resync = 0) or rejected it as a Seq jump (Resync = 1). That is
  what lets the bit-exact check replay exactly the Measurements the firmware
  stepped on, when some Estimates never arrived.
"""
from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["kernel_losses", "stepped"]


def _drops(meta: dict[str, Any]) -> dict[str, int] | None:
    d = meta.get("kernel_drops")
    if not isinstance(d, dict) or set(d) != {"rig", "firmware"}:
        return None
    if not all(isinstance(v, int) and not isinstance(v, bool) and v >= 0 for v in d.values()):
        return None
    return {"rig": d["rig"], "firmware": d["firmware"]}


def kernel_losses(frames: dict[str, Any], fw: dict[str, Any] | None, n_foreign: int,
                  meta: dict[str, Any]) -> dict[str, Any]:
    """Split the unanswered cycles that no injected loss explains (``frames
    ["missing"]`` so far) into frames lost to the firmware, rejected after
    such a loss and lost from the firmware, each corroborated by the
    firmware's Diagnostics ``fw`` and the kernel's drop counters in
    ``meta``; what is not corroborated stays missing. The counts, and
    whether the split holds (``explained``)."""
    drops = _drops(meta)
    out: dict[str, Any] = {"kernel_drops": drops, "lost_to_firmware": 0, "rejected_after_loss": 0,
                           "lost_from_firmware": 0, "explained": frames["missing"] == 0}
    if frames["missing"] == 0 or fw is None or drops is None:
        return out
    received = fw["measurements"] + fw["rejected"]
    to_fw = frames["sent"] + n_foreign - received
    after = fw["rejected"] - frames["rejected_seq_jump"] - n_foreign
    from_fw = fw["measurements"] - frames["answered"]
    # each loss run makes the next frame that arrives a Seq jump: at most one rejection per lost frame
    ok = (min(to_fw, after, from_fw) >= 0 and after <= to_fw and to_fw <= drops["firmware"]
          and from_fw <= drops["rig"] and to_fw + after + from_fw == frames["missing"])
    if ok:
        out.update(lost_to_firmware=to_fw, rejected_after_loss=after, lost_from_firmware=from_fw, explained=True)
    return out


def stepped(was_sent: np.ndarray, answered: np.ndarray, resync: np.ndarray, expect_reject: np.ndarray,
            frames: dict[str, Any], measurements: int | None) -> tuple[np.ndarray, int | None]:
    """The cycles whose Measurement the firmware stepped on, and the first
    cycle from which that is not known (None: known throughout).

    Every sent cycle but the expected Seq jumps when the firmware got every
    frame (no unanswered cycle, or the only losses counted are Estimates
    lost from the firmware); the answered cycles when every Estimate it sent
    arrived. With losses both ways: every answered cycle; a cycle k - 1
    before an answered one when Estimate k's Resync flag is 0 (the firmware
    stepped on k - 1 and its Estimate was lost on the way) and not when it
    is 1 (k - 1 was a Seq jump after a loss, rejected); the rest not, when
    that makes the firmware's own count ``measurements`` (then each of them
    was lost before the firmware or rejected); else they are unknown."""
    plain = was_sent & ~expect_reject
    if not (plain & ~answered).any():
        return plain, None
    counted = frames.get("missing") == 0 and measurements is not None
    if counted and frames.get("lost_to_firmware") == 0 and frames.get("rejected_after_loss") == 0:
        return plain, None
    if counted and frames.get("lost_from_firmware") == 0:
        return answered.copy(), None
    out = answered.copy()
    known = answered | ~was_sent
    ks = np.flatnonzero(answered)
    ks = ks[ks > 0]
    prev = ks - 1
    out[prev] |= ~resync[ks] & was_sent[prev]
    known[prev] = True
    if measurements is not None and int(out.sum()) == measurements:
        return out, None
    left = np.flatnonzero(~known)
    return out, (int(left[0]) if left.size else None)
