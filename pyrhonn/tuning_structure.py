"""Structure search inside the tuning: the selection settings a trial draws
(:class:`StructureSearch`) and each fold's selection for them, cached.
:mod:`pyrhonn.tuning` describes it (Structure search)."""
from __future__ import annotations

import threading
from dataclasses import dataclass
from typing import Any, Mapping


from .config import Activation, IdentifierConfig
from .identifier import capacities
from .structure import CandidateSpace, Criterion, Selection, select
from .validation import check_int, check_real, fail
from .tuning_objective import TrialFailure, _Problem

__all__ = ["STRUCTURE_SETTINGS", "StructureSearch"]

STRUCTURE_SETTINGS = ("max_delay", "degree", "max_terms")
"""The settings of :func:`pyrhonn.structure.select` a structure search searches, in order."""


@dataclass(frozen=True)
class StructureSearch:
    """The selection settings :func:`tune` searches with ``structure=``.

    ``max_delay``, ``degree`` and ``max_terms`` are inclusive integer ranges
    ``(low, high)`` (low == high fixes a setting) of the deepest state tap,
    the largest product and the most terms per neuron of
    :func:`pyrhonn.structure.select`; the stopping rule ``criterion`` (and
    ``holdout`` for the held-out rule) picks each neuron's terms up to
    ``max_terms``. ``delay_step``, ``factors`` and ``activations`` are fixed
    (:class:`pyrhonn.structure.CandidateSpace`); the slope of S is searched by
    the tuning's beta, so the selection uses beta = 1.
    """

    max_delay: tuple[int, int] = (0, 4)
    degree: tuple[int, int] = (1, 2)
    max_terms: tuple[int, int] = (2, 16)
    delay_step: int = 1
    factors: tuple[str, ...] = ("S", "u", "1")
    activations: tuple[Activation, ...] = (Activation.BIPOLAR, Activation.LOGISTIC)
    criterion: Criterion = Criterion.EBIC
    holdout: float = 0.2

    def __post_init__(self) -> None:
        limits = {"max_delay": (0, 254), "degree": (1, 4), "max_terms": (1, 255)}
        for name, (lo_min, hi_max) in limits.items():
            r = getattr(self, name)
            if not isinstance(r, tuple) or len(r) != 2:
                raise fail(name, f"expected a range (low, high) of whole numbers, got {r!r}")
            low = check_int(f"{name}.low", r[0], lo_min, hi_max)
            high = check_int(f"{name}.high", r[1], lo_min, hi_max)
            if low > high:
                raise fail(name, f"low must be <= high, got ({low}, {high})")
        check_int("delay_step", self.delay_step, 1, 254)
        try:
            object.__setattr__(self, "criterion", Criterion(self.criterion))
        except ValueError:
            raise fail("criterion", f"expected one of {[c.value for c in Criterion]}, got {self.criterion!r}") from None
        h = check_real("holdout", self.holdout)
        if not 0.0 < h < 1.0:
            raise fail("holdout", f"expected a fraction in (0, 1), got {h!r}")
        self.space(self.max_delay[1], self.degree[1])  # factors and activations, checked by CandidateSpace

    def space(self, max_delay: int, degree: int) -> CandidateSpace:
        """The candidate space of one trial."""
        return CandidateSpace(max_delay=max_delay, delay_step=self.delay_step, degree=degree,
                              factors=self.factors, activations=self.activations, betas=(1.0,))

    def dimensions(self) -> tuple[tuple[str, int, int], ...]:
        """``(setting, low, high)`` of each searched setting, in :data:`STRUCTURE_SETTINGS` order."""
        return tuple((name, *getattr(self, name)) for name in STRUCTURE_SETTINGS)

    def check(self, config: IdentifierConfig) -> None:
        """Refuse settings beyond the compiled capacities or the data's inputs (``ValueError`` naming the field)."""
        caps = capacities(config.dtype)
        for name, value, cap in (("max_delay", self.max_delay[1], "RHONN_MAX_DELAY"),
                                 ("degree", self.degree[1], "RHONN_MAX_FACTORS"),
                                 ("degree", self.degree[1], "RHONN_MAX_POWER"),
                                 ("max_terms", self.max_terms[1], "RHONN_MAX_TERMS")):
            if value > caps[cap]:
                raise fail(f"structure.{name}", f"{value} exceeds the compiled capacity {cap} = {caps[cap]} "
                                                "(pyrhonn info)")
        if "u" in self.factors and config.n_inputs == 0:
            raise fail("structure.factors", "'u' asks for input factors but the data has no inputs")

    def to_dict(self) -> dict[str, Any]:
        return {"max_delay": list(self.max_delay), "degree": list(self.degree), "max_terms": list(self.max_terms),
                "delay_step": self.delay_step, "factors": list(self.factors),
                "activations": [a.value for a in self.activations], "criterion": self.criterion.value,
                "holdout": self.holdout}


class _Selector:
    """Each fold's selection for given settings, on the fold's training part, cached (thread-safe)."""

    def __init__(self, problem: _Problem, structure: StructureSearch) -> None:
        self.problem = problem
        self.structure = structure
        self._cache: dict[tuple[int, tuple[int, ...]], Selection | str] = {}
        self._lock = threading.Lock()

    def selection(self, fold: int, settings: Mapping[str, int]) -> Selection:
        key = (fold, tuple(settings[name] for name in STRUCTURE_SETTINGS))
        with self._lock:
            hit = self._cache.get(key)
        if hit is None:
            X, U, valid = self.problem.raw
            N = self.problem.folds[fold][0]
            sp = self.structure
            try:
                hit = select(X[:N], U[:N], valid[:N], space=sp.space(settings["max_delay"], settings["degree"]),
                             criterion=sp.criterion, max_terms=settings["max_terms"], holdout=sp.holdout)
            except ValueError as exc:
                hit = f"selection on samples 0..{N - 1} refused: {exc}"
            with self._lock:
                self._cache[key] = hit
        if isinstance(hit, str):
            raise TrialFailure(hit)
        return hit

    def configs(self, settings: Mapping[str, int]) -> list[IdentifierConfig]:
        """The selected config of every fold (its own P0, Q, R, w0; the problem's dtype): P0 the fit's
        covariance of the weights, which trials scale by a factor (its shape kept)."""
        return [self.selection(f, settings).config(dtype=self.problem.dtype)
                for f in range(len(self.problem.folds))]
