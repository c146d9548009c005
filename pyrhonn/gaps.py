"""Gaps in a record: lost samples split it into segments, as the firmware does.

A record (a CSV file or a bus log aligned on its sample clock) has two kinds
of holes, handled by the same rules as the firmware (``firmware_sim``):

- **A dropout**: the sample arrived (its inputs are known) but a state's
  measurement did not (flag 0, a lost or late frame of the state's message).
  The identifier steps with that state not valid: it learns nothing from it
  and predicts through it with its own output (:meth:`Identifier.run`). The
  firmware does the same with a Measurement whose ``Valid`` flag is 0.
- **A lost sample**: no input for it (a Measurement frame that never came,
  a row marked ``lost`` in a CSV). The identifier cannot step without u(k).
  The firmware counts ``d - 1`` lost frames on the sequence jump, rejects the
  frame that reveals the gap and restarts its identifier on the next one
  (``rhonn_restart``: weights and covariances kept, nothing learnt from that
  step, the delayed taps refilled). So here: the sample after a gap is not
  stepped (``rejected``), and the next segment begins with
  :meth:`Identifier.restart`. Any lost sample is a gap, however short: the
  firmware's threshold is one frame.

:func:`segments_of` finds the segments; :func:`simulate_segments` runs
:func:`pyrhonn.simulation.simulate` over each, restarting between them.
"""
from __future__ import annotations

import heapq
import re
from dataclasses import dataclass
from typing import Any

import numpy as np

from .identifier import Identifier, IdentifierError
from .simulation import Simulation, simulate

__all__ = ["Gap", "LISTED", "SegmentTracker", "Segments", "segments_of", "simulate_segments"]


@dataclass(frozen=True)
class Gap:
    """``lost`` samples from sample ``first`` on; ``rejected`` the sample after them (not stepped)."""

    first: int
    lost: int
    rejected: int


#: gaps (and segments) metrics.json lists: the first LISTED, and the LISTED largest of the rest
LISTED = 50


class _Pick:
    """The first ``limit`` entries added, and the ``limit`` largest of the rest (by ``size``; the earlier
    among equals): at most 2 * ``limit`` entries held, however many are added."""

    def __init__(self, limit: int = LISTED) -> None:
        self.limit = limit
        self.count = 0
        self.first: list[dict[str, Any]] = []
        self._heap: list[tuple[int, int, dict[str, Any]]] = []  # (size, -order, entry): the smallest, latest on top

    def add(self, size: int, entry: dict[str, Any]) -> None:
        order = self.count
        self.count += 1
        if len(self.first) < self.limit:
            self.first.append(entry)
            return
        item = (size, -order, entry)
        if len(self._heap) < self.limit:
            heapq.heappush(self._heap, item)
        elif item[:2] > self._heap[0][:2]:
            heapq.heapreplace(self._heap, item)

    def listed(self) -> list[dict[str, Any]]:
        """The entries kept, in the order added."""
        return self.first + [e for _, _, e in sorted(self._heap, key=lambda item: -item[1])]


class _Counts:
    """The firmware's counters of a record's segments and gaps."""

    segment_count: int
    gap_count: int
    lost: int

    @property
    def restarts(self) -> int:
        return max(self.segment_count - 1, 0)


@dataclass(frozen=True)
class Segments(_Counts):
    """The stepped runs ``bounds`` ([a, b) sample ranges, in order) and the ``gaps`` between them;
    ``stepped`` (T,) bool: the samples the identifier steps on."""

    bounds: tuple[tuple[int, int], ...]
    gaps: tuple[Gap, ...]
    stepped: np.ndarray

    @property
    def segment_count(self) -> int:  # type: ignore[override]
        return len(self.bounds)

    @property
    def gap_count(self) -> int:  # type: ignore[override]
        return len(self.gaps)

    @property
    def lost(self) -> int:  # type: ignore[override]
        return sum(g.lost for g in self.gaps)

    def first_sizes(self, k: int) -> list[int]:
        """The samples of the first ``k`` segments."""
        return [b - a for a, b in self.bounds[:k]]

    def starts(self) -> np.ndarray:
        """(T,) bool: the first sample of every segment (its prediction was made before the gap, or is x0)."""
        out = np.zeros(self.stepped.shape, dtype=bool)
        for a, _ in self.bounds:
            out[a] = True
        return out

    def report(self, t: np.ndarray | None, lines: np.ndarray, valid: np.ndarray | None = None,
               names: tuple[str, ...] = ()) -> dict[str, Any]:
        """The ``gaps`` entry of metrics.json: counts as the firmware's counters, and the segments and gaps
        listed (see :data:`LISTED`; with ``valid`` (T, n) and the state ``names``: each listed segment's
        dropouts per state, predicted through)."""
        def when(k: int) -> dict[str, Any]:
            return {"sample": k, "line": int(lines[k]), **({"t": float(t[k])} if t is not None else {})}

        segments, gaps = _Pick(), _Pick()
        for a, b in self.bounds:
            drop = None if valid is None else {name: int((~valid[a:b, j]).sum()) for j, name in enumerate(names)}
            segments.add(b - a, _segment(when(a), when(b - 1), b - a, drop))
        for g in self.gaps:
            gaps.add(g.lost, _gap(when(g.first), g.lost, when(g.rejected)))
        return _report(self.lost, segments, gaps)


