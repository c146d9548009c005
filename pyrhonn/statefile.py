"""Save and load an identifier's full filter state.

File format ``pyrhonn-state``, version 2: a NumPy ``.npz`` archive (a zip of
``.npy`` members, no pickles) holding

============  ===============  ==================================================
member        shape / dtype    meaning
============  ===============  ==================================================
``header``    0-d unicode      JSON: ``format`` = "pyrhonn-state", ``version`` = 2,
                               ``config`` (IdentifierConfig.to_dict()), ``dtype``,
                               ``steps``, ``started``, ``learning``, ``written_by``
                               ("pyrhonn X.Y.Z", informative only)
``w_<i>``     (L_i,) dtype     weights w_i(k) of neuron i
``p_<i>``     (L_i(L_i+1)/2,)  P_i(k), packed upper triangle, row by row; for a
                               neuron with ``covariance = "ud"`` its factors
                               P_i = U D U^T packed the same way (D on the
                               diagonal, U's strict upper triangle beside it)
``z_<i>``     (L_i,) dtype     regressor z_i(k-1) that produced x̂_i(k)
``xhat``      (n,) dtype       x̂(k)
``history``   (D, n) dtype     effective x(k-d), d = 0..D-1, newest first, where
                               D is the config's deepest delay (what the next
                               step's delayed taps read)
``input_history``  (D, m)      u(k-d), d = 0..D-1, newest first
``valid_run`` (n,) uint8       per state, the samples in a row (up to 255) in
                               which it was measured (a neuron whose own taps
                               read a prediction does not learn)
============  ===============  ==================================================

Version 1 files (written before inputs could be delayed) are read too: their
``history`` has D+1 rows, of which the first D are taken (inputs had no delay
then, so they hold no past inputs), and every state counts as measured.

``dtype`` is the identifier's (float64 or float32); the values are stored in
it exactly, so a loaded identifier continues bit for bit. Readers reject a
file with another ``format`` or a newer ``version``; every other defect
(missing member, wrong shape or dtype, non-finite value) raises
``ValueError`` naming the member.

A save writes a temporary file beside the target and renames it over the
target (:mod:`pyrhonn.atomic`): a save that is interrupted, even by
``kill -9`` or a power cut, leaves the previous state file as it was (or no
file, if there was none), never a partial archive.
"""
from __future__ import annotations

import json
import zipfile
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from . import atomic
from .config import IdentifierConfig
from .version import __version__
from .covariance import clearly_indefinite, unpacked

if TYPE_CHECKING:  # the identifier imports this module (Identifier.save, .load), never the reverse
    from .identifier import Identifier

__all__ = ["FORMAT", "VERSION", "save_state", "load_state"]

FORMAT = "pyrhonn-state"
VERSION = 2


def save_state(identifier: Identifier, path: str | Path) -> None:
    """Write ``identifier``'s full state to ``path`` (see module docs)."""
    if not isinstance(getattr(identifier, "config", None), IdentifierConfig):
        raise ValueError(f"identifier: expected an Identifier, got {type(identifier).__name__}")
    cfg = identifier.config
    header = {
        "format": FORMAT,
        "version": VERSION,
        "written_by": f"pyrhonn {__version__}",
        "dtype": cfg.dtype,
        "config": cfg.to_dict(),
        "steps": identifier.steps,
        "started": bool(identifier._net.started),
        "learning": identifier.learning,
    }
    members: dict[str, Any] = {"header": np.array(json.dumps(header))}
    regressors = identifier.regressors
    for i in range(cfg.n_states):
        members[f"w_{i}"] = identifier.get_weights(i)
        members[f"p_{i}"] = identifier._stored_covariance(i)
        members[f"z_{i}"] = regressors[i]
    members["xhat"] = identifier.prediction
    past = identifier._history()
    members["history"] = past["x"]
    members["input_history"] = past["u"]
    members["valid_run"] = past["valid_run"]
    # a temporary file renamed over ``path``: a save interrupted at any point (kill -9 included) leaves
    # the previous state file whole, never a truncated archive
    with atomic.replacing(path) as fh:
        np.savez(fh, **members)


