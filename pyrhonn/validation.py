"""Argument checks shared by every public entry of pyrhonn.

Each check raises ``ValueError`` whose message starts with the path of the
offending field (``neurons[2].beta: must be > 0, got 0.0``) and never
converts silently: a bool is not an integer, a list is not an array, a
complex or object array is not real.
"""
from __future__ import annotations

import difflib
import math
import os
import stat
from pathlib import Path

import numpy as np

__all__ = ["fail", "check_int", "check_real", "check_array", "check_data", "read_file", "MissingFileError", "near_names"]


def fail(path: str, message: str) -> ValueError:
    """The ValueError every check raises: ``"<path>: <message>"``."""
    return ValueError(f"{path}: {message}")


class MissingFileError(FileNotFoundError, ValueError):
    """A file that is not there: a ``FileNotFoundError`` (as ``open`` raises) and a ``ValueError``
    (as every other bad input), whose message names the closest files in its folder."""


def read_file(path: str | os.PathLike[str], source: str, *, limit: int) -> bytes:
    """The bytes of the regular file ``path``, at most ``limit`` of them.

    A device, pipe or socket (``/dev/zero`` would be read forever, a FIFO
    blocks) or a larger file is a ValueError naming ``source``; a missing file
    is a :class:`MissingFileError` naming the closest files in its folder; a
    file that cannot be opened raises the OSError ``open`` gives.
    """
    p = Path(path)
    if not p.exists():
        raise MissingFileError(f"{source}: No such file or directory{near_names(p)}")
    if p.exists() and not (p.is_file() or p.is_dir()):  # a directory: let open() say so
        raise ValueError(f"{source}: not a regular file (a device, pipe or socket)")
    with open(p, "rb") as fh:
        if not stat.S_ISREG(os.fstat(fh.fileno()).st_mode):
            raise ValueError(f"{source}: not a regular file")
        data = fh.read(limit + 1)
    if len(data) > limit:
        raise ValueError(f"{source}: larger than {limit:,} bytes, the most pyrhonn reads from such a file")
    return data


def near_names(p: Path) -> str:
    """A hint for a file that is not there: "; did you mean ...?" with the closest names in its
    folder, or that the folder itself is missing ("" when nothing is close)."""
    folder = p.parent
    try:
        names = [q.name for q in folder.iterdir()] if folder.is_dir() else []
    except OSError:
        names = []
    close = difflib.get_close_matches(p.name, names, n=2, cutoff=0.7)
    if close:
        return "; did you mean " + " or ".join(repr(str(folder / c)) for c in close) + "?"
    return "" if folder.is_dir() else f" (the folder {str(folder)!r} does not exist either)"


def decode_text(data: bytes, source: str, *, bom: bool = False) -> str:
    """``data`` as UTF-8 text (``bom``: a leading byte-order mark allowed and
    dropped); a ValueError naming ``source`` and the line of the first byte
    that is not UTF-8."""
    try:
        return data.decode("utf-8-sig" if bom else "utf-8")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        raise ValueError(f"{source}: line {line}: not UTF-8 text (byte {exc.start})") from None


def check_int(path: str, value: object, lo: int, hi: int | None = None) -> int:
    """An integer (not bool) in ``lo..hi`` (``hi`` None: no upper bound)."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise fail(path, f"expected an integer, got {type(value).__name__} {value!r}")
    v = int(value)
    if v < lo or (hi is not None and v > hi):
        rng = f"{lo}..{hi}" if hi is not None else f">= {lo}"
        raise fail(path, f"{v} out of range {rng}")
    return v


def check_real(path: str, value: object, *, positive: bool = False, nonnegative: bool = False) -> float:
    """A finite real number (not bool), optionally > 0 or >= 0."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise fail(path, f"expected a real number, got {type(value).__name__} {value!r}")
    try:
        v = float(value)
    except OverflowError:  # a Python int beyond float64 (a TOML or JSON integer can be any size)
        raise fail(path, "out of the float64 range (an integer beyond 1.8e308)") from None
    if not math.isfinite(v):
        raise fail(path, f"must be finite, got {v!r}")
    if positive and not v > 0.0:
        raise fail(path, f"must be > 0, got {v!r}")
    if nonnegative and not v >= 0.0:
        raise fail(path, f"must be >= 0, got {v!r}")
    return v


def _first_nonfinite(a: np.ndarray) -> str:
    return ", ".join(str(int(i)) for i in np.argwhere(~np.isfinite(a))[0])


def check_array(path: str, value: object, shape: tuple[int, ...]) -> np.ndarray:
    """Configuration data: a real numpy array of exactly ``shape``, all
    finite; returns a read-only float64 copy (configs are immutable)."""
    if not isinstance(value, np.ndarray):
        raise fail(path, f"expected a numpy array of shape {shape}, got {type(value).__name__}")
    if value.dtype.kind not in "fiu":
        raise fail(path, f"expected a real numeric array, got dtype {value.dtype}")
    if value.shape != shape:
        raise fail(path, f"expected shape {shape}, got {value.shape}")
    arr = np.array(value, dtype=np.float64)
    if not np.all(np.isfinite(arr)):
        raise fail(f"{path}[{_first_nonfinite(arr)}]", "must be finite")
    arr.setflags(write=False)
    return arr


def check_data(path: str, value: object, shape: tuple[int, ...], dtype: np.dtype | str = "float64") -> np.ndarray:
    """Run-time data: exactly ``dtype`` and ``shape``, all finite; returned
    as is (no copy)."""
    dt = np.dtype(dtype)
    if not isinstance(value, np.ndarray):
        raise fail(path, f"expected a {dt} numpy array of shape {shape}, got {type(value).__name__}")
    if value.dtype != dt:
        raise fail(path, f"expected dtype {dt}, got {value.dtype}")
    if value.shape != shape:
        raise fail(path, f"expected shape {shape}, got {value.shape}")
    if not np.all(np.isfinite(value)):
        idx = _first_nonfinite(value)
        raise fail(f"{path}[{idx}]", f"must be finite, got {value[tuple(int(i) for i in idx.split(', '))]!r}")
    return value
