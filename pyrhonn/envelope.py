"""A long series drawn in bounded memory: the min-max envelope of buckets of samples.

A plot of a recording of millions of samples cannot draw every sample (the
picture is 800 pixels wide) and should not hold them all. :class:`Envelope`
takes the series a chunk at a time and keeps, for every bucket of ``width``
consecutive samples, the x of its first sample and each series' minimum and
maximum over it (NaN samples skipped; NaN if all are), and per flag series
whether any sample of the bucket has it. ``width`` starts at 1 (every
sample kept as it is) and doubles, merging neighbouring buckets, whenever
more than ``2 * buckets`` of them are held: at the end there are between
``buckets`` and ``2 * buckets`` (or one per sample for a short series).
Drawing each bucket as a vertical stroke from its minimum to its maximum
gives the picture the full series gives at that width (every peak kept),
which a plot of every n-th sample does not.
"""
from __future__ import annotations

import numpy as np

__all__ = ["BUCKETS", "Envelope"]

BUCKETS = 1024  #: buckets kept at least once a series is longer (the plots are 800 pixels wide)


class Envelope:
    """The min-max envelope of ``series`` float series and ``flags`` bool series (see the module docs)."""

    def __init__(self, series: int, flags: int = 0, buckets: int = BUCKETS) -> None:
        if buckets < 1:
            raise ValueError(f"buckets: expected >= 1, got {buckets}")
        self.buckets = buckets
        self.width = 1  #: samples per bucket
        self.samples = 0
        self._ids = np.zeros(0, dtype=np.int64)
        self._x = np.zeros(0)
        self._lo = np.zeros((0, series))
        self._hi = np.zeros((0, series))
        self._any = np.zeros((0, flags), dtype=bool)
        self.last_x = np.nan  #: x of the last sample
        self.has_t = False  #: whether x is a time (else the sample index), for the axis label
        self._marks: dict[int, float] = {}
        self._wanted: set[int] = set()

    def mark(self, sample: int) -> None:
        """Remember the x of ``sample`` when it is fed (:meth:`x_of`)."""
        self._wanted.add(sample)

    def x_of(self, sample: int) -> float:
        return self._marks[sample]

    def feed(self, x: np.ndarray, values: np.ndarray, flags: np.ndarray | None = None) -> None:
        """The next samples: ``x`` (L,), ``values`` (L, series) float, ``flags`` (L, flags) bool."""
        L = x.shape[0]
        if L == 0:
            return
        k0 = self.samples
        for k in [k for k in self._wanted if k0 <= k < k0 + L]:
            self._marks[k] = float(x[k - k0])
        ids = (np.arange(k0, k0 + L) // self.width).astype(np.int64)
        f = np.zeros((L, self._any.shape[1]), dtype=bool) if flags is None else flags
        self._append(ids, x, values, values, f)
        self.samples += L
        self.last_x = float(x[-1])
        while self._ids.size > 2 * self.buckets:
            self.width *= 2
            self._ids //= 2
            ids, x0, lo, hi, fl = self._ids, self._x, self._lo, self._hi, self._any
            self._ids = np.zeros(0, dtype=np.int64)
            self._x, self._lo, self._hi, self._any = x0[:0], lo[:0], hi[:0], fl[:0]
            self._append(ids, x0, lo, hi, fl)

    def _append(self, ids: np.ndarray, x: np.ndarray, lo: np.ndarray, hi: np.ndarray, fl: np.ndarray) -> None:
        """Fold rows with bucket ``ids`` (non-decreasing, none before the last held) into the buckets."""
        heads = np.flatnonzero(np.r_[True, ids[1:] != ids[:-1]])
        with np.errstate(invalid="ignore"):
            blo = np.fmin.reduceat(lo, heads, axis=0)
            bhi = np.fmax.reduceat(hi, heads, axis=0)
        bany = np.logical_or.reduceat(fl, heads, axis=0) if fl.shape[1] else np.zeros((heads.size, 0), dtype=bool)
        bids, bx = ids[heads], x[heads]
        if self._ids.size and bids[0] == self._ids[-1]:  # the first bucket continues the last one held
            self._lo[-1] = np.fmin(self._lo[-1], blo[0])
            self._hi[-1] = np.fmax(self._hi[-1], bhi[0])
            self._any[-1] |= bany[0]
            bids, bx, blo, bhi, bany = bids[1:], bx[1:], blo[1:], bhi[1:], bany[1:]
        self._ids = np.concatenate([self._ids, bids])
        self._x = np.concatenate([self._x, bx])
        self._lo = np.concatenate([self._lo, blo])
        self._hi = np.concatenate([self._hi, bhi])
        self._any = np.concatenate([self._any, bany])

    def line(self, s: int) -> tuple[np.ndarray, np.ndarray]:
        """(x, y) to draw series ``s``: every sample while a bucket holds one, else each bucket's
        minimum then maximum at its first x (a vertical stroke per bucket)."""
        if self.width == 1:
            return self._x.copy(), self._lo[:, s].copy()
        return np.repeat(self._x, 2), np.column_stack([self._lo[:, s], self._hi[:, s]]).ravel()

    def runs(self, f: int) -> list[tuple[float, float]]:
        """The x ranges of the runs of buckets where flag ``f`` is set: from the first x of the run's first
        bucket to the first x of the bucket after it (the last x for a run that ends the series)."""
        edges = np.flatnonzero(np.diff(np.r_[0, self._any[:, f].astype(np.int8), 0]))
        ends = np.r_[self._x, self.last_x]
        return [(float(self._x[a]), float(ends[b])) for a, b in zip(edges[::2], edges[1::2])]