def _segment(first: dict[str, Any], last: dict[str, Any], samples: int,
             dropouts: dict[str, int] | None) -> dict[str, Any]:
    return {"first": first, "last": last, "samples": samples, **({"dropouts": dropouts} if dropouts is not None else {})}


def _gap(first: dict[str, Any], lost: int, rejected: dict[str, Any]) -> dict[str, Any]:
    return {"first_lost": first, "lost": lost, "rejected": rejected}


def _report(lost: int, segments: _Pick, gaps: _Pick) -> dict[str, Any]:
    return {
        "rule": "a lost sample (no input) ends a segment; the sample after the gap is not stepped (the "
                "firmware rejects the frame that reveals a gap) and the next segment starts with a restart "
                "(weights and covariances kept, nothing learnt from its first step); a state without a "
                "measurement in a sample that arrived is a dropout: not valid, predicted through",
        "lost_samples": lost, "gaps": gaps.count, "rejected_after_gap": gaps.count,
        "restarts": max(segments.count - 1, 0),
        "segment_count": segments.count,
        "listed": {"limit": LISTED, "complete": segments.count <= LISTED and gaps.count <= LISTED,
                   "rule": f"segments and gap_list hold every segment and gap when there are at most {LISTED}; "
                           f"past that, the first {LISTED} in order and the {LISTED} largest of the rest (segments "
                           f"by samples, gaps by lost samples; the earlier among equals), in order"},
        "segments": segments.listed(),
        "gap_list": gaps.listed()}


