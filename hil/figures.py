"""The replay's figures (matplotlib Agg), each one a PNG of ``hil replay --out``:

- ``position.png``, ``velocity.png`` (another identifier: ``<state>.png`` per
  state, by its config's name): the real trace over the identified one
  (as the paper's Fig. 19-20), under it the Measurement frames the rig sent
  (measured, held or not valid, and missing: lost, or refused after a loss),
  the error, and zooms on the hold and its end;
- ``health.png``: the filter's health over the run, per neuron: the
  normalised innovation squared e^2/s with the 95 % band of a chi-square
  with one degree of freedom (where a consistent filter's NIS falls 95 % of
  the time), trace P, the refused and gated updates and the covariance resets (marked
  on every panel). From the offline twin that the bit-exact check runs on
  the frames the firmware stepped on: the firmware's own numbers, bit for
  bit, at every sample, where its Health frames come only at the end;
- ``losses.png``: what became of the frames over time (lost by the
  scenario, refused as Seq jumps, lost to or from the firmware at a full
  receive queue, missing), the estimates later than one period, and the
  kernel's drop counters of both sockets (udp_multicast, sampled during the
  run);
- ``latency.png``: the latency's histogram with p99 and p99.9, and over the
  run.

Figures whose timing comes from the ``virtual`` transport (latency, late
estimates) carry a warning printed on them: that firmware is a thread of the
rig's own process. :func:`build_figures` returns the figures, open;
:func:`figures` saves and closes them.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from pyrhonn import atomic

__all__ = ["NIS_BAND", "VIRTUAL_WARNING", "build_figures", "figures"]

#: the 95 % band of a chi-square with one degree of freedom: where a consistent filter's e^2/s falls
NIS_BAND = (9.8207e-4, 5.0239)
#: printed on figures whose timing comes from the virtual bus
VIRTUAL_WARNING = ("WARNING: timing from the virtual transport (the firmware is a thread of the rig's process): "
                   "not a bus measurement")
#: the loss plot's bins over the run
LOSS_BINS = 200


def _axis(name: str, unit: str) -> str:
    """An axis label: the name and its unit, where the unit is known."""
    return f"{name} ({unit})" if unit else name


def _hold_window(sc: dict[str, Any], j: int) -> tuple[float, float, str] | None:
    """(start, end, legend label) of the hold's shading on state ``j``'s plots, or None."""
    # the velocity differenced from a held position is not valid through the hold either
    derived = j == 1 and sc.get("velocity_from_position", False) and 0 in sc["hold_states"]
    if sc["hold_duration"] <= 0 or not (j in sc["hold_states"] or derived):
        return None
    label = "measurement held" if j in sc["hold_states"] else "not valid (differenced from the held position)"
    return sc["hold_start"], sc["hold_start"] + sc["hold_duration"], label


def _zooms(sc: dict[str, Any], hold: tuple[float, float, str] | None, t_end: float,
           t_worst: float) -> list[tuple[str, float, float]]:
    """The two zoom windows under a state's plot: the hold and its end, where the
    identifier bridges and then takes the fresh measurements up again; without a
    hold, the largest error and the end of the run."""
    if hold is not None:
        a, b, _ = hold
        margin = 0.1 * (b - a)
        return [("the hold", a - margin, b + margin), ("the end of the hold", b - 0.01, b + 0.04)]
    return [("the largest error", t_worst - 0.015, t_worst + 0.015), ("the end of the run", t_end - 0.03, t_end)]


def _state_figure(report: dict[str, Any], j: int, name: str, unit: str, fig_no: int | None) -> Any:
    """Real vs identified (top), the Measurement frames under it (measured, held, missing), the error,
    and two zooms (bottom) of state ``j``."""
    import matplotlib.pyplot as plt

    s, sc = report["_series"], report["scenario"]
    T = sc["period"]
    k, est, truth, t = s["k"], np.asarray(s["est"]), np.asarray(s["truth"]), np.asarray(s["t"])
    tt, tk = t + T, t[k] + T                    # x(k+1) is due one period after frame k
    err = est[:, j] - truth[k, j] if len(k) else np.zeros(0)
    real = "real (trajectory file)" if sc.get("trajectory") else "real (noise-free)"
    hold = _hold_window(sc, j)
    fig = plt.figure(figsize=(10, 10.8))
    grid = fig.add_gridspec(4, 2, height_ratios=(2.2, 1.2, 1.3, 1.6), hspace=0.55, wspace=0.25)
    top = fig.add_subplot(grid[0, :])
    frames = fig.add_subplot(grid[1, :], sharex=top)
    mid = fig.add_subplot(grid[2, :], sharex=top)
    worst = float(tk[int(np.argmax(np.abs(err)))]) if err.size else float(tt[len(tt) // 2])
    zooms = [(fig.add_subplot(grid[3, i]), *w) for i, w in enumerate(_zooms(sc, hold, float(tt[-1]), worst))]

    def traces(ax: Any, lo: float = -np.inf, hi: float = np.inf) -> None:
        """The identified estimate under the real trace: the noisy one must not hide the real one."""
        on, onk = (tt >= lo) & (tt <= hi), (tk >= lo) & (tk <= hi)
        if onk.any():
            ax.plot(tk[onk], est[onk, j], lw=0.7, color="tab:orange", alpha=0.75,
                    label="identified (firmware over the bus)", zorder=2)
        ax.plot(tt[on], truth[on, j], lw=1.4, color="black", label=real, zorder=3)

    def shade(ax: Any, legend: bool) -> None:
        if hold is not None:
            ax.axvspan(hold[0], hold[1], color="0.88", zorder=0, label=hold[2] if legend else None)

    traces(top)
    shade(top, True)
    top.set_ylabel(_axis(name, unit))
    top.set_xlabel("time (s)")
    top.set_title(f"LIM {name}: real vs identified (cf. Fig. {fig_no}), {report['transport']}" if fig_no else
                  f"{name}: real vs identified, {report['transport']}")
    top.legend(loc="best", fontsize=8)

    _frames_panel(frames, s, j, name, unit)
    shade(frames, False)

    mid.plot(tk, err, lw=0.6, color="tab:red", label="identified - real")
    mid.axhline(0.0, color="0.4", lw=0.6)
    shade(mid, True)
    mid.set_ylabel(_axis("error", unit))
    mid.set_xlabel("time (s)")
    mid.set_title("error of the identified estimate against the real trace", fontsize=9)
    mid.legend(loc="best", fontsize=7)

    for ax, what, lo, hi in zooms:
        traces(ax, lo, hi)
        shade(ax, False)
        ax.set_xlim(lo, hi)
        ax.set_ylabel(_axis(name, unit))
        ax.set_xlabel("time (s)")
        ax.set_title(f"zoom: {what}", fontsize=9)
    return fig


def _latency_figure(report: dict[str, Any], lat_us: np.ndarray) -> Any:
    """The latency's histogram with its p99 and p99.9 marked, and the latency over the run
    (stalls show as bursts in time, not in a histogram)."""
    import matplotlib.pyplot as plt

    s = report["_series"]
    T_us = report["scenario"]["period"] * 1e6
    t = np.asarray(s["t"])[np.asarray(s["k"])]
    t = t - t[0]
    p99, p999 = np.percentile(lat_us, [99, 99.9])
    fig, (hist, over) = plt.subplots(2, 1, figsize=(9, 7.2), gridspec_kw={"hspace": 0.45})
    marks = ((T_us, "r", "--", f"one period ({T_us:g} us)"), (p99, "tab:purple", ":", f"p99 {p99:.1f} us"),
             (p999, "tab:green", "-.", f"p99.9 {p999:.1f} us"))
    hist.hist(lat_us, bins=100, log=True, color="tab:blue")
    for x, color, ls, label in marks:
        hist.axvline(x, color=color, ls=ls, lw=1.2, label=label)
    hist.set_xlabel("latency Measurement sent -> Estimate received (us)")
    hist.set_ylabel("estimates per bin (count)")
    hist.set_title(f"latency over {report['transport']} (n = {lat_us.size})")
    hist.legend(fontsize=8)
    over.plot(t, lat_us, ".", ms=1.5, color="tab:blue", label="one estimate")
    for x, color, ls, label in marks:
        over.axhline(x, color=color, ls=ls, lw=1.0, label=label)
    over.set_yscale("log")
    over.set_xlabel("time since the first Measurement (s)")
    over.set_ylabel("latency (us)")
    over.set_title("latency over the run: a stall shows as a burst of late estimates", fontsize=9)
    over.legend(fontsize=7, loc="upper right", markerscale=4)
    _virtual_warning(fig, report)
    return fig


def _virtual_warning(fig: Any, report: dict[str, Any]) -> None:
    if report.get("transport") == "virtual":
        fig.text(0.5, 0.995, VIRTUAL_WARNING, ha="center", va="top", fontsize=9, color="darkred", weight="bold",
                 bbox={"facecolor": "#fff2cc", "edgecolor": "darkred", "boxstyle": "round,pad=0.3"})


def _frames_panel(ax: Any, s: dict[str, Any], j: int, name: str, unit: str) -> None:
    """The Measurement frames of state ``j`` at their sampling instants: measured (fresh), held or not
    valid (the value the frame carried), and missing (never stepped on: lost, or refused after a loss)
    as ticks along the bottom."""
    from .score import FATES

    t, X, valid, fate = (np.asarray(s[key]) for key in ("t", "X", "valid", "fate"))
    used = (fate == FATES.index("answered")) | (fate == FATES.index("lost from the firmware"))
    fresh, held, missing = used & valid[:, j], used & ~valid[:, j], ~used
    ax.plot(t[fresh], X[fresh, j], ".", ms=1.5, color="tab:blue", label=f"measured ({int(fresh.sum())})")
    ax.plot(t[held], X[held, j], ".", ms=1.5, color="0.55", label=f"held / not valid ({int(held.sum())})")
    ax.plot(t[missing], np.full(int(missing.sum()), 0.04), "|", ms=8, color="tab:red",
            transform=ax.get_xaxis_transform(), label=f"missing: lost or refused ({int(missing.sum())})")
    ax.set_ylabel(_axis(name, unit))
    ax.set_xlabel("time (s)")
    ax.set_title("Measurement frames sent to the firmware", fontsize=9)
    ax.legend(loc="best", fontsize=7, markerscale=3)


def _health_figure(report: dict[str, Any]) -> Any:
    """NIS with its chi-square band, trace P, refused, reset and gated updates, per neuron over the run."""
    import matplotlib.pyplot as plt

    s, sc = report["_series"], report["scenario"]
    h = s["health"]
    t = np.asarray(s["t"])[h["cycle"]]
    nis, trace, rejected, resets, gated = (np.asarray(h[key]) for key in ("nis", "trace_p", "rejected", "resets",
                                                                           "gated"))
    fig, (a_nis, a_p, a_n) = plt.subplots(3, 1, figsize=(10, 9), sharex=True, gridspec_kw={"hspace": 0.35})
    a_nis.axhspan(*NIS_BAND, color="tab:green", alpha=0.12, label="95 % band of chi-square(1)")
    tiny = 1e-12                                  # a NIS of 0 (no update yet) on a log axis
    for i in range(nis.shape[1]):
        a_nis.plot(t, np.maximum(nis[:, i], tiny), lw=0.8, label=f"neuron {i}")
        a_p.plot(t, np.maximum(trace[:, i], tiny), lw=0.9, label=f"neuron {i}")
        a_n.step(t, rejected[:, i], where="post", lw=0.9, label=f"refused, neuron {i}")
        a_n.step(t, resets[:, i], where="post", lw=0.9, ls="--", label=f"resets, neuron {i}")
        if gated[:, i].any():
            a_n.step(t, gated[:, i], where="post", lw=0.9, ls=":", label=f"gated, neuron {i}")
    reset_at = t[1:][np.any(np.diff(resets, axis=0) > 0, axis=1)] if t.size > 1 else t[:0]
    for ax in (a_nis, a_p, a_n):
        if sc["hold_duration"] > 0:
            ax.axvspan(sc["hold_start"], sc["hold_start"] + sc["hold_duration"], color="0.9", zorder=0,
                       label="measurement hold" if ax is a_nis else None)
        for i, x in enumerate(reset_at):
            ax.axvline(x, color="tab:red", lw=0.8, ls=":", label="covariance reset" if i == 0 and ax is a_nis else None)
    a_nis.set_yscale("log")
    a_nis.set_ylabel("NIS e^2/s (-)")
    a_nis.set_title("filter health over the run (the offline twin of the firmware, bit for bit; "
                    f"{t.size} samples)")
    a_p.set_yscale("log")
    a_p.set_ylabel("trace P (-)")
    from matplotlib.ticker import MaxNLocator

    a_n.yaxis.set_major_locator(MaxNLocator(integer=True))
    a_n.set_ylim(0, 1.15 * max(1, int(rejected.max(initial=0)), int(resets.max(initial=0)),
                               int(gated.max(initial=0))))
    a_n.set_ylabel("count (updates)")
    a_n.set_title(f"refused updates {int(rejected[-1].sum()) if t.size else 0}, covariance resets "
                  f"{int(resets[-1].sum()) if t.size else 0}, gated updates {int(gated[-1].sum()) if t.size else 0} "
                  "(cumulative)", fontsize=9)
    a_n.set_xlabel("time (s)")
    for ax in (a_nis, a_p, a_n):
        ax.legend(loc="upper left", fontsize=6, ncol=4)
    return fig


def _losses_figure(report: dict[str, Any]) -> Any:
    """Frames lost, refused and late per stretch of the run, and the kernel's drop counters over it."""
    import matplotlib.pyplot as plt

    from .score import FATES

    s, sc = report["_series"], report["scenario"]
    t, fate = np.asarray(s["t"]), np.asarray(s["fate"])
    N = t.size
    edges = np.linspace(0, N, min(LOSS_BINS, N) + 1).astype(np.int64)
    mid_t = t[np.minimum((edges[:-1] + edges[1:]) // 2, N - 1)]
    per_bin = lambda mask: np.add.reduceat(mask.astype(np.int64), edges[:-1])   # noqa: E731
    fig, (a_f, a_k) = plt.subplots(2, 1, figsize=(10, 7.5), sharex=True, gridspec_kw={"hspace": 0.35})
    drawn = 0
    for code, what in enumerate(FATES):
        if code == 0 or not (fate == code).any():
            continue
        a_f.step(mid_t, per_bin(fate == code), where="mid", lw=1.0, label=f"{what} ({int((fate == code).sum())})")
        drawn += 1
    late = np.zeros(N, dtype=bool)
    lat = np.asarray(s["latency_ns"])
    late[np.asarray(s["k"])] = lat > int(round(sc["period"] * 1e9))
    a_f.step(mid_t, per_bin(late), where="mid", lw=0.8, color="0.5", ls="--",
             label=f"estimate later than one period ({int(late.sum())})")
    if not drawn:
        a_f.text(0.5, 0.6, "no frame lost or refused", transform=a_f.transAxes, ha="center", fontsize=9)
    a_f.set_ylabel(f"frames per {N / max(1, edges.size - 1) * sc['period'] * 1e3:.3g} ms (count)")
    a_f.set_title(f"frame loss over the run, {report['transport']}")
    a_f.legend(loc="upper left", fontsize=7)
    drops = s.get("kernel_drops")
    total = (report.get("frames") or {}).get("kernel_drops")
    if drops and drops.get("cycle"):
        tk = t[np.minimum(np.asarray(drops["cycle"]), N - 1)]
        for side in ("rig", "firmware"):
            a_k.step(tk, drops[side], where="post", lw=1.0,
                     label=f"kernel drops, {side} socket ({(total or {}).get(side, drops[side][-1])} over the run)")
        a_k.legend(loc="upper left", fontsize=7)
    else:
        why = ("the virtual bus has no socket to drop datagrams" if report.get("transport") == "virtual" else
               "this transport's kernel drop counters are not read")
        a_k.text(0.5, 0.5, f"kernel drops: not counted ({why})", transform=a_k.transAxes, ha="center", fontsize=9)
    a_k.set_ylabel("datagrams dropped since the start (count)")
    a_k.set_xlabel("time (s)")
    a_k.set_title("the kernel's receive-queue drops (/proc/net/udp), sampled during the run", fontsize=9)
    _virtual_warning(fig, report)
    return fig


def _scored(report: dict[str, Any]) -> list[tuple[str, str, int | None]]:
    """(name, unit, figure of the paper) of each state plotted, in state order: the LIM's position and
    velocity (Fig. 19-20), or every state of another identifier, by its config's name."""
    if not (report.get("scenario") or {}).get("identifier"):
        return [("position", "m", 19), ("velocity", "m/s", 20)]
    ident = report.get("identification") or {}
    scored = ident.get("scored") or [[name, ""] for name in report.get("states", [])]
    return [(str(name), str(unit), None) for name, unit in scored]


def build_figures(report: dict[str, Any]) -> dict[str, Any]:
    """The figures of a scored run (hil.score.score), by file name, open (the caller closes them)."""
    import matplotlib

    matplotlib.use("Agg")
    s = report.get("_series")
    if s is None:
        return {}
    out = {}
    for j, (name, unit, fig_no) in enumerate(_scored(report)):
        out[f"{name}.png"] = _state_figure(report, j, name, unit, fig_no)
    if s.get("health") is not None and len(s["health"]["cycle"]):
        out["health.png"] = _health_figure(report)
    if "fate" in s:
        out["losses.png"] = _losses_figure(report)
    lat = np.asarray(s["latency_ns"], dtype=np.float64) / 1e3
    if lat.size:
        out["latency.png"] = _latency_figure(report, lat)
    return out


def figures(report: dict[str, Any], out: Path) -> list[Path]:
    """:func:`build_figures` saved into ``out`` as PNGs (each replaced whole), then closed."""
    import matplotlib.pyplot as plt

    figs = build_figures(report)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, fig in figs.items():
        paths.append(atomic.save_figure(fig, out / name, dpi=100))
        plt.close(fig)
    return paths
