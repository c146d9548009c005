"""Pass/fail verdicts of a replay for CI: thresholds against the measured
values, the run's own checks beside them, a JUnit XML file and a JSON summary.

A :class:`Thresholds` (the ``[thresholds]`` table of a scenario file,
:mod:`hil.scenario_file`) sets upper limits on what a report measures:

- ``rmse.<state>``: the estimate's RMSE against the truth x(k+1) (the
  report's ``RMSE (truth)`` column), in the state's unit;
- ``bridging_ratio.<state>``: inside the measurement hold, the estimate's
  RMSE over the held frames' own (the report's ``(…%)`` figure, as a
  fraction): 1 is no better than holding the last reading, 0 a perfect
  bridge;
- ``lost_frames``: frames the bus lost, beyond the scenario's injected loss
  (lost to or from the firmware at a full receive queue, missing, never
  sent);
- ``latency_us.<p>`` (``p50``, ``p99``, ``p99.9``, ``max``, ``avg``): the
  latency Measurement sent -> Estimate back, in microseconds. Not judged on
  the ``virtual`` bus, whose firmware is a thread of the rig's process: such
  a verdict is *skipped*, with that reason.

:func:`evaluate` adds the run's own checks (every frame accounted for, the
estimates bit-exact with ``Identifier.run``, a ``--from-log`` regression
equal) and gives one :class:`Verdict` per check: ``pass``, ``fail`` or
``skipped``. A limit whose value the run did not measure (no hold to bridge,
fewer than two estimates) fails: a CI gate must not pass on what it never saw.
"""
from __future__ import annotations

import json
import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

__all__ = ["LATENCY_KEYS", "Thresholds", "Verdict", "evaluate", "failed", "junit_xml", "summary"]

#: the latency statistics a threshold may name (hil.score.stats_us)
LATENCY_KEYS = ("p50", "p99", "p99.9", "max", "avg")
#: why latency is not judged on the virtual bus
VIRTUAL_LATENCY = ("not judged on the virtual bus: its firmware is a thread of the rig's process, so the latency "
                   "is Python's thread hand-overs, not a bus; judge it on udp_multicast or socketcan")


def _limits(where: str, table: Any, keys: tuple[str, ...] | None) -> dict[str, float]:
    from pyrhonn.validation import check_real, fail

    if not isinstance(table, dict):
        raise fail(where, f"expected a table of limits, got {type(table).__name__} {table!r}")
    out = {}
    for key, value in table.items():
        if keys is not None and key not in keys:
            raise fail(f"{where}.{key}", f"unknown; expected one of {', '.join(keys)}")
        out[key] = check_real(f"{where}.{key}", value, nonnegative=True)
    return out


@dataclass(frozen=True)
class Thresholds:
    """Upper limits on a run's measured values (see the module docstring).
    Empty: no limit, only the run's own checks."""

    rmse: dict[str, float] = field(default_factory=dict)
    bridging_ratio: dict[str, float] = field(default_factory=dict)
    lost_frames: int | None = None
    latency_us: dict[str, float] = field(default_factory=dict)

    @classmethod
    def from_dict(cls, d: Any, where: str = "thresholds") -> Thresholds:
        from pyrhonn.validation import check_int, fail

        if not isinstance(d, dict):
            raise fail(where, f"expected a table, got {type(d).__name__}")
        known = ("rmse", "bridging_ratio", "lost_frames", "latency_us")
        unknown = sorted(set(d) - set(known))
        if unknown:
            raise fail(f"{where}.{unknown[0]}", f"unknown; expected one of {', '.join(known)}")
        lost = d.get("lost_frames")
        return cls(rmse=_limits(f"{where}.rmse", d.get("rmse", {}), None),
                   bridging_ratio=_limits(f"{where}.bridging_ratio", d.get("bridging_ratio", {}), None),
                   lost_frames=None if lost is None else check_int(f"{where}.lost_frames", lost, 0),
                   latency_us=_limits(f"{where}.latency_us", d.get("latency_us", {}), LATENCY_KEYS))

    def check_states(self, states: tuple[str, ...], where: str = "thresholds") -> None:
        """Refuse a per-state limit on a state the report does not score."""
        from pyrhonn.validation import fail

        for kind, limits in (("rmse", self.rmse), ("bridging_ratio", self.bridging_ratio)):
            for name in limits:
                if name not in states:
                    raise fail(f"{where}.{kind}.{name}", f"not a scored state; expected one of {', '.join(states)}")

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"rmse": dict(self.rmse), "bridging_ratio": dict(self.bridging_ratio),
                             "latency_us": dict(self.latency_us)}
        if self.lost_frames is not None:
            d["lost_frames"] = self.lost_frames
        return d


