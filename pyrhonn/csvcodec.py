"""The CSV text codec of data files and predictions, in C (``pyrhonn._csvtext``, built from
``pyrhonn/csv_c/pyrhonn_csv.c``; host code, not part of the core).

:func:`format_rows` writes a block of float64 values as CSV lines, each value as its shortest
decimal that reads back as the same float64 (the text ``repr`` writes, ``0.1``, ``1e-05``,
``100.0``): a file written so reads back bit for bit. :func:`parse_rows` reads a block of numeric
CSV lines (no quotes) into columns, each number correctly rounded (as ``float``), and names the
line and column of the first cell that is not a plain decimal number, or of a line with the wrong
number of fields; :mod:`pyrhonn.datafile` reads such a block cell by cell again for its own,
fuller error messages.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from . import _csvtext

__all__ = ["CELL_MAX", "CellError", "Layout", "format_rows", "parse_rows"]

_ffi, _lib = _csvtext.ffi, _csvtext.lib
CELL_MAX: int = int(_lib.PYRHONN_CSV_CELL_MAX)  #: the most characters a value takes ("-1.2345678901234567e-308")
_SEPARATORS = (",", ";", "\t")


class CellError(ValueError):
    """A block :func:`parse_rows` refuses: ``row`` its 1-based line in the block, ``column`` the
    field's name (None when the line itself is at fault: a blank line, a lone carriage return, or the
    wrong number of fields)."""

    def __init__(self, message: str, row: int, column: str | None) -> None:
        super().__init__(message)
        self.row, self.column = row, column


def _separator(sep: str) -> bytes:
    if sep not in _SEPARATORS:
        raise ValueError(f"sep: expected ',', ';' or a tab, got {sep!r}")
    return sep.encode()


def format_rows(values: np.ndarray, show: np.ndarray | None = None, integer: Sequence[bool] = (),
                sep: str = ",") -> bytes:
    """The CSV lines of ``values`` (float64, (rows, cols)), one per row, each ended by ``\\n``: every
    value its shortest round-trip decimal; empty where it is not finite or ``show`` (bool, same shape)
    is False. A column whose ``integer`` entry is True holds whole numbers (below 2^53 in magnitude),
    written without a decimal point (``12``); ValueError naming the row and column of one that is not."""
    if not isinstance(values, np.ndarray) or values.dtype != np.float64 or values.ndim != 2:
        raise ValueError(f"values: expected a 2-D float64 array, got {getattr(values, 'dtype', type(values))} "
                         f"{getattr(values, 'shape', '')}")
    rows, cols = values.shape
    if show is not None and (not isinstance(show, np.ndarray) or show.dtype != np.bool_ or show.shape != values.shape):
        raise ValueError(f"show: expected a bool array of shape {values.shape}, got "
                         f"{getattr(show, 'dtype', type(show))} {getattr(show, 'shape', '')}")
    if integer and len(integer) != cols:
        raise ValueError(f"integer: expected one flag per column ({cols}), got {len(integer)}")
    sep_byte = _separator(sep)
    if rows == 0:
        return b""
    v = np.ascontiguousarray(values)
    s = None if show is None else np.ascontiguousarray(show).view(np.uint8)
    ints = bytes(int(bool(f)) for f in integer) if integer else None
    cap = rows * (cols + 1) * (CELL_MAX + 1)
    out = np.empty(cap, dtype=np.uint8)  # not zeroed: only the n bytes written are kept
    n = _lib.pyrhonn_csv_format(_ffi.from_buffer("double[]", v), _ffi.NULL if s is None else _ffi.from_buffer(s),
                                rows, cols, _ffi.NULL if ints is None else ints, sep_byte,
                                _ffi.from_buffer(out), cap)
    if n < -1:
        r, c = divmod(-2 - n, cols)
        raise ValueError(f"values: row {r}, column {c}: {float(v[r, c])!r} is not a whole number below 2^53 "
                         "(an integer column)")
    if n < 0:  # cannot happen: cap holds every row at its longest
        raise RuntimeError("format_rows: the output buffer was too small")
    return out[:n].tobytes()


@dataclass(frozen=True)
class Layout:
    """The fields of the lines :func:`parse_rows` reads: ``names`` (one per field), ``numbers`` and
    ``flags`` the indices of the fields read as numbers and as 0/1 flags (the others are skipped)."""

    names: tuple[str, ...]
    numbers: tuple[int, ...]
    flags: tuple[int, ...] = ()

    def __post_init__(self) -> None:
        used = list(self.numbers) + list(self.flags)
        if len(set(used)) != len(used) or any(not 0 <= f < len(self.names) for f in used):
            raise ValueError(f"Layout: numbers {self.numbers} and flags {self.flags} must be distinct fields "
                             f"among the {len(self.names)} names")


def parse_rows(text: bytes, layout: Layout, sep: str = ",") -> tuple[np.ndarray, np.ndarray]:
    """The lines of ``text`` (lines ended by ``\\n`` or ``\\r\\n``, the last one possibly not; no quotes, no
    blank line): ``(numbers, flags)``, numbers (L, len(layout.numbers)) float64 (NaN for an empty cell), flags
    (L, len(layout.flags)) uint8 (0 or 1 for a bare ``0`` or ``1``, 2 for anything else). A number is
    a decimal (``-1.5``, ``2e-3``, ``.5``) with spaces around it allowed; anything else (``nan``,
    ``inf``, a decimal comma, text, a value beyond the float64 range) raises :class:`CellError`
    naming the line and the field; a line with the wrong number of fields, a blank line or a lone
    ``\\r`` (a line end to the csv module) raise it naming the line."""
    if not isinstance(text, bytes):
        raise ValueError(f"text: expected bytes, got {type(text).__name__}")
    sep_byte = _separator(sep)
    fields = len(layout.names)
    kind = bytearray(fields)
    slot = np.zeros(max(fields, 1), dtype=np.uintp)
    for i, f in enumerate(layout.numbers):
        kind[f], slot[f] = 1, i
    for i, f in enumerate(layout.flags):
        kind[f], slot[f] = 2, i
    lines = text.count(b"\n") + (0 if text.endswith(b"\n") or not text else 1)
    numbers = np.empty((lines, len(layout.numbers)), dtype=np.float64)
    flags = np.empty((lines, len(layout.flags)), dtype=np.uint8)
    bad = _ffi.new("long long *")
    got = _lib.pyrhonn_csv_parse(text, len(text), sep_byte, fields, bytes(kind), _ffi.from_buffer("size_t[]", slot),
                                 _ffi.from_buffer("double[]", numbers) if numbers.size else _ffi.NULL,
                                 numbers.shape[1], _ffi.from_buffer(flags) if flags.size else _ffi.NULL,
                                 flags.shape[1], lines, bad)
    if got < 0:
        row = int(-got)
        if bad[0] < 0:
            raise CellError(f"line {row}: a blank line, a lone carriage return, or not {fields} fields", row, None)
        name = layout.names[int(bad[0])]
        raise CellError(f"line {row}, column {name!r}: not a decimal number in the float64 range", row, name)
    return numbers[:got], flags[:got]
