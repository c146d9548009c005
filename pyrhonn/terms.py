"""Builders for common high-order term sets (eq. 4), so nobody writes index
tables by hand. Every builder returns a tuple of terms (tuples of
:class:`~pyrhonn.config.Factor`), ready to concatenate with ``+``.

State and input indices are 0-based, as everywhere in the API.
"""
from __future__ import annotations

from itertools import combinations, combinations_with_replacement
from typing import Iterable, Sequence

from .config import Factor, Term

__all__ = ["bias", "first_order", "inputs", "pairwise_products", "delayed_taps", "delayed_inputs", "powers"]


def _indices(name: str, values: Iterable[int]) -> list[int]:
    out = []
    for v in values:
        if isinstance(v, bool) or not isinstance(v, int) or v < 0:
            raise ValueError(f"{name}: expected non-negative integer indices, got {v!r}")
        out.append(v)
    return out


def _count_or_indices(name: str, value: int | Sequence[int]) -> list[int]:
    """A count n (indices 0..n-1, n in 0..255) or an explicit list of indices."""
    if isinstance(value, bool):
        raise ValueError(f"{name}: expected a count or a list of indices, got {value!r}")
    if isinstance(value, int):
        if not 0 <= value <= 255:
            raise ValueError(f"{name}: a count must be in 0..255, got {value}")
        return list(range(value))
    return _indices(name, value)


def bias() -> tuple[Term, ...]:
    """A single constant term, z = 1."""
    return ((Factor.one(),),)


def first_order(states: int | Sequence[int], inputs: int | Sequence[int] = 0) -> tuple[Term, ...]:
    """S(x_j) for each state j, then u_j for each input j (the xi of eq. 5).

    ``states`` / ``inputs`` are either a count (all indices below it) or an
    explicit list of indices.
    """
    s = _count_or_indices("states", states)
    u = _count_or_indices("inputs", inputs)
    return tuple((Factor.s(j),) for j in s) + tuple((Factor.u(j),) for j in u)


def inputs(indices: int | Sequence[int], power: int = 1) -> tuple[Term, ...]:
    """u_j^power for each input j."""
    u = _count_or_indices("inputs", indices)
    return tuple((Factor.u(j, power),) for j in u)


def pairwise_products(states: int | Sequence[int], squares: bool = False) -> tuple[Term, ...]:
    """S(x_a) S(x_b) for every pair a < b of the given states; with
    ``squares=True`` also S(x_a)^2."""
    s = _count_or_indices("states", states)
    pairs = combinations_with_replacement(s, 2) if squares else combinations(s, 2)
    out: list[Term] = []
    for a, b in pairs:
        out.append((Factor.s(a, power=2),) if a == b else (Factor.s(a), Factor.s(b)))
    return tuple(out)


def delayed_taps(state: int, delays: Sequence[int], raw: bool = False) -> tuple[Term, ...]:
    """S(x_state(k - d)) (or the raw x with ``raw=True``) for each d: the
    multiple / time-varying delays of the paper's Remark 1."""
    (j,) = _indices("state", [state])
    ds = _indices("delays", delays)
    make = Factor.x if raw else Factor.s
    return tuple((make(j, delay=d),) for d in ds)


def delayed_inputs(input_index: int, delays: Sequence[int], power: int = 1) -> tuple[Term, ...]:
    """u_input(k - d)^power for each d: an input that acts on the plant
    after a dead time (``delayed_inputs(0, [3])`` is ``((Factor.u(0, delay=3),),)``)."""
    (j,) = _indices("input_index", [input_index])
    ds = _indices("delays", delays)
    if isinstance(power, bool) or not isinstance(power, int) or power < 1:
        raise ValueError(f"power: expected an integer >= 1, got {power!r}")
    return tuple((Factor.u(j, power, delay=d),) for d in ds)


def powers(state: int, up_to: int) -> tuple[Term, ...]:
    """S(x_state)^p for p = 1..up_to."""
    (j,) = _indices("state", [state])
    if isinstance(up_to, bool) or not isinstance(up_to, int) or up_to < 1:
        raise ValueError(f"up_to: expected an integer >= 1, got {up_to!r}")
    return tuple((Factor.s(j, power=p),) for p in range(1, up_to + 1))