def _fail(path: Path, member: str, message: str) -> ValueError:
    return ValueError(f"{path}: {member}: {message}")


#: the header member's most characters (a config of the largest capacities is far smaller)
MAX_HEADER_CHARS = 1 << 22


def _declared(path: Path, archive: Any, name: str) -> tuple[tuple[int, ...], np.dtype]:
    """The shape and dtype a member's .npy header declares, read before anything is allocated."""
    try:
        info = archive.zip.getinfo(f"{name}.npy")
        with archive.zip.open(info) as fh:
            version = np.lib.format.read_magic(fh)  # type: ignore[no-untyped-call]
            if version == (1, 0):
                shape, _, dtype = np.lib.format.read_array_header_1_0(fh)  # type: ignore[no-untyped-call]
            elif version == (2, 0):
                shape, _, dtype = np.lib.format.read_array_header_2_0(fh)  # type: ignore[no-untyped-call]
            else:
                raise ValueError(f"unsupported .npy version {version}")
    except (KeyError, ValueError, OSError, zipfile.BadZipFile, EOFError) as exc:
        raise _fail(path, name, f"unreadable ({exc})") from None
    count = 1
    for d in shape:
        count *= int(d)
    need = count * int(dtype.itemsize)
    if need > info.file_size:  # the archive's own record of the member's size
        raise _fail(path, name, f"declares shape {shape} of {dtype} ({need:,} bytes), but the member holds "
                                f"{info.file_size:,} bytes")
    return tuple(int(d) for d in shape), dtype