@dataclass(frozen=True)
class Verdict:
    """One check: ``status`` is "pass", "fail" or "skipped"; ``limit`` None for the run's own checks."""

    name: str
    measured: float | bool | None
    limit: float | None
    status: str
    reason: str = ""
    unit: str = ""

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "measured": self.measured, "limit": self.limit, "status": self.status,
                "reason": self.reason, "unit": self.unit}


def _at_most(name: str, measured: float | None, limit: float, unit: str, missing: str) -> Verdict:
    if measured is None or not math.isfinite(measured):
        return Verdict(name, None, limit, "fail", f"not measured: {missing}", unit)
    ok = measured <= limit
    return Verdict(name, measured, limit, "pass" if ok else "fail",
                   "" if ok else f"{measured:.4g} {unit} is above the limit {limit:.4g}".replace("  ", " "), unit)


def _bridging(hold: dict[str, Any] | None) -> float | None:
    if not hold or not hold.get("cycles"):
        return None
    est, frames = hold.get("estimate_rmse_inside"), hold.get("frames_rmse_inside")
    if est is None or frames is None or not (math.isfinite(est) and math.isfinite(frames)) or frames <= 0:
        return None
    return float(est / frames)


UNITS = {"position": "m", "velocity": "m/s"}


def lost_frames(frames: dict[str, Any]) -> int:
    """Frames the bus lost, beyond the scenario's injected loss."""
    return int(sum(frames.get(k, 0) for k in ("lost_to_firmware", "lost_from_firmware", "missing",
                                              "lost_unaccounted")))


def evaluate(report: dict[str, Any], thresholds: Thresholds) -> list[Verdict]:
    """Every threshold against its measured value in ``report`` (hil.score.score), then the run's own checks."""
    out: list[Verdict] = []
    ident = report.get("identification") or {}
    for state, limit in thresholds.rmse.items():
        out.append(_at_most(f"rmse.{state}", (ident.get(state) or {}).get("rmse"), limit, UNITS.get(state, ""),
                            "fewer than two estimates came back"))
    for state, limit in thresholds.bridging_ratio.items():
        out.append(_at_most(f"bridging_ratio.{state}", _bridging((ident.get(state) or {}).get("hold")), limit, "",
                            f"no held {state} frame was answered (no hold in this scenario?)"))
    if thresholds.lost_frames is not None:
        out.append(_at_most("lost_frames", lost_frames(report["frames"]), thresholds.lost_frames, "frames", ""))
    lat = report.get("latency_us") or {}
    for key, limit in thresholds.latency_us.items():
        name = f"latency_us.{key}"
        if report.get("transport") == "virtual":
            out.append(Verdict(name, lat.get(key), limit, "skipped", VIRTUAL_LATENCY, "us"))
        else:
            out.append(_at_most(name, lat.get(key), limit, "us", "no estimate came back"))
    f = report["frames"]
    out.append(Verdict("frames_accounted", bool(f["accounted"]), None, "pass" if f["accounted"] else "fail",
                       "" if f["accounted"] else "not every cycle is accounted for (see the frames line)"))
    be = report.get("bit_exact")
    if be is not None:
        out.append(Verdict("bit_exact", bool(be["equal"]), None, "pass" if be["equal"] else "fail",
                           "" if be["equal"] else f"{be['mismatches']} of {be['checked']} estimates differ from "
                                                  "Identifier.run"))
    reg = report.get("regression")
    if reg is not None:
        out.append(Verdict("vs_recorded_run", bool(reg["equal"]), None, "pass" if reg["equal"] else "fail",
                           "" if reg["equal"] else f"{reg['differ']} of {reg['compared']} estimates differ from "
                                                   f"{reg['log']}"))
    return out


