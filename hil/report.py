"""A scored run as a terminal table, JSON, and PNG plots (hil.figures)."""
from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from pyrhonn import atomic

from .figures import figures

__all__ = ["figures", "step_time", "table", "to_json", "write"]


def _clean(obj: Any) -> Any:
    if isinstance(obj, dict):
        # keys as JSON has them (str); "_"-prefixed ones are in-memory series, not for the report
        return {str(k): _clean(v) for k, v in obj.items() if not str(k).startswith("_")}
    if isinstance(obj, (list, tuple)):
        return [_clean(v) for v in obj]
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (np.floating, float)):
        v = float(obj)
        return v if math.isfinite(v) else None
    if isinstance(obj, np.bool_):
        return bool(obj)
    return obj


def to_json(report: dict[str, Any]) -> str:
    return json.dumps(_clean(report), indent=1, sort_keys=True)


LABEL_WIDTH = 24  #: the label column of the table; its values start after it


def _label(text: str) -> str:
    """A row's label, padded to the label column, and at least one space before the value."""
    return text.ljust(LABEL_WIDTH - 1) + " "


def step_time(fw: dict[str, Any], key: str = "step_time_max") -> str:
    """The firmware's StepTimeMax (``key``: or its last StepTime) from its Diagnostics, in us; a saturated
    one, at the top of its signal's range, as the lower bound it is: ">= 655.4 us, saturated"."""
    value = fw[key + "_us"]
    if fw.get(key + "_saturated"):
        return f">= {value:,.1f} us, saturated"
    return f"{value:,.1f} us"


def _fmt(stats: dict, keys=("min", "avg", "p99", "p99.9", "max")) -> str:
    if not stats or not stats.get("n"):
        return "-"
    return "  ".join(f"{k} {stats[k]:9.1f}" for k in keys if k in stats)


def _stamp(kind: str | None) -> str:
    return ("the kernel's receive timestamp (the estimate at the rig's socket)" if kind == "kernel"
            else "when the rig's recv returned")


def _e(v: float | None) -> str:
    return f"{'-':>11}" if v is None else f"{v:11.3e}"


def _inside(hold: dict[str, Any], unit: str) -> str:
    """The hold line's tail: inside the hold, the identifier against the held frames."""
    est, frames = hold.get("estimate_rmse_inside"), hold.get("frames_rmse_inside")
    if est is None or frames is None or not (math.isfinite(est) and math.isfinite(frames)) or frames <= 0:
        return ""
    end = hold.get("end_error_max")
    tail = "" if end is None else f"; the estimate made at the hold's last sample is {end:.3e} {unit} off"
    return (f"; inside the hold the estimates are {est:.3e} {unit} RMSE off it, the held frames {frames:.3e} "
            f"({100 * est / frames:.1f} %)" + tail)


_WHY = {"held": "held", "derived": "derived from a held or missing reading"}


def _not_valid(counts: dict[str, dict[str, int]] | None) -> list[str]:
    """The line saying how many samples the rig sent not valid, per signal and why."""
    if not counts:
        return []
    parts = [f"{name} {sum(why.values())} (" + ", ".join(f"{n} {_WHY.get(k, k)}" for k, n in why.items() if n) + ")"
             for name, why in counts.items()]
    return ["  not valid: " + "; ".join(parts) + " - neither learnt nor used: the identifier predicts them from "
            "its own outputs"]


def _scored(ident: dict[str, Any]) -> list[tuple[str, str]]:
    """The scored states and their units (reports before another identifier could be replayed: the LIM's)."""
    return [(str(n), str(u)) for n, u in ident.get("scored", [["position", "m"], ["velocity", "m/s"]])]


