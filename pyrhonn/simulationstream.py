"""Validation of an identifier over a record read a chunk at a time: :func:`pyrhonn.gaps.simulate_segments`
(and so :func:`pyrhonn.simulation.simulate`) with a free run and H-step-ahead predictions, bit for bit,
whatever the chunks.

:class:`SimulationStream` takes each chunk's states, inputs, validity and the
gap flags of :class:`pyrhonn.gaps.SegmentTracker` (samples stepped, first of
a segment) and gives back the rows it has finished, aligned with the data as
``simulate`` gives them. It carries across chunks:

- the identifier itself (the one-step pass: learning before the free run's
  sample K, weights frozen from it on) and a checkpoint of the free run (the
  network from K on fed its own predictions), stepped in turn;
- the rows whose H-step branch needs inputs not yet read: a branch from
  sample k runs on the inputs of samples k+1..k+H-1, so the last H rows of a
  segment still open wait for the next chunk (with the branch results
  already made for them). Memory is bounded by the chunk and H, whatever the
  record's length.

A restart begins every segment but the first (:mod:`pyrhonn.gaps`); the
free run starts at the first sample stepped at or after K and ends with its
segment (or where it diverged).
"""
from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from .identifier import Identifier, IdentifierError

__all__ = ["SimulationStream", "Rows"]


@dataclass(frozen=True)
class Rows:
    """Rows ``k0``.. of the record, finished: every (L, n) array aligned with the data (row k estimates x(k),
    NaN where there is none); ``stepped`` (L,) as fed, ``starts`` (L,) the first sample of each segment; ``free_rows`` (L,) the rows of the free
    run's segment from its first sample on (None without a free run); ``ahead_rows`` (L,) the rows at least H
    samples into their segment (None without ``steps``)."""

    k0: int
    one_step: np.ndarray
    free_run: np.ndarray | None
    ahead: np.ndarray | None
    stepped: np.ndarray
    starts: np.ndarray
    free_rows: np.ndarray | None
    ahead_rows: np.ndarray | None

    @property
    def n_rows(self) -> int:
        return int(self.stepped.shape[0])


