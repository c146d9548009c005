"""Option parsing shared by the subcommands: numbers given on the command
line, checked with a message that names the option."""
from __future__ import annotations

import argparse
import math
from contextlib import contextmanager
from typing import Iterator

__all__ = ["name_units", "options_named", "real_option", "row_range"]


def real_option(option: str, text: str, *, positive: bool = False, nonnegative: bool = False) -> float:
    """``text`` as a finite float; ValueError ``"<option>: ..."`` otherwise."""
    try:
        value = float(text)
    except ValueError:
        raise ValueError(f"{option}: expected a number, got {text!r}") from None
    if not math.isfinite(value):
        raise ValueError(f"{option}: expected a finite number, got {text!r}")
    if positive and not value > 0:
        raise ValueError(f"{option}: must be > 0, got {text!r}")
    if nonnegative and not value >= 0:
        raise ValueError(f"{option}: must be >= 0, got {text!r}")
    return value


@contextmanager
def options_named(**options: str) -> Iterator[None]:
    """Library errors name their fields (``horizon: ...``); inside this block
    the ones named here are re-raised with the command-line option instead
    (``options_named(horizon="--horizon")`` gives ``--horizon: ...``)."""
    try:
        yield
    except ValueError as exc:
        field, sep, rest = str(exc).partition(": ")
        if sep and field in options:
            raise ValueError(f"{options[field]}: {rest}") from None
        raise


def row_range(option: str, text: str | None, n_samples: int) -> tuple[int, int]:
    """``text`` ``"A:B"`` (samples A..B-1, 0-based; A or B may be left out) as ``(a, b)`` within
    0..n_samples, at least 2 samples; None is every sample. ValueError ``"<option>: ..."`` otherwise."""
    if text is None:
        return 0, n_samples
    a, sep, b = text.partition(":")
    try:
        lo = int(a) if a.strip() else 0
        hi = int(b) if b.strip() else n_samples
    except ValueError:
        lo = hi = -1
    if not sep or lo < 0 or hi < 0:
        raise ValueError(f"{option}: expected A:B (samples A..B-1, 0-based), got {text!r}")
    if b.strip() and hi <= lo:
        raise ValueError(f"{option}: expected 0 <= A < B, got {text!r}")
    hi = min(hi, n_samples)
    if lo >= n_samples or hi - lo < 2:
        raise ValueError(f"{option}: {text} leaves fewer than 2 of the {n_samples} samples")
    return lo, hi


def name_units(text: str) -> dict[str, str]:
    """``--units``: NAME=UNIT pairs, comma-separated (an argparse type; the names are checked against the
    config by the command)."""
    units: dict[str, str] = {}
    for item in text.split(","):
        name, sep, unit = item.partition("=")
        name, unit = name.strip(), unit.strip()
        if not sep or not name or not unit:
            raise argparse.ArgumentTypeError(f"expected NAME=UNIT[,NAME=UNIT...], got {item.strip()!r}")
        if name in units:
            raise argparse.ArgumentTypeError(f"{name!r} is given twice")
        units[name] = unit
    return units
