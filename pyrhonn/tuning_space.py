"""The tuning's search space: which of P0, Q, R, eta and beta are searched,
over which log-uniform ranges, shared or per neuron, and how a trial's
values become a config. :mod:`pyrhonn.tuning` describes it (The search
space)."""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any, Mapping, Sequence

import numpy as np

from .config import IdentifierConfig, NeuronConfig
from .validation import check_real, fail

__all__ = ["DEFAULT_FACTORS", "Dimension", "PARAMETERS", "Q_OVER_P0", "apply_factors", "apply_values", "search_space"]

PARAMETERS = ("p0", "q", "r", "eta", "beta")
"""The tunable fields of :class:`~pyrhonn.config.NeuronConfig`, in search order."""

DEFAULT_FACTORS: dict[str, tuple[float, float]] = {
    "p0": (1e-4, 1e4),
    "q": (1e-4, 1e4),
    "r": (1e-3, 1e3),
    "eta": (1e-2, 2.0),
    "beta": (1e-1, 1e1),
}
"""Default search range of each parameter, as (low, high) factors of its base value."""


Q_OVER_P0 = 1e-3
"""A Q of zero is centred at this fraction of the neuron's P0 (see the module docs)."""


SIGNIFICANT_DIGITS = 3


@dataclass(frozen=True)
class Dimension:
    """One searched value: optuna parameter ``name``, the config field
    ``param`` it sets in ``neurons``, its log-uniform range and the base
    value (None when the base config has no single scalar value in range)."""

    name: str
    param: str
    neurons: tuple[int, ...]
    low: float
    high: float
    base: float | None

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "param": self.param, "neurons": list(self.neurons), "low": self.low,
                "high": self.high, "base": self.base}


def _geomean(values: np.ndarray) -> float:
    return float(np.exp(np.mean(np.log(values))))


def _center(neuron: NeuronConfig, param: str) -> tuple[float, float | None]:
    """``(centre of the default range, scalar base value or None)`` of one neuron's parameter."""
    if param == "p0":
        if isinstance(neuron.p0, np.ndarray):
            return _geomean(np.diag(neuron.p0_matrix())), None
        return float(neuron.p0), float(neuron.p0)
    if param == "q":
        q = neuron.q
        if isinstance(q, np.ndarray):
            positive = q[q > 0]
            if positive.size:
                return _geomean(positive), None
            return _center(neuron, "p0")[0] * Q_OVER_P0, None
        if q > 0:
            return float(q), float(q)
        return _center(neuron, "p0")[0] * Q_OVER_P0, None
    value = float(getattr(neuron, param))
    return value, value


def _round(value: float) -> float:
    return float(f"{value:.{SIGNIFICANT_DIGITS - 1}e}")


def _check_ranges(ranges: Mapping[str, Any] | None) -> dict[str, tuple[float, float]]:
    if ranges is None:
        return {}
    if not isinstance(ranges, Mapping):
        raise fail("ranges", f"expected a mapping of parameter -> (low, high), got {type(ranges).__name__}")
    out: dict[str, tuple[float, float]] = {}
    for key, value in ranges.items():
        if key not in PARAMETERS:
            raise fail("ranges", f"unknown parameter {key!r}; expected one of {', '.join(PARAMETERS)}")
        if not isinstance(value, tuple) or len(value) != 2:
            raise fail(f"ranges[{key!r}]", f"expected a tuple (low, high), got {value!r}")
        low = check_real(f"ranges[{key!r}].low", value[0], positive=True)
        high = check_real(f"ranges[{key!r}].high", value[1], positive=True)
        if not low < high:
            raise fail(f"ranges[{key!r}]", f"low must be < high, got ({low!r}, {high!r})")
        out[key] = (low, high)
    return out


def _check_params(params: Sequence[str]) -> tuple[str, ...]:
    if isinstance(params, str) or not isinstance(params, (tuple, list)):
        raise fail("params", f"expected a tuple of parameter names, got {type(params).__name__}")
    if not params:
        raise fail("params", f"expected at least one of {', '.join(PARAMETERS)}")
    for p in params:
        if p not in PARAMETERS:
            raise fail("params", f"unknown parameter {p!r}; expected some of {', '.join(PARAMETERS)}")
    if len(set(params)) != len(params):
        raise fail("params", f"duplicate entries in {list(params)}")
    return tuple(p for p in PARAMETERS if p in params)