def table(report: dict[str, Any], *, timing_note: str | None = None) -> str:
    f = report["frames"]
    served = (report.get("firmware_side") or {}).get("firmware")
    lines = [f"HIL replay over {report['transport']} ({report['channel']}"
             f"{', firmware ' + served if served else ''}): {report['cycles']} cycles at "
             f"{report['scenario']['period'] * 1e3:g} ms, seed {report['scenario']['seed']}"
             + (f", trajectory {report['scenario']['trajectory']}" if report['scenario'].get('trajectory') else
                ", the simulated LIM"),
             "",
             f"{_label('frames')}sent {f['sent']}  lost (injected) {f['lost_injected']}  answered {f['answered']}  "
             f"rejected (Seq jump) {f['rejected_seq_jump']}  missing {f['missing']}  late {f['late']}",
             f"{_label('')}duplicates {f['duplicates']}  unexpected {f['unexpected']}  foreign sent "
             f"{sum(f['foreign_sent'].values())}  step errors {f['step_errors']}  -> "
             f"{'all accounted for' if f['accounted'] else 'NOT ACCOUNTED FOR'}"]
    if report.get("partial"):
        lines.append(f"{_label('')}PARTIAL LOG: {report['partial']}; the cycles it never sent count as unaccounted")
    lost = [f.get(k, 0) for k in ("lost_to_firmware", "rejected_after_loss", "lost_from_firmware")]
    drops = f.get("kernel_drops")
    if any(lost) or (drops and any(drops.values())):
        lines.append(f"{_label('')}full receive queues: lost to the firmware {lost[0]} (then rejected as Seq jumps "
                     f"{lost[1]}), lost from the firmware {lost[2]}; datagrams the kernel dropped"
                     + (f": rig {drops['rig']}, firmware {drops['firmware']}" if drops else ": not counted here"))
    drain = report.get("drain") or {}
    if drain.get("capped"):
        lines.append(f"{_label('')}the drain stopped after {drain['s']:.1f} s with estimates still coming in: "
                     "the missing ones may have been queued unread (a larger --drain reads them)")
    fw = report.get("firmware")
    if fw:
        lines.append(f"{_label('firmware (Diagnostics)')}measurements {fw['measurements']}  rejected {fw['rejected']}  "
                     f"seq errors {fw['seq_errors']}  lost {fw['lost_frames']}  kernel drops {fw['rx_drops']}  "
                     f"overruns {fw['overruns']}  step max {step_time(fw)}")
    for h in report.get("health") or []:
        def num(v: float | None) -> str:
            return "saturated" if v is None else f"{v:.3g}"
        lines.append(f"{_label('filter health' if h['neuron'] == 0 else '')}neuron {h['neuron']}  e^2/s {num(h['nis'])}  "
                     f"trace P {num(h['trace_p'])}  updates {h['updates']}  refused {h['rejected']}  "
                     f"resets {h['resets']}  bounded {h['bounded']}"
                     + ("" if h.get("gated") is None else f"  gated {h['gated']}"))
    ident = report.get("identification")
    if ident:
        lines += ["", f"{_label('identification')}{'RMSE':>11}{'abs. dev.':>11}{'Table 7':>11}{'Table 7':>11}"
                      f"{'RMSE':>11}{'RMSE vs':>11}{'sensor':>11}{'peak |x|':>10}",
                  f"{_label('')}{'(truth)':>11}{'(truth)':>11}{'RMSE':>11}{'abs. dev.':>11}{'no hold':>11}"
                  f"{'measured':>11}{'RMSE':>11}",
                  *(f"{_label('  ' + name + (' (' + unit + ')' if unit else ''))}"
                    f"{_e(ident[name]['rmse'])}{_e(ident[name]['absolute_deviation'])}"
                    f"{_e(ident[name]['table7_rmse'])}{_e(ident[name]['table7_absolute_deviation'])}"
                    f"{_e(ident[name]['outside_hold']['rmse'])}{_e(ident[name]['vs_measurement']['rmse'])}"
                    f"{_e(ident[name]['measurement_vs_truth']['rmse'])}"
                    f"{ident[name]['signal_peak']:10.3g}"
                    for name, unit in _scored(ident)),
                  f"  (truth: against {ident['truth']}; no hold: the same, the cycles whose sample and target are "
                  "both measured; vs measured: against the next Measurement frame where it is fresh; sensor: that Measurement "
                  "frame against the truth)",
                  *(f"  hold: {name} held for {ident[name]['hold']['cycles']} cycles, in which it moved up to "
                    f"{ident[name]['hold']['travel_max']:.3g} {unit} unobserved; the frames themselves, held values "
                    f"included, are {ident[name]['hold']['frames_rmse']:.3e} {unit} RMSE off the truth"
                    + (f" (Table 7: {ident[name]['table7_rmse']:.3e})" if ident[name]["table7_rmse"] is not None
                       else "") + _inside(ident[name]["hold"], unit)
                    for name, unit in _scored(ident) if ident[name]["hold"]["cycles"]),
                  *_not_valid(report.get("not_valid")),
                  f"  note: {ident['note']}"]
    be = report.get("bit_exact")
    if be:
        lines.append(f"{_label('bit exact vs offline')}{be['checked']} estimates checked against Identifier.run: "
                     f"{'equal' if be['equal'] else str(be['mismatches']) + ' differ'}"
                     + (f"; not checked from cycle {be['unknown_from']} on (frames lost both ways: which ones the "
                        "firmware stepped on is not known)" if be.get("unknown_from") is not None else ""))
    reg = report.get("regression")
    if reg:
        if reg["equal"]:
            verdict = "equal"
        elif not reg["compared"]:
            verdict = "NO CYCLE ANSWERED IN BOTH"
        else:
            worst = max(reg["max_abs_diff"], key=reg["max_abs_diff"].get)
            verdict = (f"{reg['differ']} DIFFER (first at cycle {reg['first_difference']['cycle']}; largest "
                       f"|difference| {reg['max_abs_diff'][worst]:.3g} in {worst})")
        extra = "" if not (reg["only_recorded"] or reg["only_replayed"]) else (
            f" ({reg['only_recorded']} answered in the recorded run only, {reg['only_replayed']} in this one only)")
        lines.append(f"{_label('vs recorded run')}{reg['compared']} estimates compared with {reg['log']}: {verdict}{extra}")
    lat = report["latency_us"]
    lines += ["", f"{_label('timing (us)')}",
              f"{_label('  latency send->est.')}{_fmt(lat)}",
              f"{_label('')}within one period: {100 * lat['within_period']:.2f} %"
              + (f" (picked up by the rig process within one period: {100 * lat['within_period_picked_up']:.2f} %)"
                 if "within_period_picked_up" in lat else "") if lat.get("n") else "",
              f"{_label('  (stamped at)')}{_stamp(lat.get('stamp'))}",
              f"{_label('  rig pick-up')}{_fmt(report.get('rig_pickup_us', {}))}",
              f"{_label('  rig lateness')}{_fmt(report['rig_lateness_us'])}",
              f"{_label('  rig period jitter')}{_fmt(report['rig_period_jitter_us'], ('avg', 'p99', 'p99.9', 'max_abs'))}"]
    if report.get("_verdicts"):
        from .verdicts import lines as verdict_lines

        lines += ["", *verdict_lines(*report["_verdicts"])]
    if timing_note:
        lines += ["", f"note: {timing_note}"]
    return "\n".join(ln.rstrip() for ln in lines if ln is not None) + "\n"


def write(report: dict[str, Any], out: str | Path, *, timing_note: str | None = None) -> list[Path]:
    """report.json, report.txt and the PNGs into ``out``, each replaced whole, the folder marked
    incomplete (pyrhonn.atomic.MARKER) until the last is in place."""
    with atomic.output_folder(out, "pyrhonn hil") as folder:
        paths = [atomic.write_text(folder / "report.json", to_json(report) + "\n"),
                 atomic.write_text(folder / "report.txt", table(report, timing_note=timing_note))]
        return paths + figures(report, folder)
