"""Latency statistics of a run: nanosecond samples summarised in
microseconds, the form every latency figure of a report takes (the rig's
receive pickup, the scored latency and jitter, the runner's histograms)."""
from __future__ import annotations

import numpy as np

__all__ = ["stats_us"]


def stats_us(values_ns: np.ndarray) -> dict[str, float | int]:
    """min/avg/p50/p99/p99.9/max of nanosecond values, in microseconds."""
    v = np.asarray(values_ns, dtype=np.float64)
    if v.size == 0:
        return {"n": 0}
    q = np.percentile(v, [50, 99, 99.9])
    return {"n": int(v.size), "min": float(v.min()) / 1e3, "avg": float(v.mean()) / 1e3, "p50": float(q[0]) / 1e3,
            "p99": float(q[1]) / 1e3, "p99.9": float(q[2]) / 1e3, "max": float(v.max()) / 1e3}
