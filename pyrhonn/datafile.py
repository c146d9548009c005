"""Measurement files: a CSV of states and inputs named by an identifier config.

Read whole by :func:`read_data` (``pyrhonn tune --data``, ``select``, ``validate``) or a chunk of rows at
a time by :class:`DataReader` (``pyrhonn identify``, ``select`` on a long record), which reads the file
in blocks of whole lines and parses a plain block in C (:func:`pyrhonn.csvcodec.parse_rows`); written by
:func:`write_data` (``pyrhonn identify --can-log`` writes the samples it
aligned from a bus log so), each value as its shortest round-trip decimal
(:func:`pyrhonn.csvcodec.format_rows`).

Input file
----------
UTF-8 text (a byte-order mark is allowed), first line a header naming the
columns; one line per sample k = 0..T-1, in time order.

- The separator is ``,``, ``;`` or a tab: the one that splits the header
  into the config's names (``sep`` / ``--csv-sep`` sets it). Numbers use a
  decimal point, or a decimal comma (``1,5``) in a file separated by ``;``
  or tabs, as spreadsheets in many locales export it (found from the data,
  or set by ``decimal`` / ``--decimal``).
- An optional **unit row** right after the header: a line none of whose
  cells is a number (``s;m;m/s;V``, ``[s]``, or empty cells); its units are
  kept in ``Data.units`` (brackets dropped).

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
- Optional ``lost`` holding ``0`` or ``1``: 1 marks a sample that never
  arrived (a lost frame); its inputs and states may be empty. The record is
  split there into segments, the firmware's way (:mod:`pyrhonn.gaps`): the
  sample after the gap is not stepped and the identifier restarts on the
  next. The first and last data rows cannot be lost.
- Other columns are ignored (and listed on the output).
- Numbers are decimal (``-1.5``, ``2e-3``, or ``-1,5`` with a decimal
  comma); spaces around a cell are allowed.
  An empty cell or ``nan`` is a missing value, allowed only in a state
  column whose validity is 0 on that line. Infinities, other text, missing
  inputs or times are errors.

A file that is not CSV text (a BLF, MDF or other binary file, a candump or
ASC log) is named as such, with the option that reads it; a missing file
names the closest file names in its folder.

Every defect (undecodable text, malformed CSV, an empty file, a header
without data, duplicate or missing columns, a line with the wrong number of
fields, a non-numeric cell, a missing value in a valid state, a bad
validity flag) raises ``ValueError`` as ``<file>: line <N>: ...`` with N
1-based, the header being line 1 (a quoted cell spanning lines counts them
all; N is the first line of the record).
"""
from __future__ import annotations

import csv
import difflib
import io
import itertools
import os
import re
import stat
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO, Iterable, Iterator, Sequence

import numpy as np

from . import atomic
from .configfile import ConfigFile
from .csvcodec import CellError, Layout, format_rows, parse_rows
from .validation import MissingFileError, near_names

__all__ = ["BLOCK_BYTES", "Data", "DataReader", "LOST_COLUMN", "ROWS_AT_ONCE", "SEPARATORS", "TIME_COLUMN", "check_suffix", "concatenate",
           "data_columns", "data_rows", "header_line", "read_data", "write_data"]