def _member(path: Path, archive: Any, name: str, shape: tuple[int, ...], dtype: np.dtype) -> np.ndarray:
    if name not in archive.files:
        raise _fail(path, name, "missing")
    declared, kind = _declared(path, archive, name)
    if kind != dtype:
        raise _fail(path, name, f"expected dtype {dtype}, got {kind}")
    if declared != shape:
        raise _fail(path, name, f"expected shape {shape}, got {declared}")
    try:
        a: np.ndarray = archive[name]
    except (ValueError, OSError, zipfile.BadZipFile, EOFError) as exc:
        raise _fail(path, name, f"unreadable ({exc})") from None
    if a.dtype != dtype:
        raise _fail(path, name, f"expected dtype {dtype}, got {a.dtype}")
    if a.shape != shape:
        raise _fail(path, name, f"expected shape {shape}, got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise _fail(path, name, "contains non-finite values")
    return a


def load_state(path: str | Path, identifier_type: type[Identifier]) -> Identifier:
    """Rebuild an identifier of ``identifier_type`` (:class:`pyrhonn.Identifier`
    or a subclass) from a file written by :func:`save_state`."""
    path = Path(path)
    try:
        archive = np.load(path, allow_pickle=False)
    except FileNotFoundError:
        raise ValueError(f"{path}: no such file") from None
    except (ValueError, OSError, zipfile.BadZipFile, EOFError) as exc:
        # numpy takes bytes it does not recognise for a pickle and suggests loading them unsafely:
        # never the advice for a file that is not even an archive
        why = "neither an .npz archive nor an .npy array" if "pickle" in str(exc) else str(exc)
        raise ValueError(f"{path}: not a {FORMAT} file ({why})") from None
    if not isinstance(archive, np.lib.npyio.NpzFile):
        raise ValueError(f"{path}: not a {FORMAT} file (a single .npy array, not an archive)")
    with archive:
        if "header" not in archive.files:
            raise _fail(path, "header", f"missing: not a {FORMAT} file")
        shape, kind = _declared(path, archive, "header")
        if shape != () or kind.kind != "U":
            raise _fail(path, "header", f"expected a JSON object (a 0-d unicode string), declared {kind} of shape "
                                        f"{shape}")
        if kind.itemsize > 4 * MAX_HEADER_CHARS:
            raise _fail(path, "header", f"declares a string of {kind.itemsize // 4:,} characters, more than the "
                                        f"{MAX_HEADER_CHARS:,} a state file's header holds")
        try:
            raw = archive["header"]
            header = json.loads(str(raw[()])) if raw.dtype.kind == "U" and raw.shape == () else None
        except (ValueError, OSError, zipfile.BadZipFile, EOFError) as exc:
            raise _fail(path, "header", f"unreadable ({exc})") from None
        except RecursionError:
            raise _fail(path, "header", "unreadable (JSON nested too deeply)") from None
        if not isinstance(header, dict):
            raise _fail(path, "header", "expected a JSON object")
        if header.get("format") != FORMAT:
            raise _fail(path, "header.format", f"expected {FORMAT!r}, got {header.get('format')!r}")
        version = header.get("version")
        if not isinstance(version, int) or isinstance(version, bool) or version < 1:
            raise _fail(path, "header.version", f"expected a positive integer, got {version!r}")
        if version > VERSION:
            raise _fail(path, "header.version", f"version {version} is newer than this pyrhonn reads ({VERSION})")
        try:
            cfg = IdentifierConfig.from_dict(header.get("config"))  # type: ignore[arg-type]
        except (ValueError, TypeError) as exc:
            raise _fail(path, "header.config", str(exc)) from None
        if header.get("dtype") != cfg.dtype:
            raise _fail(path, "header.dtype", f"{header.get('dtype')!r} does not match config dtype {cfg.dtype!r}")
        steps = header.get("steps")
        if not isinstance(steps, int) or isinstance(steps, bool) or not 0 <= steps < 2**32:
            raise _fail(path, "header.steps", f"expected an integer in 0..2**32-1, got {steps!r}")
        for key in ("started", "learning"):
            if not isinstance(header.get(key), bool):
                raise _fail(path, f"header.{key}", f"expected true or false, got {header.get(key)!r}")
        try:
            ident = identifier_type(cfg)
        except ValueError as exc:
            raise _fail(path, "header.config", str(exc)) from None
        dt = np.dtype(cfg.dtype)
        n = cfg.n_states
        weights, covs, regs = [], [], []
        for i, nr in enumerate(cfg.neurons):
            L = nr.n_terms
            weights.append(_member(path, archive, f"w_{i}", (L,), dt))
            p = _member(path, archive, f"p_{i}", (L * (L + 1) // 2,), dt)
            diag = p[np.cumsum(np.r_[0, np.arange(L, 1, -1)])]
            if not np.all(diag > 0):
                raise _fail(path, f"p_{i}", "covariance diagonal must be > 0" if nr.covariance.code == 0
                            else "factor D must be > 0")
            if nr.covariance.code == 0:
                lowest = clearly_indefinite(unpacked(p, L))
                if lowest is not None:
                    raise _fail(path, f"p_{i}", f"covariance not positive semi-definite (smallest eigenvalue "
                                                f"{lowest:.3g})")
            covs.append(p)
            regs.append(_member(path, archive, f"z_{i}", (L,), dt))
        xhat = _member(path, archive, "xhat", (n,), dt)
        D, m = cfg.max_delay, cfg.n_inputs
        if version == 1:
            history = {"x": _member(path, archive, "history", (D + 1, n), dt)[:D], "u": np.zeros((D, m), dt),
                       "valid_run": np.full(n, 255, np.uint8)}
            past_members = {"history"}
        else:
            history = {"x": _member(path, archive, "history", (D, n), dt),
                       "u": _member(path, archive, "input_history", (D, m), dt),
                       "valid_run": _member(path, archive, "valid_run", (n,), np.dtype(np.uint8))}
            past_members = {"history", "input_history", "valid_run"}
        extra = set(archive.files) - {"header", "xhat"} - past_members - {f"{k}_{i}" for k in "wpz" for i in range(n)}
        if extra:
            raise _fail(path, "archive", f"unexpected members {sorted(extra)}")
    try:
        ident._restore(weights=weights, packed_cov=covs, regressors=regs, prediction=xhat, history=history,
                       started=header["started"], learning=header["learning"], steps=steps)
    except ValueError as exc:  # IdentifierError: the core's own check: P positive definite at the file's precision
        member = str(exc).split(":", 1)[0]
        raise _fail(path, member, f"covariance not positive definite at {cfg.dtype} precision") from None
    return ident
