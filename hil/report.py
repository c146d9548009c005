"""A scored run as a terminal table, JSON, and PNG plots (matplotlib Agg):
position and velocity real vs identified (as the paper's Fig. 19-20) and a
latency histogram."""
from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from pyrhonn import atomic

__all__ = ["figures", "table", "to_json", "write"]


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
    return (f"; inside the hold the estimates are {est:.3e} {unit} RMSE off it, the held frames {frames:.3e} "
            f"({100 * est / frames:.1f} %)")


_WHY = {"held": "held", "derived": "derived from a held or missing reading"}


def _not_valid(counts: dict[str, dict[str, int]] | None) -> list[str]:
    """The line saying how many samples the rig sent not valid, per signal and why."""
    if not counts:
        return []
    parts = [f"{name} {sum(why.values())} (" + ", ".join(f"{n} {_WHY.get(k, k)}" for k, n in why.items() if n) + ")"
             for name, why in counts.items()]
    return ["  not valid: " + "; ".join(parts) + " - neither learnt nor used: the identifier predicts them from "
            "its own outputs"]


def table(report: dict[str, Any], *, timing_note: str | None = None) -> str:
    f = report["frames"]
    served = (report.get("firmware_side") or {}).get("firmware")
    lines = [f"HIL replay over {report['transport']} ({report['channel']}"
             f"{', firmware ' + served if served else ''}): {report['cycles']} cycles at "
             f"{report['scenario']['period'] * 1e3:g} ms, seed {report['scenario']['seed']}"
             + (f", trajectory {report['scenario']['trajectory']}" if report['scenario'].get('trajectory') else
                ", the simulated LIM"),
             "",
             f"{'frames':<22}sent {f['sent']}  lost (injected) {f['lost_injected']}  answered {f['answered']}  "
             f"rejected (Seq jump) {f['rejected_seq_jump']}  missing {f['missing']}  late {f['late']}",
             f"{'':<22}duplicates {f['duplicates']}  unexpected {f['unexpected']}  foreign sent "
             f"{sum(f['foreign_sent'].values())}  step errors {f['step_errors']}  -> "
             f"{'all accounted for' if f['accounted'] else 'NOT ACCOUNTED FOR'}"]
    if report.get("partial"):
        lines.append(f"{'':<22}PARTIAL LOG: {report['partial']}; the cycles it never sent count as unaccounted")
    lost = [f.get(k, 0) for k in ("lost_to_firmware", "rejected_after_loss", "lost_from_firmware")]
    drops = f.get("kernel_drops")
    if any(lost) or (drops and any(drops.values())):
        lines.append(f"{'':<22}full receive queues: lost to the firmware {lost[0]} (then rejected as Seq jumps "
                     f"{lost[1]}), lost from the firmware {lost[2]}; datagrams the kernel dropped"
                     + (f": rig {drops['rig']}, firmware {drops['firmware']}" if drops else ": not counted here"))
    drain = report.get("drain") or {}
    if drain.get("capped"):
        lines.append(f"{'':<22}the drain stopped after {drain['s']:.1f} s with estimates still coming in: "
                     "the missing ones may have been queued unread (a larger --drain reads them)")
    fw = report.get("firmware")
    if fw:
        lines.append(f"{'firmware (Diagnostics)':<22}measurements {fw['measurements']}  rejected {fw['rejected']}  "
                     f"seq errors {fw['seq_errors']}  lost {fw['lost_frames']}  kernel drops {fw['rx_drops']}  "
                     f"overruns {fw['overruns']}  step max {fw['step_time_max_us']:.1f} us")
    for h in report.get("health") or []:
        def num(v: float | None) -> str:
            return "saturated" if v is None else f"{v:.3g}"
        lines.append(f"{'filter health' if h['neuron'] == 0 else '':<22}neuron {h['neuron']}  e^2/s {num(h['nis'])}  "
                     f"trace P {num(h['trace_p'])}  updates {h['updates']}  refused {h['rejected']}  "
                     f"resets {h['resets']}  bounded {h['bounded']}")
    ident = report.get("identification")
    if ident:
        lines += ["", f"{'identification':<22}{'RMSE':>11}{'abs. dev.':>11}{'Table 7':>11}{'Table 7':>11}"
                      f"{'RMSE':>11}{'RMSE vs':>11}{'sensor':>11}{'peak |x|':>10}",
                  f"{'':<22}{'(truth)':>11}{'(truth)':>11}{'RMSE':>11}{'abs. dev.':>11}{'no hold':>11}"
                  f"{'measured':>11}{'RMSE':>11}",
                  *(f"  {name + ' (' + unit + ')':<20}{_e(ident[name]['rmse'])}{_e(ident[name]['absolute_deviation'])}"
                    f"{_e(ident[name]['table7_rmse'])}{_e(ident[name]['table7_absolute_deviation'])}"
                    f"{_e(ident[name]['outside_hold']['rmse'])}{_e(ident[name]['vs_measurement']['rmse'])}"
                    f"{_e(ident[name]['measurement_vs_truth']['rmse'])}"
                    f"{ident[name]['signal_peak']:10.3g}"
                    for name, unit in (("position", "m"), ("velocity", "m/s"))),
                  f"  (truth: against {ident['truth']}; no hold: the same, the cycles whose target is outside "
                  "the hold; vs measured: against the next Measurement frame where it is fresh; sensor: that Measurement "
                  "frame against the truth)",
                  *(f"  hold: {name} held for {ident[name]['hold']['cycles']} cycles, in which it moved up to "
                    f"{ident[name]['hold']['travel_max']:.3g} {unit} unobserved; the frames themselves, held values "
                    f"included, are {ident[name]['hold']['frames_rmse']:.3e} {unit} RMSE off the truth (Table 7: "
                    f"{ident[name]['table7_rmse']:.3e})" + _inside(ident[name]["hold"], unit)
                    for name, unit in (("position", "m"), ("velocity", "m/s")) if ident[name]["hold"]["cycles"]),
                  *_not_valid(report.get("not_valid")),
                  f"  note: {ident['note']}"]
    be = report.get("bit_exact")
    if be:
        lines.append(f"{'bit exact vs offline':<22}{be['checked']} estimates checked against Identifier.run: "
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
        lines.append(f"{'vs recorded run':<22}{reg['compared']} estimates compared with {reg['log']}: {verdict}{extra}")
    lat = report["latency_us"]
    lines += ["", f"{'timing (us)':<22}",
              f"  {'latency send->est.':<20}{_fmt(lat)}",
              f"  {'':<20}within one period: {100 * lat['within_period']:.2f} %"
              + (f" (picked up by the rig process within one period: {100 * lat['within_period_picked_up']:.2f} %)"
                 if "within_period_picked_up" in lat else "") if lat.get("n") else "",
              f"  {'(stamped at)':<20}{_stamp(lat.get('stamp'))}",
              f"  {'rig pick-up':<20}{_fmt(report.get('rig_pickup_us', {}))}",
              f"  {'rig lateness':<20}{_fmt(report['rig_lateness_us'])}",
              f"  {'rig period jitter':<20}{_fmt(report['rig_period_jitter_us'], ('avg', 'p99', 'p99.9', 'max_abs'))}"]
    if timing_note:
        lines += ["", f"note: {timing_note}"]
    return "\n".join(ln for ln in lines if ln is not None) + "\n"


def figures(report: dict[str, Any], out: Path) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    s = report.get("_series")
    if s is None:
        return []
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    k, est, truth, t = s["k"], s["est"], s["truth"], s["t"]
    T = report["scenario"]["period"]
    for j, (name, unit, fig_no) in enumerate((("position", "m", 19), ("velocity", "m/s", 20))):
        fig, ax = plt.subplots(figsize=(8, 3.6))
        real = "real (trajectory file)" if report["scenario"].get("trajectory") else "real (noise-free)"
        ax.plot(t + T, truth[:, j], lw=1.2, label=real)
        if len(k):
            ax.plot(t[k] + T, est[:, j], lw=0.8, ls="--", label="identified (firmware over the bus)")
        sc = report["scenario"]
        # the velocity differenced from a held position is not valid through the hold either
        derived = j == 1 and sc.get("velocity_from_position", False) and 0 in sc["hold_states"]
        if sc["hold_duration"] > 0 and (j in sc["hold_states"] or derived):
            ax.axvspan(sc["hold_start"], sc["hold_start"] + sc["hold_duration"], color="0.9",
                       label="measurement held" if j in sc["hold_states"] else "not valid (from the held position)")
        ax.set_xlabel("time (s)")
        ax.set_ylabel(f"{name} ({unit})")
        ax.set_title(f"LIM {name}: real vs identified (cf. Fig. {fig_no}), {report['transport']}")
        ax.legend(loc="best", fontsize=8)
        fig.tight_layout()
        p = atomic.save_figure(fig, out / f"{name}.png", dpi=110)
        plt.close(fig)
        paths.append(p)
    lat = np.asarray(s["latency_ns"], dtype=np.float64) / 1e3
    if lat.size:
        fig, ax = plt.subplots(figsize=(7, 3.6))
        ax.hist(lat, bins=100, log=True)
        ax.axvline(T * 1e6, color="r", ls="--", label="one period")
        ax.set_xlabel("latency Measurement sent -> Estimate received (us)")
        ax.set_ylabel("frames")
        ax.set_title(f"latency over {report['transport']} (n = {lat.size})")
        ax.legend()
        fig.tight_layout()
        p = atomic.save_figure(fig, out / "latency.png", dpi=110)
        plt.close(fig)
        paths.append(p)
    return paths


def write(report: dict[str, Any], out: str | Path, *, timing_note: str | None = None) -> list[Path]:
    """report.json, report.txt and the PNGs into ``out``, each replaced whole, the folder marked
    incomplete (pyrhonn.atomic.MARKER) until the last is in place."""
    with atomic.output_folder(out, "pyrhonn hil") as folder:
        paths = [atomic.write_text(folder / "report.json", to_json(report) + "\n"),
                 atomic.write_text(folder / "report.txt", table(report, timing_note=timing_note))]
        return paths + figures(report, folder)
