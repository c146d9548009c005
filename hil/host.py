"""What the host took from a timing run: the hypervisor's steal time.

A bench on a virtual machine shares its physical CPUs with other guests. When
the hypervisor runs something else on the physical CPU under one of our
vCPUs, both the rig and the firmware freeze for that time, whatever their
scheduling policy, and estimates come back late. Linux counts that time per
CPU as *steal* (the 8th value of each ``cpuN`` line of ``/proc/stat``, in
USER_HZ ticks, usually 10 ms), which is what ``top`` shows as ``st``.

:class:`StealMeter` reads it either side of a run, so that a bench report can
say how much of the run the host took away. The resolution is one tick, so
short stalls may not show; nonzero steal means the host was oversubscribed
during the run, zero does not prove it was not. On a bare-metal host, or where
``/proc/stat`` cannot be read, the meter reports ``available: False``.
"""
from __future__ import annotations

import os
import time
from pathlib import Path

PROC_STAT = Path("/proc/stat")


def steal_ticks(text: str) -> dict[int, int]:
    """CPU number -> steal ticks, from the text of /proc/stat (ValueError on
    a ``cpuN`` line with fewer than 8 values: kernels before 2.6.11)."""
    out: dict[int, int] = {}
    for line in text.splitlines():
        fields = line.split()
        if not fields or not fields[0].startswith("cpu") or fields[0] == "cpu":
            continue
        name = fields[0][3:]
        if not name.isdigit():
            continue
        if len(fields) < 9:
            raise ValueError(f"/proc/stat: {fields[0]} has no steal column: {line!r}")
        out[int(name)] = int(fields[8])
    return out


class StealMeter:
    """Steal time of each CPU between :meth:`start` and :meth:`stop`.

    ``stop()`` returns ``{"available": True, "ms": {cpu: ms}, "total_ms":
    ms, "elapsed_s": s}`` or ``{"available": False, "why": ...}``."""

    def __init__(self, path: Path = PROC_STAT) -> None:
        self.path = Path(path)
        self._before: dict[int, int] | None = None
        self._why = ""
        self._t0 = 0.0

    def _read(self) -> dict[int, int] | None:
        try:
            return steal_ticks(self.path.read_text())
        except (OSError, ValueError) as exc:
            self._why = f"{self.path}: {exc}"
            return None

    def start(self) -> None:
        self._before = self._read()
        self._t0 = time.monotonic()

    def stop(self) -> dict:
        after = self._read()
        if self._before is None or after is None:
            return {"available": False, "why": self._why or "start() was not called"}
        try:
            hz = os.sysconf("SC_CLK_TCK")
        except (ValueError, OSError, AttributeError):
            hz = 100
        ms = {cpu: 1000.0 * (after[cpu] - self._before[cpu]) / hz for cpu in sorted(after) if cpu in self._before}
        return {"available": True, "ms": ms, "total_ms": sum(ms.values()),
                "elapsed_s": time.monotonic() - self._t0, "tick_ms": 1000.0 / hz}


def steal_line(steal: dict, cpus: tuple[int, ...] | None = None) -> str:
    """One report line: the steal of ``cpus`` (all when None) during the run."""
    if not steal.get("available"):
        return f"host: steal time not available ({steal.get('why', '?')})"
    ms = steal["ms"]
    shown = [c for c in (cpus if cpus is not None else ms) if c in ms]
    parts = ", ".join(f"CPU{c} {ms[c]:.0f} ms" for c in shown)
    took = sum(ms[c] for c in shown)
    share = 100.0 * took / (1000.0 * steal["elapsed_s"] * max(len(shown), 1)) if steal["elapsed_s"] > 0 else 0.0
    verdict = ("the hypervisor ran something else on these CPUs during the run: stalls no scheduling policy "
               "here can prevent" if took > 0 else "none counted (resolution one tick)")
    return f"host: steal time {parts} ({share:.2f} % of the run): {verdict}"
