"""Measurement files: a CSV of states and inputs named by an identifier config.

Read by ``pyrhonn identify`` and ``pyrhonn tune --data``; written by
:func:`write_data` (``pyrhonn identify --can-log`` writes the samples it
aligned from a bus log so).

Input file
----------
UTF-8 text (a byte-order mark is allowed), comma-separated, first line a
header naming the columns; one line per sample k = 0..T-1, in time order.

- One column per state and per input, named by the config's ``state_names``
  and ``input_names`` (``pyrhonn show-config`` prints them). ``--config``
  also accepts the name of a shipped config (e.g. ``example1``).
- Optional ``t``: the sample time, finite and strictly increasing; used as
  the x axis of the plots and copied to the predictions.
- Optional per-state validity columns ``<state><suffix>`` (suffix
  ``_valid`` unless ``valid_suffix`` says otherwise) holding ``0`` or
  ``1``: 0 marks a measurement that was not updated (a dropout or a delay).
  The identifier does not learn from it and uses its own prediction in its
  place (see :meth:`pyrhonn.Identifier.run`); its cell may be empty or NaN.
  A state without a validity column is valid on every line.
- Other columns are ignored (and listed on the output).
- Numbers are decimal (``-1.5``, ``2e-3``); spaces around a cell are allowed.
  An empty cell or ``nan`` is a missing value, allowed only in a state
  column whose validity is 0 on that line. Infinities, other text, missing
  inputs or times are errors.

Every defect (undecodable text, malformed CSV, an empty file, a header
without data, duplicate or missing columns, a line with the wrong number of
fields, a non-numeric cell, a missing value in a valid state, a bad
validity flag) raises ``ValueError`` as ``<file>: line <N>: ...`` with N
1-based, the header being line 1 (a quoted cell spanning lines counts them
all; N is the first line of the record).
"""
from __future__ import annotations

import csv
import io
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from . import atomic
from .configfile import ConfigFile
from .validation import decode_text, read_file

__all__ = ["Data", "TIME_COLUMN", "check_suffix", "read_data", "write_data"]

