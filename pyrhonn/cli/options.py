"""Option parsing shared by the subcommands: numbers given on the command
line, checked with a message that names the option."""
from __future__ import annotations

import math
from contextlib import contextmanager
from typing import Iterator

__all__ = ["options_named", "real_option"]


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
