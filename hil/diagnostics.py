"""The firmware's Diagnostics frame as the rig reads it: decoded in the
protocol its log was recorded in, with every time at the top of its range
flagged as saturated (a lower bound, never a measurement).

Protocol ``rhonn_id 2.1`` (the DBC in firmware_sim) widened StepTimeMax from
16 to 24 bits (10 ns per LSB: 655.35 us became 167,772.15 us) and moved the
signals after it up by one byte. Logs recorded before (sidecar format 2 and
earlier) hold ``rhonn_id 2.0`` Diagnostics frames, decoded here with that
layout, kept as it was, so that those logs still score. Measurement,
Estimate, Control and Health frames did not change.

Protocol ``rhonn_id 2.2`` widened Health from 32 to 48 bytes to carry Gated
(the updates the innovation gate skipped); its Diagnostics frame is 2.1's,
so logs of 2.1 (SAME_DIAGNOSTICS) decode with this build's DBC, their
Health frames without Gated (pyrhonn.firmware.decode_health).
"""
from __future__ import annotations

import functools
from typing import Any

__all__ = ["LEGACY_PROTOCOL", "SAME_DIAGNOSTICS", "TIMES", "decode", "saturated_names"]

LEGACY_PROTOCOL = "rhonn_id 2.0"
#: earlier protocols whose Diagnostics frame is this build's (only Health changed since)
SAME_DIAGNOSTICS = ("rhonn_id 2.1",)
TIMES = ("CycleTime", "StepTime", "StepTimeMax")  #: the times in us; every other signal is a count or a flag

# The Diagnostics frame of rhonn_id 2.0, as its DBC defined it (frozen: only old logs use it).
_LEGACY_DBC = """VERSION "rhonn_id 2.0"

BU_: RIG RHONN

BO_ 304 Diagnostics: 32 RHONN
 SG_ Counter : 0|8@1+ (1,0) [0|255] "" RIG
 SG_ LastSeq : 8|16@1+ (1,0) [0|65535] "" RIG
 SG_ CycleTime : 24|16@1+ (0.01,0) [0|655.35] "us" RIG
 SG_ StepTime : 40|16@1+ (0.01,0) [0|655.35] "us" RIG
 SG_ StepTimeMax : 56|16@1+ (0.01,0) [0|655.35] "us" RIG
 SG_ Overruns : 72|16@1+ (1,0) [0|65535] "" RIG
 SG_ Rejected : 88|16@1+ (1,0) [0|65535] "" RIG
 SG_ LastReject : 104|8@1+ (1,0) [0|255] "" RIG
 SG_ StepErrors : 112|16@1+ (1,0) [0|65535] "" RIG
 SG_ StepStatus : 128|4@1+ (1,0) [0|15] "" RIG
 SG_ Learning : 132|1@1+ (1,0) [0|1] "" RIG
 SG_ Started : 133|1@1+ (1,0) [0|1] "" RIG
 SG_ WeightsOpen : 134|1@1+ (1,0) [0|1] "" RIG
 SG_ Synced : 135|1@1+ (1,0) [0|1] "" RIG
 SG_ Measurements : 136|32@1+ (1,0) [0|4294967295] "" RIG
 SG_ SeqErrors : 168|16@1+ (1,0) [0|65535] "" RIG
 SG_ LostFrames : 184|32@1+ (1,0) [0|4294967295] "" RIG
 SG_ RxDrops : 216|32@1+ (1,0) [0|4294967295] "" RIG
"""


@functools.cache
def _message(protocol: str) -> Any:
    """The cantools Diagnostics message of ``protocol`` (this build's DBC, or the legacy one)."""
    import cantools

    from pyrhonn.firmware import database

    db = database()
    if protocol == db.version or protocol in SAME_DIAGNOSTICS:
        return db.get_message_by_name("Diagnostics")
    if protocol == LEGACY_PROTOCOL:
        legacy = cantools.database.load_string(_LEGACY_DBC, database_format="dbc")
        assert isinstance(legacy, cantools.database.can.Database)  # a DBC is a CAN database
        return legacy.get_message_by_name("Diagnostics")
    raise ValueError(f"protocol: Diagnostics of {protocol!r} cannot be decoded (this hil knows {db.version!r}, "
                     f"{', '.join(map(repr, SAME_DIAGNOSTICS))} and {LEGACY_PROTOCOL!r})")


def decode(data: bytes, protocol: str | None = None) -> dict[str, Any]:
    """A Diagnostics payload as its signals (times in us as floats, the rest as
    ints) plus ``saturated``: the names of the times at the top of their range
    (the firmware saturated them: the time was at least that). ``protocol``:
    the DBC version the frame was sent in (None: this build's)."""
    from pyrhonn.firmware import database

    msg = _message(protocol or database().version)
    raw = msg.decode(bytes(data), scaling=False, decode_choices=False)
    out: dict[str, Any] = {}
    for sig in msg.signals:
        v = raw[sig.name]
        out[sig.name] = float(sig.raw_to_scaled(v)) if sig.name in TIMES else int(v)
    out["saturated"] = saturated_names(raw, msg)
    return out


def saturated_names(raw: dict[str, int], msg: Any) -> list[str]:
    """The times whose raw value is the largest their signal can carry."""
    return [sig.name for sig in msg.signals if sig.name in TIMES and int(raw[sig.name]) >= (1 << sig.length) - 1]