_NUMBER = re.compile(r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?\Z")
_MISSING = ("", "nan", "NaN", "NAN")
_INFINITE = re.compile(r"[+-]?(?:inf|Inf|INF|infinity|Infinity|INFINITY)\Z")
TIME_COLUMN = "t"
MAX_FILE_BYTES = 1 << 30  #: 1 GiB of CSV: ~10 million rows of a 9-column log, beyond what one run holds



def check_suffix(text: str) -> str:
    """A validity-column suffix: non-empty, no CSV syntax, no outer spaces."""
    if not text or any(c in text for c in ",\"\r\n") or text != text.strip():
        raise ValueError(f"expected a non-empty column-name suffix, got {text!r}")
    return text


@dataclass(frozen=True)
class Data:
    """A data file as read: T samples.

    ``X`` (T, n) float64 with NaN where a state is missing, ``U`` (T, m),
    ``valid`` (T, n) bool, ``t`` (T,) or None, ``lines`` (T,) the file line
    of each sample, ``ignored`` the columns not used.
    """

    X: np.ndarray
    U: np.ndarray
    valid: np.ndarray
    t: np.ndarray | None
    lines: np.ndarray
    ignored: tuple[str, ...]

    @property
    def n_samples(self) -> int:
        return int(self.X.shape[0])

    def in_dtype(self, dtype: str, state_names: Sequence[str], input_names: Sequence[str],
                 source: str) -> tuple[np.ndarray, np.ndarray]:
        """``(X, U)`` in ``dtype`` (the core the identifier runs in); ValueError naming
        the line and column of a measured value or input that overflows it."""
        def convert(a: np.ndarray, names: Sequence[str], mask: np.ndarray | None) -> np.ndarray:
            with np.errstate(over="ignore"):
                out = a.astype(dtype)
            bad = ~np.isfinite(out) & np.isfinite(a)
            if mask is not None:
                bad &= mask
            if bad.any():
                k, j = (int(i) for i in np.argwhere(bad)[0])
                raise ValueError(f"{source}: line {int(self.lines[k])}, column {names[j]!r}: {float(a[k, j])!r} "
                                 f"overflows {dtype} (--dtype {dtype})")
            return out

        return convert(self.X, state_names, self.valid), convert(self.U, input_names, None)


def _records(text: str, source: str) -> list[tuple[int, list[str]]]:
    """Every CSV record with the line it starts on; blank lines are kept as []."""
    reader = csv.reader(io.StringIO(text, newline=""), strict=True)
    out: list[tuple[int, list[str]]] = []
    last = 0
    while True:
        try:
            record = next(reader)
        except StopIteration:
            return out
        except csv.Error as exc:
            hint = " (a quote that is never closed?)" if "end of data" in str(exc) else ""
            raise ValueError(f"{source}: line {last + 1}: malformed CSV: {exc}{hint}") from None
        if len(record) == 1 and not record[0].strip():
            record = []
        out.append((last + 1, record))
        last = reader.line_num


def _cell(source: str, line: int, column: str, text: str) -> float:
    """A numeric cell: a float, NaN for a missing value; ValueError otherwise."""
    s = text.strip()
    if _NUMBER.match(s):
        value = float(s)
        if not np.isfinite(value):
            raise ValueError(f"{source}: line {line}, column {column!r}: {s!r} is out of the float64 range")
        return value
    if s in _MISSING:
        return float("nan")
    if _INFINITE.match(s):
        raise ValueError(f"{source}: line {line}, column {column!r}: not finite: {s!r}")
    raise ValueError(f"{source}: line {line}, column {column!r}: not a number: {text!r}")


def read_data(path: str | Path, cf: ConfigFile, *, valid_suffix: str = "_valid",
              config_source: str = "the config") -> Data:
    """Read and check a data file for the config ``cf`` (see the module docs)."""
    source = str(path)
    text = decode_text(read_file(path, source, limit=MAX_FILE_BYTES), source, bom=True)  # spreadsheets write a BOM
    if not text.strip():
        raise ValueError(f"{source}: empty file (expected a header row naming the columns, then the data)")
    records = _records(text, source)
    header_line, header = records[0]
    if not header:
        raise ValueError(f"{source}: line {header_line}: empty line where the header row was expected")
    names = [h.strip() for h in header]
    where: dict[str, int] = {}
    for c, name in enumerate(names):
        if not name:
            raise ValueError(f"{source}: line {header_line}: column {c + 1} has an empty name")
        if name in where:
            raise ValueError(f"{source}: line {header_line}: duplicate column {name!r} "
                             f"(columns {where[name] + 1} and {c + 1})")
        where[name] = c
    required = list(cf.state_names) + list(cf.input_names)
    missing = [name for name in required if name not in where]
    if missing:
        raise ValueError(
            f"{source}: line {header_line}: missing column{'s' if len(missing) > 1 else ''} "
            + ", ".join(repr(m) for m in missing)
            + f" ({config_source} names the states {', '.join(cf.state_names)}"
            + (f" and the inputs {', '.join(cf.input_names)})" if cf.input_names else " and no inputs)"))
    validity: dict[int, int] = {}
    for j, name in enumerate(cf.state_names):
        vname = f"{name}{valid_suffix}"
        if vname in required or vname == TIME_COLUMN:
            raise ValueError(f"--valid-suffix: the validity column of state {name!r} would be {vname!r}, "
                             "which is also a state, input or time column; choose another suffix")
        if vname in where:
            validity[j] = where[vname]
    used = set(required) | {f"{cf.state_names[j]}{valid_suffix}" for j in validity} | {TIME_COLUMN}
    ignored = tuple(name for name in names if name not in used)
    body = records[1:]
    while body and not body[-1][1]:
        body.pop()  # blank lines at the end of the file
    if not body:
        raise ValueError(f"{source}: line {header_line}: header only, no data rows")
    n, m, T = len(cf.state_names), len(cf.input_names), len(body)
    X = np.empty((T, n))
    U = np.empty((T, m))
    valid = np.ones((T, n), dtype=bool)
    t = np.empty(T) if TIME_COLUMN in where else None
    lines = np.empty(T, dtype=np.int64)
    state_cols = [where[name] for name in cf.state_names]
    input_cols = [where[name] for name in cf.input_names]
    width = len(names)
    for k, (line, record) in enumerate(body):
        lines[k] = line
        if not record:
            raise ValueError(f"{source}: line {line}: empty line inside the data")
        if len(record) != width:
            raise ValueError(f"{source}: line {line}: expected {width} fields as in the header, got {len(record)}")
        if t is not None:
            value = _cell(source, line, TIME_COLUMN, record[where[TIME_COLUMN]])
            if np.isnan(value):
                raise ValueError(f"{source}: line {line}, column 't': missing time")
            if k and not value > t[k - 1]:
                raise ValueError(f"{source}: line {line}, column 't': time {value!r} is not after "
                                 f"{float(t[k - 1])!r} on line {int(lines[k - 1])} (times must increase)")
            t[k] = value
        for j, c in validity.items():
            flag = record[c].strip()
            if flag not in ("0", "1"):
                raise ValueError(f"{source}: line {line}, column {names[c]!r}: expected 0 or 1, got {record[c]!r}")
            valid[k, j] = flag == "1"
        for j, c in enumerate(state_cols):
            value = _cell(source, line, names[c], record[c])
            if np.isnan(value) and valid[k, j]:
                how = (f"{names[validity[j]]} = 1" if j in validity
                       else f"no {cf.state_names[j]}{valid_suffix!s} column; add one with 0 on this line "
                            "to mark a missing measurement")
                raise ValueError(f"{source}: line {line}, column {names[c]!r}: missing value (empty or NaN) "
                                 f"but the state is marked valid ({how})")
            X[k, j] = value
        for j, c in enumerate(input_cols):
            value = _cell(source, line, names[c], record[c])
            if np.isnan(value):
                raise ValueError(f"{source}: line {line}, column {names[c]!r}: missing input value "
                                 "(inputs must be given on every line)")
            U[k, j] = value
    return Data(X=X, U=U, valid=valid, t=t, lines=lines, ignored=ignored)


def write_data(path: str | Path, data: Data, cf: ConfigFile, *, valid_suffix: str = "_valid") -> None:
    """Write ``data`` as a data file that :func:`read_data` reads back equal
    (``t`` if given, the states, the inputs, a validity column per state; an
    invalid state's cell empty; floats written exactly), whole or not at all
    (:mod:`pyrhonn.atomic`)."""
    check_suffix(valid_suffix)
    n, m = len(cf.state_names), len(cf.input_names)
    if data.X.shape != (data.n_samples, n) or data.U.shape != (data.n_samples, m):
        raise ValueError(f"data: expected X ({data.n_samples}, {n}) and U ({data.n_samples}, {m}) for the config, "
                         f"got {data.X.shape} and {data.U.shape}")
    header = ([TIME_COLUMN] if data.t is not None else []) + list(cf.state_names) + list(cf.input_names) + \
        [f"{name}{valid_suffix}" for name in cf.state_names]
    with atomic.replacing(path, "w", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(header)
        for k in range(data.n_samples):
            row = [repr(float(data.t[k]))] if data.t is not None else []
            row += [repr(float(data.X[k, j])) if data.valid[k, j] else "" for j in range(n)]
            row += [repr(float(v)) for v in data.U[k]]
            row += ["1" if v else "0" for v in data.valid[k]]
            w.writerow(row)