def failed(verdicts: list[Verdict]) -> list[Verdict]:
    return [v for v in verdicts if v.status == "fail"]


def summary(report: dict[str, Any], verdicts: list[Verdict], source: str | None) -> dict[str, Any]:
    """The JSON summary: the verdicts and what ran, without the report's series."""
    bad = failed(verdicts)
    return {"format": "pyrhonn-hil-verdicts 1", "passed": not bad, "failed": [v.name for v in bad],
            "thresholds_from": source, "transport": report.get("transport"), "channel": report.get("channel"),
            "cycles": report.get("cycles"), "scenario": report.get("scenario"),
            "verdicts": [v.to_dict() for v in verdicts]}


def _shown(v: Verdict) -> str:
    if isinstance(v.measured, bool):
        return "yes" if v.measured else "no"
    if v.measured is None:
        return "not measured"
    return f"{v.measured:.6g}" + (f" {v.unit}" if v.unit else "")


def junit_xml(report: dict[str, Any], verdicts: list[Verdict], suite: str) -> str:
    """A JUnit XML document: one testsuite named ``suite``, one testcase per verdict
    (``<failure>`` or ``<skipped>`` with the reason), the measured value and limit in its ``system-out``."""
    root = ET.Element("testsuites", name="pyrhonn hil")
    ts = ET.SubElement(root, "testsuite", name=suite, tests=str(len(verdicts)),
                       failures=str(len(failed(verdicts))),
                       skipped=str(sum(v.status == "skipped" for v in verdicts)), errors="0", time="0")
    props = ET.SubElement(ts, "properties")
    for key in ("transport", "channel", "cycles"):
        ET.SubElement(props, "property", name=key, value=str(report.get(key)))
    for v in verdicts:
        tc = ET.SubElement(ts, "testcase", classname=suite, name=v.name, time="0")
        text = f"measured {_shown(v)}" + ("" if v.limit is None else f", limit {v.limit:.6g}" +
                                          (f" {v.unit}" if v.unit else ""))
        if v.status == "fail":
            ET.SubElement(tc, "failure", message=v.reason or "failed", type="threshold" if v.limit is not None
                          else "check").text = text
        elif v.status == "skipped":
            ET.SubElement(tc, "skipped", message=v.reason)
        ET.SubElement(tc, "system-out").text = text
    ET.indent(root)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def lines(verdicts: list[Verdict], source: str | None) -> list[str]:
    """The report's verdict section: each check beside its measured value and limit."""
    out = ["verdicts" + (f" (thresholds from {source})" if source else " (no thresholds given: the run's own checks)"),
           f"  {'':<22}{'measured':>16}  {'limit':>12}  result"]
    for v in verdicts:
        limit = "" if v.limit is None else f"<= {v.limit:.6g}"
        result = {"pass": "pass", "fail": "FAIL", "skipped": "skipped"}[v.status]
        out.append(f"  {v.name:<22}{_shown(v):>16}  {limit:>12}  {result}" + (f" ({v.reason})" if v.reason else ""))
    bad = failed(verdicts)
    out.append(f"  -> {len(bad)} of {len(verdicts)} FAILED: {', '.join(v.name for v in bad)}" if bad
               else f"  -> all {sum(v.status == 'pass' for v in verdicts)} passed"
               + (f", {sum(v.status == 'skipped' for v in verdicts)} skipped"
                  if any(v.status == "skipped" for v in verdicts) else ""))
    return out


def write_outputs(report: dict[str, Any], verdicts: list[Verdict], source: str | None, *,
                  junit: Path | None, summary_path: Path | None, suite: str) -> list[Path]:
    """``--junit`` and ``--summary``, each replaced whole (pyrhonn.atomic)."""
    from pyrhonn import atomic

    paths = []
    if junit is not None:
        paths.append(atomic.write_text(junit, junit_xml(report, verdicts, suite)))
    if summary_path is not None:
        paths.append(atomic.write_text(summary_path, json.dumps(summary(report, verdicts, source), indent=1,
                                                                allow_nan=False, default=str) + "\n"))
    return paths