class SimulationStream:
    """``simulate_segments(identifier, X, U, valid, segments, free_run_from=K, steps=H)`` a chunk at a time
    (see the module docs). :meth:`feed` each chunk, then :meth:`finish`; each returns the rows finished (or
    None). ``next_prediction`` is x̂ after the last sample stepped; ``free_run_diverged`` the first row the free
    run could not reach (None if it did not diverge); ``free_start`` the sample the free run started at. An
    ``IdentifierError`` of the one-step pass names the sample in the whole record."""

    def __init__(self, identifier: Identifier, *, free_run_from: int | None = None, steps: int | None = None) -> None:
        if not isinstance(identifier, Identifier):
            raise ValueError(f"identifier: expected a pyrhonn Identifier, got {type(identifier).__name__}")
        if free_run_from is not None and (isinstance(free_run_from, bool) or not isinstance(free_run_from, int)
                                          or free_run_from < 0):
            raise ValueError(f"free_run_from: expected a whole number >= 0, got {free_run_from!r}")
        if steps is not None and (isinstance(steps, bool) or not isinstance(steps, int) or steps < 1):
            raise ValueError(f"steps: expected a whole number >= 1, got {steps!r}")
        self._id = identifier
        self._K = free_run_from
        self._h = steps
        n, m, dtype = identifier._n, identifier._m, identifier._dtype
        self._n, self._dtype = n, dtype
        self._X = np.zeros((0, n), dtype=dtype)
        self._U = np.zeros((0, m), dtype=dtype)
        self._V = np.zeros((0, n), dtype=bool)
        self._stepped = np.zeros(0, dtype=bool)
        self._starts = np.zeros(0, dtype=bool)
        self._last_stepped = False  # the last sample fed was stepped
        self._ahead = np.full((0, n), np.nan, dtype=dtype)  # branch results made for the rows held
        self._S = 0  # the record's index of the first row held
        self._segments = 0
        self._seg_start = 0
        self._prev = identifier.prediction  # x̂ of the next row of the open segment
        self.next_prediction = identifier.prediction
        self._free_state: object = None
        self._free_next = np.full(n, np.nan, dtype=dtype)
        self._in_free = False  # in the free run's segment, from its start
        self.free_start: int | None = None
        self.free_run_diverged: int | None = None
        self.failed: IdentifierError | None = None  # the one-step pass's failure: the stream stopped there

    def feed(self, X: np.ndarray, U: np.ndarray, valid: np.ndarray, stepped: np.ndarray) -> Rows | None:
        """The next chunk: ``X`` (L, n), ``U`` (L, m) of the identifier's dtype, ``valid`` (L, n) bool,
        ``stepped`` (L,) bool, the samples the identifier steps on (:meth:`pyrhonn.gaps.SegmentTracker.feed`;
        a run of them is a segment). ValueError naming the argument, nothing taken, on a bad chunk; after a
        failure of the identifier the stream takes nothing more."""
        if self.failed is not None:
            raise ValueError(f"the stream stopped: {self.failed}")
        L = X.shape[0] if isinstance(X, np.ndarray) and X.ndim == 2 else -1
        for name, a, shape, kind in (("X", X, (L, self._n), self._dtype), ("U", U, (L, self._U.shape[1]), self._dtype),
                                     ("valid", valid, (L, self._n), np.dtype(bool)),
                                     ("stepped", stepped, (L,), np.dtype(bool))):
            if not isinstance(a, np.ndarray) or a.shape != shape or a.dtype != kind:
                raise ValueError(f"{name}: expected a {kind} array of shape {shape if L >= 0 else '(L, ...)'}")
        try:
            self._id._finite_trajectory(X[stepped], U[stepped], valid[stepped])  # a lost sample has no inputs
        except ValueError as exc:  # named by the record's sample, not the chunk's stepped rows
            rows, first = np.flatnonzero(stepped), self._S + self._X.shape[0]
            raise ValueError(re.sub(r"^([XU])\[(\d+), ", lambda m: f"{m.group(1)}[{first + int(rows[int(m.group(2))])}, ",
                                    str(exc))) from None
        self._X = np.concatenate([self._X, X])
        self._U = np.concatenate([self._U, U])
        self._V = np.concatenate([self._V, valid])
        self._stepped = np.concatenate([self._stepped, stepped])
        if L:
            starts = stepped & ~np.r_[self._last_stepped, stepped[:-1]]
            self._last_stepped = bool(stepped[-1])
            self._starts = np.concatenate([self._starts, starts])
        self._ahead = np.concatenate([self._ahead, np.full((L, self._n), np.nan, dtype=self._dtype)])
        return self._advance(final=False)

    def finish(self) -> Rows | None:
        """After the last chunk: the rows still held."""
        if self.failed is not None:
            raise ValueError(f"the stream stopped: {self.failed}")
        return self._advance(final=True)

    def _advance(self, final: bool) -> Rows | None:
        B = self._X.shape[0]
        h = self._h or 0
        open_end = B > 0 and bool(self._stepped[-1]) and not final
        limit = max(B - h, 0) if open_end and h >= 2 else B  # a branch from row t reads rows to t+h-1
        if limit == 0:
            return None
        with self._id._lock:  # one pass at a time on this identifier (see its class docs)
            return self._rows(B, limit)

    def _rows(self, B: int, limit: int) -> Rows:
        """Rows 0..limit-1 of the ``B`` held stepped (one-step pass, branches, free run) and given back."""
        h = self._h or 0
        ident, n, S, K, dtype = self._id, self._n, self._S, self._K, self._dtype
        X, U, V = self._X, self._U, self._V  # C-contiguous: concatenated, then cut by rows
        nan = np.full((limit, n), np.nan, dtype=dtype)
        one = nan.copy()
        free = None if K is None else nan.copy()
        free_rows = None if K is None else np.zeros(limit, dtype=bool)
        ahead_rows = None if self._h is None else np.zeros(limit, dtype=bool)
        out = np.full((B, n), np.nan, dtype=dtype)  # run convention: row t = x̂(t+1)
        edges = np.flatnonzero(np.diff(np.r_[0, self._stepped.astype(np.int8), 0]))
        for a, b in zip(edges[::2].tolist(), edges[1::2].tolist()):  # stepped runs: segments (or their parts)
            if a >= limit:
                break
            stop = min(b, limit)
            if self._starts[a]:
                if self._segments:
                    ident.restart()
                self._segments += 1
                self._seg_start = S + a
                self._in_free = False
                self._prev = ident.prediction
            cuts = [a, stop] if K is None or not a < K - S < stop else [a, K - S, stop]
            for p, q in zip(cuts[:-1], cuts[1:]):
                if K is not None and S + p >= K and self.free_start is None:  # the free run starts here
                    ident.learning = False
                    self._free_state = ident._checkpoint()
                    self._free_next = self._prev.copy()
                    self._in_free = True
                    self.free_start = S + p
                one[p] = self._prev
                self._one_step(X[:b], U[:b], V[:b], p, q, out)
                one[p + 1:q] = out[p:q - 1]
                self._prev = out[q - 1].copy()
                if self._in_free and free is not None and free_rows is not None:
                    self._free_run(X[:b], U[:b], p, q, free)
                    free_rows[p:q] = True
            if ahead_rows is not None:
                ahead_rows[max(a, self._seg_start - S + h):stop] = True
        self.next_prediction = self._prev.copy()
        ahead: np.ndarray | None = None
        if self._h == 1:
            ahead = np.where((self._stepped[:limit] & ~self._starts[:limit])[:, None], one, np.nan).astype(dtype)
        elif self._h is not None:
            ahead = self._ahead[:limit].copy()
        rows = Rows(k0=S, one_step=one, free_run=free, ahead=ahead, stepped=self._stepped[:limit].copy(),
                    starts=self._starts[:limit].copy(), free_rows=free_rows, ahead_rows=ahead_rows)
        self._X, self._U, self._V = self._X[limit:], self._U[limit:], self._V[limit:]
        self._stepped, self._starts, self._ahead = self._stepped[limit:], self._starts[limit:], self._ahead[limit:]
        self._S = S + limit
        return rows

    def _one_step(self, X: np.ndarray, U: np.ndarray, V: np.ndarray, p: int, q: int, out: np.ndarray) -> None:
        """Rows p..q-1 of the one-step pass (with their branches); ``X`` ends where the segment ends (or where
        the rows held end, when the branches of rows p..q-1 all fit in them)."""
        ident = self._id
        h = self._h or 0
        done, status = ident._pass(X, U, V, p, q, out, ahead=h if h >= 2 else 0, ahead_out=self._ahead)
        if not status:
            return
        try:
            ident._raise_step_error(status, X, U, V, p + done, single=False, neuron=int(ident._net.fault_neuron))
        except IdentifierError as exc:
            S = self._S
            text = re.sub(r"at sample (\d+)", lambda m: f"at sample {int(m.group(1)) + S}", str(exc))
            self.failed = IdentifierError(exc.status, text, None if exc.sample is None else exc.sample + S)
            raise self.failed from None

    def _free_run(self, X: np.ndarray, U: np.ndarray, p: int, q: int, free: np.ndarray) -> None:
        """Rows p..q-1 of the free run (every state the network's own, weights frozen): row p's value is the
        one carried, rows p+1..q-1 this pass's, row q's carried on."""
        free[p] = self._free_next
        if self.free_run_diverged is not None:
            return
        ident = self._id
        mine = ident._checkpoint()
        ident._rollback(self._free_state)
        fout = np.full((X.shape[0], self._n), np.nan, dtype=self._dtype)
        done, status = ident._pass(X, U, np.zeros(X.shape[:1] + (self._n,), dtype=np.bool_), p, q, fout)
        self._free_state = ident._checkpoint()
        ident._rollback(mine)
        free[p + 1:q] = fout[p:q - 1]
        self._free_next = fout[q - 1].copy()  # NaN if the pass stopped before it
        if status:
            self.free_run_diverged = self._S + p + done + 1