def search_space(config: IdentifierConfig, *, params: Sequence[str] = PARAMETERS, per_neuron: bool = False,
                 ranges: Mapping[str, tuple[float, float]] | None = None,
                 relative: bool = False) -> tuple[Dimension, ...]:
    """The dimensions :func:`tune` searches for ``config`` (see the module docs).

    With ``relative`` (structure search) every dimension is a factor of
    each neuron's own value: the default range is :data:`DEFAULT_FACTORS`,
    ``ranges`` are factor ranges, and the base value is the factor 1.
    """
    if not isinstance(config, IdentifierConfig):
        raise fail("config", f"expected an IdentifierConfig, got {type(config).__name__}")
    if not isinstance(per_neuron, bool):
        raise fail("per_neuron", f"expected a bool, got {type(per_neuron).__name__}")
    chosen = _check_params(params)
    fixed = _check_ranges(ranges)
    dims: list[Dimension] = []
    for param in chosen:
        lo_f, hi_f = DEFAULT_FACTORS[param]
        centres = [(1.0, 1.0) if relative else _center(nr, param) for nr in config.neurons]
        groups = [(f"neurons[{i}].{param}", (i,)) for i in range(config.n_states)] if per_neuron \
            else [(param, tuple(range(config.n_states)))]
        for name, members in groups:
            cs = [centres[i][0] for i in members]
            bases = {centres[i][1] for i in members}
            low, high = fixed.get(param, (min(cs) * lo_f, max(cs) * hi_f))
            base = bases.pop() if len(bases) == 1 else None
            if base is not None and not low <= base <= high:
                base = None
            dims.append(Dimension(name, param, members, float(low), float(high), base))
    return tuple(dims)


def apply_values(config: IdentifierConfig, space: Sequence[Dimension], values: Mapping[str, float]) -> IdentifierConfig:
    """``config`` with every dimension of ``space`` set to ``values[name]``
    rounded to 3 significant digits (the config :func:`tune` evaluates); a
    P0 or Q array is scaled so that its diagonal's geometric mean is the
    value, keeping its shape."""
    return _apply(config, space, values, relative=False)


def apply_factors(config: IdentifierConfig, space: Sequence[Dimension], values: Mapping[str, float]) -> IdentifierConfig:
    """``config`` with every dimension of a relative ``space`` applied as a
    factor (rounded to 3 significant digits) of each neuron's own value
    (structure search: the selected config's P0, Q, R, eta and beta)."""
    return _apply(config, space, values, relative=True)


def _apply(config: IdentifierConfig, space: Sequence[Dimension], values: Mapping[str, float],
           relative: bool) -> IdentifierConfig:
    changes: list[dict[str, Any]] = [{} for _ in config.neurons]
    for dim in space:
        if dim.name not in values:
            raise fail("values", f"missing {dim.name!r}")
        v = _round(check_real(f"values[{dim.name!r}]", values[dim.name], positive=True))
        for i in dim.neurons:
            changes[i][dim.param] = _applied(config.neurons[i], dim.param, v, relative)
    neurons = tuple(replace(nr, **ch) if ch else nr for nr, ch in zip(config.neurons, changes))
    return config.replace(neurons=neurons)


def _applied(neuron: NeuronConfig, param: str, v: float, relative: bool) -> float | np.ndarray:
    """One neuron's new value of ``param`` for the trial value ``v``. A P0 or
    Q array (a matrix or a diagonal with some positive entry) is scaled, so
    that its shape -- the directions the fit determined well and their
    conditioning -- is kept: by ``v`` as a factor (``relative``), else so
    that the geometric mean of its positive diagonal becomes ``v``. A scalar
    (or a Q array of zeros) is set to ``v``, or multiplied by it."""
    own = getattr(neuron, param)
    if isinstance(own, np.ndarray) and np.any(own > 0):
        scale = v if relative else v / _center(neuron, param)[0]
        scaled: np.ndarray = own * scale
        return scaled
    if not relative:
        return v
    if isinstance(own, np.ndarray):  # a Q of zeros: a factor leaves it at zero
        return own
    return float(own) * v
