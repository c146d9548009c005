"""Error metrics of a record read a chunk at a time: :func:`pyrhonn.simulation.scores` and
:func:`pyrhonn.metrics.absolute_deviation` as running sums.

:class:`RunningScores` takes each chunk's measurements, estimates and mask
(the targets scored) and keeps per state: the count scored and missing (no
estimate), the sum of squared errors (scaled by the largest error so far,
so errors up to the float64 limit neither overflow nor lose the small
ones), the mean and the sum of squared deviations of the measurements
(merged chunk by chunk, Chan et al.'s pairwise update) for the RRSE, and
the sum of errors. The absolute deviation mean |e - ē| needs ē first: the
scored errors are written to a temporary file as they come and read back
once, a chunk at a time. The figures equal the whole-record ones up to
rounding (summation order), never more than a few units in the last place.
"""
from __future__ import annotations

import tempfile
from typing import IO, Any

import numpy as np

from .simulation import Scores

__all__ = ["BLOCK", "RunningScores"]

_ROWS = 1 << 16  #: rows read back at once for the absolute deviation
BLOCK = 1 << 14  #: rows summed at once (of the whole record: the same blocks however it is read)


class RunningScores:
    """Running RMSE, RRSE and absolute deviation of one estimate of ``n`` states (see the module docs)."""

    def __init__(self, n: int, deviation: bool = False) -> None:
        self.n = n
        self.scored = np.zeros(n, dtype=np.int64)
        self.missing = np.zeros(n, dtype=np.int64)
        self._scale = np.zeros(n)  # the largest |e| so far
        self._ssq = np.zeros(n)  # sum (e / scale)^2
        self._sum = np.zeros(n)  # sum e
        self._mean = np.zeros(n)  # of the scored measurements
        self._m2 = np.zeros(n)
        self._spill: IO[bytes] | None = tempfile.TemporaryFile() if deviation else None  # noqa: SIM115
        self._pending: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        self._held = 0

    def add(self, X: np.ndarray, estimate: np.ndarray, mask: np.ndarray) -> None:
        """A chunk: ``X`` and ``estimate`` (L, n) float64, ``mask`` (L, n) bool (the targets scored).
        Summed in blocks of :data:`BLOCK` rows of the whole record, whatever the chunks: the figures do not
        depend on how the record was cut."""
        self._pending.append((X, estimate, mask))
        self._held += X.shape[0]
        if self._held >= BLOCK:
            self._flush(final=False)

    def _flush(self, final: bool) -> None:
        if not self._pending:
            return
        X, estimate, mask = (np.concatenate([p[i] for p in self._pending]) for i in range(3))
        whole = X.shape[0] if final else X.shape[0] // BLOCK * BLOCK
        for a in range(0, whole, BLOCK):
            self._block(X[a:a + BLOCK], estimate[a:a + BLOCK], mask[a:a + BLOCK])
        self._pending = [(X[whole:], estimate[whole:], mask[whole:])] if whole < X.shape[0] else []
        self._held = X.shape[0] - whole

    def _block(self, X: np.ndarray, estimate: np.ndarray, mask: np.ndarray) -> None:
        finite = np.isfinite(estimate)
        self.missing += (mask & ~finite).sum(axis=0)
        ok = mask & finite
        with np.errstate(over="ignore", invalid="ignore"):
            e = np.where(ok, X - estimate, np.nan)
        for j in range(self.n):
            rows = ok[:, j]
            c = int(rows.sum())
            if not c:
                continue
            ej, xj = e[rows, j], X[rows, j]
            peak = float(np.max(np.abs(ej)))
            with np.errstate(over="ignore", invalid="ignore"):
                if peak > self._scale[j]:
                    self._ssq[j] = self._ssq[j] * (self._scale[j] / peak) ** 2 if self._scale[j] > 0 else 0.0
                    self._scale[j] = peak
                if self._scale[j] > 0 and np.isfinite(self._scale[j]):
                    self._ssq[j] += float(np.sum((ej / self._scale[j]) ** 2))
                self._sum[j] += float(np.sum(ej))
                mean = float(np.mean(xj))
                m2 = float(np.sum((xj - mean) ** 2))
                total = int(self.scored[j]) + c
                delta = mean - self._mean[j]
                self._m2[j] += m2 + delta * delta * float(self.scored[j]) * c / total
                self._mean[j] += delta * c / total
            self.scored[j] = total
        if self._spill is not None:
            self._spill.write(np.ascontiguousarray(e, dtype=np.float64).tobytes())

    def scores(self) -> Scores:
        """RMSE and RRSE per state as :func:`pyrhonn.simulation.scores` gives them (NaN where nothing was
        scored, inf where an estimate was missing)."""
        self._flush(final=True)
        r, rr = np.full(self.n, np.nan), np.full(self.n, np.nan)
        for j in range(self.n):
            c = int(self.scored[j] + self.missing[j])
            if not c:
                continue
            if self.missing[j]:
                r[j] = rr[j] = np.inf
                continue
            with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
                r[j] = self._scale[j] * np.sqrt(self._ssq[j] / c) if np.isfinite(self._scale[j]) else np.inf
                den = np.sqrt(self._m2[j] / c)
                rr[j] = r[j] / den if den > 0 else np.nan
        return Scores(rmse=r, rrse=rr, scored=self.scored + self.missing, missing=self.missing.copy())

    def absolute_deviation(self) -> list[float | None]:
        """mean |e - ē| per state over the scored errors (None where none was scored or one is missing)."""
        if self._spill is None:
            raise ValueError("absolute_deviation: made without deviation=True")
        self._flush(final=True)
        ebar = np.where(self.scored > 0, self._sum / np.maximum(self.scored, 1), 0.0)
        total = np.zeros(self.n)
        self._spill.seek(0)
        width = self.n * 8
        while True:
            block = self._spill.read(_ROWS * width)
            if not block:
                break
            e = np.frombuffer(block, dtype=np.float64).reshape(-1, self.n)
            with np.errstate(over="ignore", invalid="ignore"):
                total += np.nansum(np.abs(e - ebar), axis=0)
        out: list[float | None] = []
        for j in range(self.n):
            out.append(None if not self.scored[j] or self.missing[j] else float(total[j] / self.scored[j]))
        return out

    def close(self) -> None:
        if self._spill is not None:
            self._spill.close()
            self._spill = None

    def __enter__(self) -> RunningScores:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()