class SegmentTracker(_Counts):
    """:func:`segments_of` one chunk of a record at a time, for a record too long to hold: :meth:`feed`
    each chunk's lost flags (and its dropouts, lines and times, for the report) in order, and get the
    samples of the chunk that are stepped and that start a segment; :meth:`finish` after the last. Holds
    counts and the segments and gaps the report lists (:data:`LISTED`), however many there are."""

    def __init__(self, names: tuple[str, ...]) -> None:
        self.names = names
        self.samples = 0
        self.segment_count = 0
        self.gap_count = 0
        self.lost = 0
        self._segments = _Pick()
        self._gaps = _Pick()
        self._prev_lost = False
        self._prev_stepped = False
        self._open: int | None = None  # the first sample of the segment not yet closed
        self._open_when: dict[str, Any] = {}
        self._drop = np.zeros(len(names), dtype=np.int64)
        self._gap_first = 0
        self._gap_when: dict[str, Any] = {}
        self._last: dict[str, Any] = {}

    @property
    def gaps(self) -> int:
        """How many gaps (a count: the gaps listed are in :meth:`report`)."""
        return self.gap_count

    def first_sizes(self, k: int) -> list[int]:
        """The samples of the first ``k`` segments closed."""
        return [e["samples"] for e in self._segments.first[:k]]

    def feed(self, lost: np.ndarray, valid: np.ndarray, lines: np.ndarray,
             t: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """The next chunk: ``lost`` (L,) bool, ``valid`` (L, n), its ``lines`` and times ``t``; returns
        (stepped, starts), both (L,) bool: the samples stepped, and the first of every segment."""
        L = lost.size
        if L == 0:
            return np.zeros(0, dtype=bool), np.zeros(0, dtype=bool)
        if self.samples == 0 and lost[0]:
            raise ValueError("lost: sample 0 is lost; a record starts and ends with samples that arrived")
        k0 = self.samples

        def when(i: int) -> dict[str, Any]:
            return {"sample": k0 + i, "line": int(lines[i]), **({"t": float(t[i])} if t is not None else {})}

        prev_lost = np.r_[self._prev_lost, lost[:-1]]
        stepped = ~lost & ~prev_lost
        prev_stepped = np.r_[self._prev_stepped, stepped[:-1]]
        starts = stepped & ~prev_stepped
        ends = ~stepped & prev_stepped  # the sample after a segment's last
        begins = lost & ~prev_lost
        rejected = ~lost & prev_lost
        drop = np.zeros((L + 1, len(self.names)), dtype=np.int64)
        np.cumsum(~valid, axis=0, out=drop[1:])
        seg = 0  # where the open segment starts in this chunk
        for i in (int(i) for i in np.flatnonzero(starts | ends | begins | rejected)):
            if ends[i]:
                self._close(k0 + i, self._drop + drop[i] - drop[seg], when(i - 1) if i else self._last)
            if begins[i]:
                self._gap_first = k0 + i
                self._gap_when = when(i)
            if rejected[i]:
                gone = k0 + i - self._gap_first
                self.gap_count += 1
                self.lost += gone
                self._gaps.add(gone, _gap(self._gap_when, gone, when(i)))
            if starts[i]:
                self._open, seg = k0 + i, i
                self._open_when = when(i)
                self._drop = np.zeros(len(self.names), dtype=np.int64)
        if self._open is not None:
            self._drop = self._drop + drop[L] - drop[seg]
        self._prev_lost, self._prev_stepped = bool(lost[-1]), bool(stepped[-1])
        self._last = when(L - 1)
        self.samples += L
        return stepped, starts

    def _close(self, stop: int, dropouts: np.ndarray, last: dict[str, Any]) -> None:
        assert self._open is not None
        self.segment_count += 1
        self._segments.add(stop - self._open, _segment(self._open_when, last, stop - self._open,
                                                       {name: int(d) for name, d in zip(self.names, dropouts)}))
        self._open = None

    def finish(self) -> None:
        """After the last chunk: closes the last segment; ValueError if the record ends with a lost sample."""
        if self._prev_lost:
            raise ValueError(f"lost: sample {self.samples - 1} is lost; a record starts and ends with samples "
                             "that arrived")
        if self._open is not None:
            self._close(self.samples, self._drop, self._last)

    def report(self) -> dict[str, Any]:
        """The ``gaps`` entry of metrics.json, as :meth:`Segments.report` gives it for the whole record."""
        return _report(self.lost, self._segments, self._gaps)


def segments_of(lost: np.ndarray) -> Segments:
    """The segments of a record whose samples ``lost`` ((T,) bool) never arrived. The first and last
    samples must have arrived (a reader cuts lost ends off); ValueError otherwise."""
    if not isinstance(lost, np.ndarray) or lost.dtype != np.bool_ or lost.ndim != 1 or lost.size < 1:
        raise ValueError("lost: expected a non-empty (T,) bool numpy array")
    if lost[0] or lost[-1]:
        raise ValueError(f"lost: sample {0 if lost[0] else lost.size - 1} is lost; a record starts and ends "
                         "with samples that arrived")
    T = lost.size
    stepped = ~lost
    edges = np.flatnonzero(np.diff(lost.astype(np.int8)))  # k where lost[k] != lost[k + 1]
    gaps: list[Gap] = []
    for a, b in zip(edges[::2] + 1, edges[1::2] + 1):  # lost runs [a, b); sample b revealed it
        gaps.append(Gap(first=int(a), lost=int(b - a), rejected=int(b)))
        stepped[b] = False
    runs = np.flatnonzero(np.diff(np.r_[0, stepped.astype(np.int8), 0]))
    bounds = tuple((int(a), int(b)) for a, b in zip(runs[::2], runs[1::2]))
    assert T == 0 or bounds
    return Segments(bounds=bounds, gaps=tuple(gaps), stepped=stepped)


def simulate_segments(identifier: Identifier, X: np.ndarray, U: np.ndarray, valid: np.ndarray, segs: Segments, *,
                      free_run_from: int | None = None,
                      steps: int | None = None) -> tuple[Simulation, np.ndarray | None, np.ndarray | None]:
    """:func:`simulate` over each segment of ``segs``, :meth:`Identifier.restart` before every one but
    the first; rows not stepped are NaN. The weights are frozen from ``free_run_from`` on; the free run
    starts there and ends with its segment (a parallel model has no input across a gap). Returns the
    simulation and the rows each kind can be scored on: (free run rows, k-step rows) as (T,) bool
    (None when not asked for). An ``IdentifierError`` names the sample in the whole record."""
    T, n = X.shape
    nan = np.full((T, n), np.nan, dtype=X.dtype)
    one, free, ahead = nan.copy(), None if free_run_from is None else nan.copy(), None if steps is None else nan.copy()
    free_rows = None if free_run_from is None else np.zeros(T, dtype=bool)
    ahead_rows = None if steps is None else np.zeros(T, dtype=bool)
    diverged: int | None = None
    learning = identifier.learning
    nxt = identifier.prediction
    free_started = False  # the free run starts in the first segment that reaches free_run_from
    try:
        for i, (a, b) in enumerate(segs.bounds):
            if i:
                identifier.restart()
            K = free_run_from
            local = None if K is None or K >= b or free_started else max(K - a, 0)
            free_started = free_started or local is not None
            try:
                sim = simulate(identifier, X[a:b], U[a:b], valid[a:b], free_run_from=local, steps=steps)
            except IdentifierError as exc:
                text = re.sub(r"at sample (\d+)", lambda m: f"at sample {int(m.group(1)) + a}", str(exc))
                raise IdentifierError(exc.status, text, None if exc.sample is None else exc.sample + a) from None
            one[a:b] = sim.one_step
            if sim.free_run is not None and free is not None and free_rows is not None:
                free[a:b] = sim.free_run
                free_rows[a + (local or 0):b] = True
                if sim.free_run_diverged is not None:
                    diverged = a + sim.free_run_diverged
                identifier.learning = False
            if sim.ahead is not None and ahead is not None and ahead_rows is not None:
                ahead[a:b] = sim.ahead
                ahead_rows[min(a + (steps or 0), b):b] = True
            nxt = sim.next_prediction
    finally:
        identifier.learning = learning
    return (Simulation(one_step=one, next_prediction=nxt, free_run=free, free_run_diverged=diverged, ahead=ahead,
                       free_run_from=free_run_from, steps=steps), free_rows, ahead_rows)