_NUMBER = re.compile(r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?\Z")
#: a column of such numbers, one a line, spaces around them (read in one pass)
_COLUMN = re.compile(r"(?:[^\S\n]*[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?[^\S\n]*(?:\n|\Z))+")
_MISSING = ("", "nan", "NaN", "NAN")
_INFINITE = re.compile(r"[+-]?(?:inf|Inf|INF|infinity|Infinity|INFINITY)\Z")
TIME_COLUMN = "t"
LOST_COLUMN = "lost"  #: 1 marks a sample that never arrived
SEPARATORS = {",": "comma", ";": "semicolon", "\t": "tab"}  #: the column separators read
_DECIMAL_COMMA = re.compile(r"\s*[+-]?[0-9]+,[0-9]+(?:[eE][+-]?[0-9]+)?\s*\Z")
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
    of each sample, ``ignored`` the columns not used; ``lost`` (T,) bool or
    None: the samples that never arrived (NaN inputs, no valid state).
    """

    X: np.ndarray
    U: np.ndarray
    valid: np.ndarray
    t: np.ndarray | None
    lines: np.ndarray
    ignored: tuple[str, ...]
    lost: np.ndarray | None = None
    units: dict[str, str] | None = None

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


def _records(text: str, source: str, sep: str = ",", before: int = 0) -> Iterator[tuple[int, list[str]]]:
    """Every CSV record with the line it starts on (``text`` starting after line ``before``), one at a
    time; blank lines are kept as []."""
    reader = csv.reader(io.StringIO(text, newline=""), strict=True, delimiter=sep)
    last = before
    while True:
        try:
            record = next(reader)
        except StopIteration:
            return
        except csv.Error as exc:
            hint = " (a quote that is never closed?)" if "end of data" in str(exc) else ""
            raise ValueError(f"{source}: line {last + 1}: malformed CSV: {exc}{hint}") from None
        if len(record) == 1 and not record[0].strip():
            record = []
        yield last + 1, record
        last = before + reader.line_num


def _cell(source: str, line: int, column: str, text: str, decimal: str = ".") -> float:
    """A numeric cell: a float, NaN for a missing value; ValueError otherwise."""
    s = text.strip()
    if decimal == ",":
        if "." in s and _NUMBER.match(s):
            raise ValueError(f"{source}: line {line}, column {column!r}: {s!r} has a decimal point, but the file's "
                             "numbers use a decimal comma (--decimal . if they do not)")
        s = s.replace(",", ".")
    elif _DECIMAL_COMMA.match(s):
        raise ValueError(f"{source}: line {line}, column {column!r}: {text.strip()!r} has a decimal comma; the file "
                         "is read with a decimal point (--decimal , to read decimal commas)")
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


def _not_csv(raw: bytes, source: str) -> None:
    """A ValueError for a file that is plainly not CSV text, saying what it is and what reads it."""
    head = raw[:4096]
    first = head.split(b"\n", 1)[0].strip()
    if head.startswith(b"LOGG"):
        what = "a BLF bus log (binary); read it with --can-log FILE.blf --dbc FILE.dbc"
    elif head.startswith(b"MDF "):
        what = "an MDF measurement file (binary), not CSV"
    elif b"\0" in head:
        what = "binary data, not CSV text"
    elif re.match(rb"\(\d+\.\d+\)\s+\S+\s+[0-9A-Fa-f]+#", first):
        what = "a candump log; read it with --can-log FILE.log --dbc FILE.dbc"
    elif first.lower().startswith(b"date ") and b"base " in head.lower():
        what = "an ASC bus log; read it with --can-log FILE.asc --dbc FILE.dbc"
    else:
        return
    raise ValueError(f"{source}: not a CSV file: {what}")


def _separator(header: str, required: Sequence[str], sep: str | None) -> str:
    """The separator: ``sep`` if given, else the one that splits ``header`` into most of ``required``."""
    if sep is not None:
        return sep
    def found(c: str) -> int:
        names = {h.strip() for h in next(csv.reader([header], delimiter=c), [])}
        return sum(name in names for name in required)
    return max(SEPARATORS, key=found)  # ties: the first, a comma


def _decimal(records: Iterable[tuple[int, list[str]]], sep: str, decimal: str | None) -> str:
    """The decimal mark: ``decimal`` if given; else a comma when the separator is not one and a cell of
    the first 100 lines is a number with a decimal comma."""
    if decimal is not None:
        return decimal
    if sep == ",":
        return "."
    for _, record in itertools.islice(records, 1, 101):
        if any(_DECIMAL_COMMA.match(cell) for cell in record):
            return ","
    return "."


def _unit_row(record: list[str], decimal: str) -> bool:
    """Whether the line after the header is a unit row: no cell a number or a missing value marker."""
    cells = [c.strip() for c in record]
    if not any(cells):
        return False
    for c in cells:
        if _NUMBER.match(c.replace(",", ".") if decimal == "," else c) or _INFINITE.match(c) or c in _MISSING[1:]:
            return False
    return True


#: bytes of the file read and parsed at once (a chunk of rows; bounds the memory a long file takes)
BLOCK_BYTES = 1 << 22
_HEAD_LINES = 102  #: the header, a unit row and the 100 lines the decimal mark is found from
_BOM = b"\xef\xbb\xbf"


def _open_regular(path: str | Path, source: str) -> BinaryIO:
    """``path`` opened for reading bytes: a regular file (a device or a pipe would be read forever)."""
    p = Path(path)
    if not p.exists():
        raise MissingFileError(f"{source}: No such file or directory{near_names(p)}")
    if not (p.is_file() or p.is_dir()):  # a directory: let open() say so
        raise ValueError(f"{source}: not a regular file (a device, pipe or socket)")
    fh = open(p, "rb")
    if not stat.S_ISREG(os.fstat(fh.fileno()).st_mode):
        fh.close()
        raise ValueError(f"{source}: not a regular file")
    return fh


class DataReader:
    """A data file (see the module docs) read and checked in chunks of rows, so that a recording of
    any length is read in bounded memory: the header is read and checked when the reader is made,
    :meth:`chunks` yields the rows as :class:`Data` (``lines`` their line numbers in the file), one
    block of the file at a time, and raises the first defect as :func:`read_data` does (a defect
    late in the file after the chunks before it). ``block_bytes``: the size of a block (a chunk holds
    the whole lines in it); ``limit``: the most bytes read (None: no limit)."""

    def __init__(self, path: str | Path, cf: ConfigFile, *, valid_suffix: str = "_valid",
                 config_source: str = "the config", sep: str | None = None, decimal: str | None = None,
                 allow_lost: bool = False, block_bytes: int = BLOCK_BYTES, limit: int | None = None) -> None:
        source = str(path)
        if sep is not None and sep not in SEPARATORS:
            raise ValueError(f"--csv-sep: expected one of ',', ';' or tab, got {sep!r}")
        if decimal is not None and decimal not in (".", ","):
            raise ValueError(f"--decimal: expected '.' or ',', got {decimal!r}")
        if sep == "," and decimal == ",":
            raise ValueError("--decimal ,: a comma cannot be both the separator and the decimal mark; use --csv-sep ';'")
        if isinstance(block_bytes, bool) or not isinstance(block_bytes, int) or block_bytes < 1:
            raise ValueError(f"block_bytes: expected a whole number of bytes >= 1, got {block_bytes!r}")
        self.source, self.allow_lost, self.limit = source, allow_lost, limit
        self._block_bytes = block_bytes
        self._fh = _open_regular(path, source)
        self._offset = 0  # bytes read
        self._tail = b""  # read after the last line end
        self._eof = False
        try:
            self._read_header(cf, valid_suffix, config_source, sep, decimal)
        except BaseException:
            self._fh.close()
            raise

    # -- the file, a block of whole lines at a time ------------------------------------------------

    def _more(self) -> bytes:
        """The next bytes of the file (b"" at its end)."""
        want = self._block_bytes
        if self.limit is not None:
            want = min(want, self.limit + 1 - self._offset)
        data = self._fh.read(max(want, 0)) if want > 0 else b""
        self._offset += len(data)
        if self.limit is not None and self._offset > self.limit:
            raise ValueError(f"{self.source}: larger than {self.limit:,} bytes, the most pyrhonn reads from such a file")
        if not data:
            self._eof = True
        return data

    def _block(self, lines: int | None = None) -> bytes:
        """The next whole lines of the file: about ``block_bytes`` of them, or the first ``lines`` lines,
        or up to the end of the file; cut at a line end after an even number of quote characters (a
        quoted cell holding a line end is not cut); b"" at the end of the file."""
        raw = self._tail
        while not self._eof and (raw.count(b"\n") < lines if lines is not None
                                 else len(raw) < self._block_bytes or b"\n" not in raw):
            raw += self._more()
        if self._eof:
            cut = len(raw)
        elif lines is not None:
            cut = 0
            for _ in range(lines):
                cut = raw.index(b"\n", cut) + 1
        else:
            cut = raw.rfind(b"\n") + 1
        while not self._eof and raw.count(b'"', 0, cut) % 2:  # inside a quoted cell: take the next line too
            end = raw.find(b"\n", cut)
            while end < 0 and not self._eof:
                raw += self._more()
                end = raw.find(b"\n", cut)
            cut = len(raw) if end < 0 else end + 1
        self._tail = raw[cut:]
        return raw[:cut]

    def _text(self, raw: bytes, first_line: int, start: int) -> str:
        """``raw`` (file bytes from offset ``start``, line ``first_line`` on) as text."""
        try:
            return raw.decode("utf-8")
        except UnicodeDecodeError as exc:
            line = first_line + raw.count(b"\n", 0, exc.start)
            raise ValueError(f"{self.source}: line {line}: not UTF-8 text (byte {start + exc.start})") from None

    # -- the header ---------------------------------------------------------------------------------

    def _read_header(self, cf: ConfigFile, valid_suffix: str, config_source: str, sep: str | None,
                     decimal: str | None) -> None:
        source = self.source
        raw = self._block(_HEAD_LINES)
        while not self._eof and not raw.strip():  # blank lines only so far: an empty file, or a header later
            raw += self._block(_HEAD_LINES)
        _not_csv(raw, source)
        bom = len(_BOM) if raw.startswith(_BOM) else 0
        text = self._text(raw[bom:], 1, bom)
        if not text.strip() and self._eof:
            raise ValueError(f"{source}: empty file (expected a header row naming the columns, then the data)")
        required = list(cf.state_names) + list(cf.input_names)
        sep = _separator(text.split("\n", 1)[0], required, sep)
        decimal = _decimal(_records(text, source, sep), sep, decimal)
        records = _records(text, source, sep)
        header_line, header = next(records)
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
        missing = [name for name in required if name not in where]
        if missing:
            close = [f"{m!r} -> {c[0]!r}" for m in missing
                     for c in [difflib.get_close_matches(m, [n for n in names if n not in required], n=1)] if c]
            hint = ("; did you mean " + ", ".join(close) + "?") if close else ""
            if len(names) == 1 and any(c in names[0] for c in SEPARATORS if c != sep):
                other = next(c for c in SEPARATORS if c != sep and c in names[0])
                hint += (f"; the header is one column when split on {SEPARATORS[sep]}s: is the file separated by "
                         f"{SEPARATORS[other]}s? (--csv-sep {'tab' if other == chr(9) else other})")
            raise ValueError(
                f"{source}: line {header_line}: missing column{'s' if len(missing) > 1 else ''} "
                + ", ".join(repr(m) for m in missing)
                + f" ({config_source} names the states {', '.join(cf.state_names)}"
                + (f" and the inputs {', '.join(cf.input_names)})" if cf.input_names else " and no inputs)")
                + f"{hint}; the header has {', '.join(repr(n) for n in names[:12])}{' ...' if len(names) > 12 else ''}")
        validity: dict[int, int] = {}
        for j, name in enumerate(cf.state_names):
            vname = f"{name}{valid_suffix}"
            if vname in required or vname in (TIME_COLUMN, LOST_COLUMN):
                raise ValueError(f"--valid-suffix: the validity column of state {name!r} would be {vname!r}, "
                                 "which is also a state, input or time column; choose another suffix")
            if vname in where:
                validity[j] = where[vname]
        if LOST_COLUMN in required:
            raise ValueError(f"{config_source}: a state or input is named {LOST_COLUMN!r}, the column that marks "
                             "lost samples; rename it")
        used = set(required) | {f"{cf.state_names[j]}{valid_suffix}" for j in validity} | {TIME_COLUMN, LOST_COLUMN}
        self.ignored = tuple(name for name in names if name not in used)
        self.units: dict[str, str] | None = None
        second = next(records, None)
        if second is not None and second[1] and len(second[1]) == len(names) and _unit_row(second[1], decimal):
            self.units = {name: cell.strip().strip("[]()").strip() for name, cell in zip(names, second[1])
                          if name in used and cell.strip().strip("[]()").strip()}
            second = None
        self._head = list(itertools.chain([second] if second is not None else [], records))
        self._head_raw = raw
        self.names, self._where, self._validity = names, where, validity
        self.sep, self.decimal, self.header_line = sep, decimal, header_line
        self._state_cols = [where[name] for name in cf.state_names]
        self._input_cols = [where[name] for name in cf.input_names]
        self._n, self._m = len(cf.state_names), len(cf.input_names)
        self._state_names, self._valid_suffix = tuple(cf.state_names), valid_suffix
        self.has_time, self.has_lost = TIME_COLUMN in where, LOST_COLUMN in where
        numbers = ([where[TIME_COLUMN]] if self.has_time else []) + self._state_cols + self._input_cols
        flag_fields = ([where[LOST_COLUMN]] if self.has_lost else []) + list(validity.values())
        self._layout = Layout(tuple(names), tuple(numbers), tuple(flag_fields))

    # -- the rows -----------------------------------------------------------------------------------

    def chunks(self) -> Iterator[Data]:
        """The data rows, a chunk at a time (each a :class:`Data` of at least one row); ValueError at
        the first defect, naming its line."""
        self._k = -1  # the last data row, counted over the whole file
        self._last_t = np.nan
        self._last_line = 0
        self._last_lost = False
        self._blank: int | None = None  # the first blank line: allowed only at the end of the file
        try:
            head_lines = self._head_raw.count(b"\n") + (0 if self._head_raw.endswith(b"\n") else 1)
            chunk = self._rows(self._head, head_lines)
            if chunk is not None:
                yield chunk
            line = 1 + self._head_raw.count(b"\n")
            start = len(self._head_raw)
            del self._head, self._head_raw
            while True:
                raw = self._block()
                if not raw:
                    break
                chunk = self._fast(raw, line) if self._blank is None else None
                if chunk is not None:  # one row a line
                    line += chunk.n_samples - (0 if raw.endswith(b"\n") else 1)
                else:
                    text = self._text(raw, line, start)
                    chunk = self._rows(_records(text, self.source, self.sep, line - 1), raw.count(b"\n") + 1)
                    line += raw.count(b"\n")
                if chunk is not None:
                    yield chunk
                start += len(raw)
        finally:
            self._fh.close()
        if self._k < 0:
            raise ValueError(f"{self.source}: line {self.header_line}: header only, no data rows")
        if self._last_lost:
            raise ValueError(f"{self.source}: line {self._last_line}, column {LOST_COLUMN!r}: the last data row cannot "
                             "be a lost sample (leave it out)")

    @property
    def samples(self) -> int:
        """The data rows read so far (all of them once :meth:`chunks` is exhausted)."""
        return self._k + 1

    def _data(self, X: np.ndarray, U: np.ndarray, valid: np.ndarray, t: np.ndarray | None, lines: np.ndarray,
              lost: np.ndarray) -> Data | None:
        T = X.shape[0]
        if T == 0:
            return None
        self._k += T
        if t is not None:
            self._last_t = float(t[-1])
        self._last_line = int(lines[-1])
        self._last_lost = bool(lost[-1])
        return Data(X=X, U=U, valid=valid, t=t, lines=lines, ignored=self.ignored,
                    lost=lost if self.has_lost else None, units=self.units)

    def _fast(self, raw: bytes, first_line: int) -> Data | None:
        """The rows of ``raw`` when every one of them is plain (numbers, 0/1 flags, empty cells only
        where a state is not valid or the sample is lost, times increasing): parsed in C
        (:func:`pyrhonn.csvcodec.parse_rows`); None for anything else (quotes, blank lines, a decimal
        comma, a defect), which :meth:`_rows` then reads and names cell by cell."""
        if self.decimal != "." or b'"' in raw:
            return None
        if not raw.isascii():
            try:
                raw.decode("utf-8")
            except UnicodeDecodeError:
                return None
        try:
            values, flags = parse_rows(raw, self._layout, self.sep)
        except CellError:
            return None
        L = values.shape[0]
        f = 0
        lost = np.zeros(L, dtype=bool)
        if self.has_lost:
            got = flags[:, 0]
            if np.any(got > 1):
                return None
            lost = got == 1
            if lost.any() and (not self.allow_lost or (self._k < 0 and lost[0])):
                return None
            f = 1
        arrived = ~lost
        valid = flags[:, f:] == 1
        if np.any((flags[:, f:] > 1) & arrived[:, None]):
            return None
        valid &= arrived[:, None]
        if len(self._validity) < self._n:  # a state without a validity column: valid where the sample arrived
            full = np.repeat(arrived[:, None], self._n, axis=1)
            full[:, list(self._validity)] = valid
            valid = full
        nan = np.isnan(values)
        c0 = 0
        t = None
        if self.has_time:
            t = values[:, 0].copy()
            if np.any(nan[:, 0]) or np.any(np.diff(t) <= 0) or (self._k >= 0 and not t[0] > self._last_t):
                return None
            c0 = 1
        X = values[:, c0:c0 + self._n].copy()
        U = values[:, c0 + self._n:].copy()
        if np.any(nan[:, c0:c0 + self._n] & valid) or np.any(nan[:, c0 + self._n:][arrived]):
            return None
        X[lost] = np.nan
        U[lost] = np.nan
        lines = np.arange(first_line, first_line + L, dtype=np.int64)
        return self._data(X, U, valid, t, lines, lost)

    def _rows(self, records: Iterable[tuple[int, list[str]]], at_most: int) -> Data | None:
        """Data rows from ``records``, checked cell by cell where a block of them is not plain: every
        defect named with its line and column."""
        source, where, validity, names = self.source, self._where, self._validity, self.names
        decimal, width = self.decimal, len(names)
        n, m = self._n, self._m
        X = np.empty((at_most, n))
        U = np.empty((at_most, m))
        valid = np.ones((at_most, n), dtype=bool)
        t = np.empty(at_most) if self.has_time else None
        lines = np.empty(at_most, dtype=np.int64)
        lost = np.zeros(at_most, dtype=bool)
        state_cols, input_cols = self._state_cols, self._input_cols
        k0 = self._k + 1  # the first row's index in the file
        k = -1  # the last row filled here

        def t_before(i: int) -> float:
            """The time of the row before row i here (in the chunk before for row 0)."""
            return float(t[i - 1]) if t is not None and i > 0 else self._last_t

        def line_before(i: int) -> int:
            return int(lines[i - 1]) if i > 0 else self._last_line

        def one_row(line: int, record: list[str]) -> None:
            """A data row, checked cell by cell: every defect named with its line and column."""
            nonlocal k
            k += 1
            lines[k] = line
            if len(record) != width:
                raise ValueError(f"{source}: line {line}: expected {width} fields as in the header, got {len(record)}")
            if t is not None:
                value = _cell(source, line, TIME_COLUMN, record[where[TIME_COLUMN]], decimal)
                if np.isnan(value):
                    raise ValueError(f"{source}: line {line}, column 't': missing time")
                if k + k0 and not value > t_before(k):
                    raise ValueError(f"{source}: line {line}, column 't': time {value!r} is not after "
                                     f"{t_before(k)!r} on line {line_before(k)} (times must increase)")
                t[k] = value
            if LOST_COLUMN in where:
                flag = record[where[LOST_COLUMN]].strip()
                if flag not in ("0", "1"):
                    raise ValueError(f"{source}: line {line}, column {LOST_COLUMN!r}: expected 0 or 1, got "
                                     f"{record[where[LOST_COLUMN]]!r}")
                if flag == "1":
                    if not self.allow_lost:
                        raise ValueError(f"{source}: line {line}, column {LOST_COLUMN!r}: a lost sample; this command "
                                         "needs a record without gaps (pyrhonn identify splits one at its gaps; or "
                                         "cut the file there)")
                    if k + k0 == 0:
                        raise ValueError(f"{source}: line {line}, column {LOST_COLUMN!r}: the first data row cannot "
                                         "be a lost sample (leave it out)")
                    lost[k] = True
                    X[k], U[k], valid[k] = np.nan, np.nan, False
                    return
            for j, c in validity.items():
                flag = record[c].strip()
                if flag not in ("0", "1"):
                    raise ValueError(f"{source}: line {line}, column {names[c]!r}: expected 0 or 1, got {record[c]!r}")
                valid[k, j] = flag == "1"
            for j, c in enumerate(state_cols):
                value = _cell(source, line, names[c], record[c], decimal)
                if np.isnan(value) and valid[k, j]:
                    how = (f"{names[validity[j]]} = 1" if j in validity
                           else f"no {self._state_names[j]}{self._valid_suffix!s} column; add one with 0 on this "
                                "line to mark a missing measurement")
                    raise ValueError(f"{source}: line {line}, column {names[c]!r}: missing value (empty or NaN) "
                                     f"but the state is marked valid ({how})")
                X[k, j] = value
            for j, c in enumerate(input_cols):
                value = _cell(source, line, names[c], record[c], decimal)
                if np.isnan(value):
                    raise ValueError(f"{source}: line {line}, column {names[c]!r}: missing input value "
                                     "(inputs must be given on every line)")
                U[k, j] = value

        def numbers(cells: tuple[str, ...]) -> np.ndarray | None:
            """A column of plain numbers in one pass (None if any cell is anything else)."""
            joined = "\n".join(cells)
            if decimal == ",":
                if "." in joined:
                    return None
                joined = joined.replace(",", ".")
            if not _COLUMN.fullmatch(joined):
                return None
            parts = joined.split("\n")
            if len(parts) != len(cells):  # a quoted cell held a line end
                return None
            try:
                with np.errstate(over="ignore"):
                    a = np.array(parts, dtype=np.float64)
            except (ValueError, OverflowError):
                return None
            return a if np.isfinite(a).all() else None

        def plain_rows(chunk: list[tuple[int, list[str]]]) -> bool:
            """Rows whose every cell is plain (numbers, flags 0/1, no lost sample, times increasing), filled
            column by column; False (nothing filled) for anything else, which :func:`one_row` then names."""
            if any(len(r) != width for _, r in chunk):
                return False
            cols = list(zip(*(r for _, r in chunk)))
            got: dict[int, np.ndarray] = {}
            for c in ([where[TIME_COLUMN]] if t is not None else []) + state_cols + input_cols:
                a = numbers(cols[c])
                if a is None:
                    return False
                got[c] = a
            flags = {c: {cell.strip() for cell in cols[c]} for c in validity.values()}
            if any(not f <= {"0", "1"} for f in flags.values()):
                return False
            if LOST_COLUMN in where and {cell.strip() for cell in cols[where[LOST_COLUMN]]} != {"0"}:
                return False
            if t is not None:
                tc = got[where[TIME_COLUMN]]
                if np.any(np.diff(tc) <= 0) or (k + 1 + k0 > 0 and not tc[0] > t_before(k + 1)):
                    return False
            rows = slice(k + 1, k + 1 + len(chunk))
            lines[rows] = [line for line, _ in chunk]
            if t is not None:
                t[rows] = got[where[TIME_COLUMN]]
            for j, c in validity.items():
                valid[rows, j] = np.array([cell.strip() == "1" for cell in cols[c]])
            for j, c in enumerate(state_cols):
                X[rows, j] = got[c]
            for j, c in enumerate(input_cols):
                U[rows, j] = got[c]
            return True

        chunk: list[tuple[int, list[str]]] = []

        def flush() -> None:
            nonlocal k
            if chunk and plain_rows(chunk):
                k += len(chunk)
            else:
                for line, record in chunk:
                    one_row(line, record)
            chunk.clear()

        for line, record in records:
            if not record:
                if self._blank is None:
                    flush()  # the rows before it first: their defects come first
                    self._blank = line
                continue
            if self._blank is not None:
                raise ValueError(f"{source}: line {self._blank}: empty line inside the data")
            chunk.append((line, record))
            if len(chunk) == 4096:
                flush()
        flush()
        T = k + 1
        return self._data(X[:T].copy(), U[:T].copy(), valid[:T].copy(), None if t is None else t[:T].copy(),
                          lines[:T].copy(), lost[:T].copy())


def read_data(path: str | Path, cf: ConfigFile, *, valid_suffix: str = "_valid",
              config_source: str = "the config", sep: str | None = None, decimal: str | None = None,
              allow_lost: bool = False) -> Data:
    """Read and check a data file for the config ``cf`` (see the module docs) whole; ``sep`` (one of
    :data:`SEPARATORS`) and ``decimal`` (``.`` or ``,``) None: found from the file. A lost sample
    (``lost`` = 1) is an error naming its line unless ``allow_lost`` (the caller handles gaps).
    :class:`DataReader` reads one in chunks."""
    reader = DataReader(path, cf, valid_suffix=valid_suffix, config_source=config_source, sep=sep,
                        decimal=decimal, allow_lost=allow_lost, limit=MAX_FILE_BYTES)
    return concatenate(list(reader.chunks()))


def concatenate(chunks: Sequence[Data]) -> Data:
    """The chunks of one file (:meth:`DataReader.chunks`, at least one) as one :class:`Data`."""
    def joined(arrays: list[np.ndarray | None]) -> np.ndarray | None:
        return None if arrays[0] is None else np.concatenate([a for a in arrays if a is not None])

    first = chunks[0]
    X, U, valid, lines = (np.concatenate([getattr(c, f) for c in chunks]) for f in ("X", "U", "valid", "lines"))
    return Data(X=X, U=U, valid=valid, t=joined([c.t for c in chunks]), lines=lines, ignored=first.ignored,
                lost=joined([c.lost for c in chunks]), units=first.units)


def write_data(path: str | Path, data: Data, cf: ConfigFile, *, valid_suffix: str = "_valid") -> None:
    """Write ``data`` as a data file that :func:`read_data` reads back equal
    (``t`` if given, the states, the inputs, a validity column per state; an
    invalid state's cell empty; floats written exactly), whole or not at all
    (:mod:`pyrhonn.atomic`)."""
    check_suffix(valid_suffix)
    gaps = data.lost is not None and bool(data.lost.any())
    rows = data_rows(data, cf, lost_column=gaps)
    with atomic.replacing(path, "wb") as fh:
        fh.write(header_line(data_columns(data.t is not None, cf, valid_suffix, gaps)))
        for text in rows:
            fh.write(text)


def data_columns(has_t: bool, cf: ConfigFile, valid_suffix: str, lost_column: bool) -> list[str]:
    """The header of a data file :func:`write_data` writes."""
    return ([TIME_COLUMN] if has_t else []) + list(cf.state_names) + list(cf.input_names) + \
        [f"{name}{valid_suffix}" for name in cf.state_names] + ([LOST_COLUMN] if lost_column else [])


def data_rows(data: Data, cf: ConfigFile, *, lost_column: bool) -> Iterator[bytes]:
    """The rows of ``data`` as :func:`write_data` writes them (with the ``lost`` column or not), a block of
    rows at a time: the rows of a record written in pieces are those of the whole."""
    n, m = len(cf.state_names), len(cf.input_names)
    if data.X.shape != (data.n_samples, n) or data.U.shape != (data.n_samples, m):
        raise ValueError(f"data: expected X ({data.n_samples}, {n}) and U ({data.n_samples}, {m}) for the config, "
                         f"got {data.X.shape} and {data.U.shape}")
    return _row_blocks(data, n, m, lost_column)


def _row_blocks(data: Data, n: int, m: int, lost_column: bool) -> Iterator[bytes]:
    T = data.n_samples
    arrived = ~data.lost if lost_column and data.lost is not None else np.ones(T, dtype=bool)
    t = [] if data.t is None else [data.t[:, None]]
    for a in range(0, T, ROWS_AT_ONCE):  # a block of rows at a time
        rows = slice(a, min(a + ROWS_AT_ONCE, T))
        flags = [data.valid[rows]] + ([~arrived[rows, None]] if lost_column else [])
        values = np.hstack([*(c[rows] for c in t), data.X[rows], data.U[rows], *flags], dtype=np.float64)
        show = np.ones(values.shape, dtype=bool)
        c = len(t)
        show[:, c:c + n] = data.valid[rows]
        show[:, c + n:c + n + m] = arrived[rows, None]
        yield format_rows(values, show, integer=[False] * (c + n + m) + [True] * (values.shape[1] - c - n - m))


def header_line(names: Sequence[str]) -> bytes:
    """A CSV header line of ``names`` (quoted where they need it), ended by a line end, as UTF-8."""
    text = io.StringIO()
    csv.writer(text, lineterminator="\n").writerow(names)
    return text.getvalue().encode("utf-8")


#: rows formatted at once when writing (bounds the text held)
ROWS_AT_ONCE = 1 << 14
