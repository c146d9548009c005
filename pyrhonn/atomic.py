"""Files and output folders that an interrupted command cannot leave half written.

Every file pyrhonn and hil write goes through this module:

- **One file** (:func:`replacing`, :func:`replacing_path`, :func:`write_text`,
  :func:`write_bytes`, :func:`save_figure`) is written to a temporary file in
  the target's own folder, flushed and fsynced, then renamed over the target
  (``rename(2)`` replaces a file in one step on POSIX), and the folder is
  fsynced so that the rename itself survives a power cut. Whatever stops the
  command (an exception, Ctrl-C, ``kill -9``, a full disk), the target is the
  previous complete file or the new complete file, never a mix or a prefix.
  An existing target keeps its permission bits; a symbolic link is written
  through (the file it points to is replaced, the link stays).
- The temporary file is named ``.<name>.tmp-<pid>-<random>``: hidden, and
  never taken for an output. It is removed on any exception, Ctrl-C
  included; only a process killed outright (``kill -9``, a power cut) can
  leave one behind, which is then safe to delete.
- **A folder of outputs** (:func:`output_folder`: ``identify --out``,
  ``reproduce --out``, ``hil replay --out``) is marked incomplete while it is
  written: a marker file :data:`MARKER` is written first and removed last,
  after every output has been renamed into place. A folder that still holds
  it was written by a run that did not finish: each file in it is whole,
  but they may mix that run's outputs with an earlier run's. Readers check
  :func:`incomplete`. A marker, not a staging folder swapped in: ``--out``
  may be a folder that holds other files (the data file beside its
  predictions, a hil log beside its report), which swapping the folder
  would hide or delete.
"""
from __future__ import annotations

import errno
import os
import secrets
import time
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any, Iterator

__all__ = ["MARKER", "incomplete", "output_folder", "replacing", "replacing_path", "save_figure",
           "temp_path", "write_bytes", "write_text"]

#: the file that marks an output folder as being written (see the module docs)
MARKER = "INCOMPLETE"


def _target(path: str | os.PathLike[str]) -> Path:
    """The file to replace: a symbolic link is followed, so the link stays a
    link to the new file; a folder is refused naming it."""
    p = Path(path)
    if p.is_symlink():
        p = Path(os.path.realpath(p))
    if p.is_dir():
        raise IsADirectoryError(errno.EISDIR, "is a directory, not a file", str(path))
    return p


def temp_path(target: Path) -> Path:
    """A fresh temporary name beside ``target``: hidden, and saying what it is."""
    return target.with_name(f".{target.name}.tmp-{os.getpid()}-{secrets.token_hex(4)}")


def _create(target: Path) -> tuple[Path, int]:
    """Create the temporary file exclusively (never an existing one); the
    OSError of a folder that is missing or not writable names ``target``."""
    try:
        mode: int | None = os.stat(target).st_mode & 0o7777   # an existing file keeps its permission bits
    except OSError:
        mode = None                                         # a new file: 0o666 less the umask, as open() gives
    while True:
        tmp = temp_path(target)
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0), 0o666)
        except FileExistsError:  # 32 random bits taken by this very pid: draw again
            continue
        except OSError as exc:
            raise OSError(exc.errno, exc.strerror, str(target)) from None
        if mode is not None:
            try:
                os.fchmod(fd, mode)
            except OSError:  # not the owner of the file it replaces: the new file is ours, with our mode
                pass
        return tmp, fd


def _sync_folder(folder: Path) -> None:
    """fsync a folder, so that a rename in it is on disk; a no-op where folders cannot be opened."""
    try:
        fd = os.open(folder, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:  # some file systems do not sync folders
        pass
    finally:
        os.close(fd)


def _commit(tmp: Path, target: Path) -> None:
    try:
        os.replace(tmp, target)
    except OSError as exc:
        raise OSError(exc.errno, exc.strerror, str(target)) from None
    _sync_folder(target.parent)


@contextmanager
def replacing(path: str | os.PathLike[str], mode: str = "wb", *, encoding: str | None = None,
              newline: str | None = None) -> Iterator[IO[Any]]:
    """An open temporary file that replaces ``path`` when the block ends
    normally (flushed, fsynced, renamed); on any exception it is removed and
    ``path`` is left as it was. ``mode``: ``"wb"`` or ``"w"`` (text, UTF-8
    unless ``encoding``)."""
    if mode not in ("wb", "w"):
        raise ValueError(f"mode: expected 'wb' or 'w', got {mode!r}")
    target = _target(path)
    tmp, fd = _create(target)
    try:
        if mode == "w":
            fh: IO[Any] = os.fdopen(fd, "w", encoding=encoding or "utf-8", newline=newline)
        else:
            fh = os.fdopen(fd, "wb")
    except BaseException:
        os.close(fd)
        tmp.unlink(missing_ok=True)
        raise
    try:
        with fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        _commit(tmp, target)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


@contextmanager
def replacing_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """A temporary path for writers that open and close the file themselves
    (python-can's log writers): when the block ends normally the file there
    is fsynced and renamed over ``path``; on any exception it is removed and
    ``path`` is left as it was. The temporary file exists (empty) on entry."""
    target = _target(path)
    tmp, fd = _create(target)
    os.close(fd)
    try:
        yield tmp
        fd = os.open(tmp, os.O_RDONLY)   # fsync syncs the file, whichever descriptor it is given
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
        _commit(tmp, target)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def write_bytes(path: str | os.PathLike[str], data: bytes) -> Path:
    """Replace ``path`` with ``data`` (see :func:`replacing`); the path written."""
    with replacing(path, "wb") as fh:
        fh.write(data)
    return Path(path)


def write_text(path: str | os.PathLike[str], text: str, *, encoding: str = "utf-8") -> Path:
    """Replace ``path`` with ``text`` (see :func:`replacing`); the path written."""
    return write_bytes(path, text.encode(encoding))


def save_figure(fig: Any, path: str | os.PathLike[str], **kwargs: Any) -> Path:
    """``fig.savefig`` into ``path`` (see :func:`replacing`), in the format its
    suffix names (the temporary file has none matplotlib would recognise)."""
    fmt = Path(path).suffix.lstrip(".").lower()
    if not fmt:
        raise ValueError(f"{path}: no suffix to choose the figure format (.png, .pdf, .svg)")
    with replacing(path, "wb") as fh:
        fig.savefig(fh, format=fmt, **kwargs)
    return Path(path)


def _marker_text(command: str) -> str:
    return (f"{command} (pid {os.getpid()}, started {time.strftime('%Y-%m-%d %H:%M:%S %z')}) is writing "
            "this folder.\nIf this file is still here after it ended, that run was interrupted: every file "
            "beside it is whole,\nbut they may mix that run's outputs with an earlier run's. Run the "
            "command again.\n")


@contextmanager
def output_folder(folder: str | os.PathLike[str], command: str) -> Iterator[Path]:
    """Create ``folder`` if needed and mark it incomplete (:data:`MARKER`,
    naming ``command``) for the duration of the block; the marker is removed
    only when the block ends normally, so a run that is interrupted or fails
    leaves it. Write the outputs inside the block with the functions above."""
    path = Path(folder)
    path.mkdir(parents=True, exist_ok=True)
    write_text(path / MARKER, _marker_text(command))
    yield path
    os.unlink(path / MARKER)
    _sync_folder(path)


def incomplete(folder: str | os.PathLike[str]) -> str | None:
    """The marker's text when ``folder`` was left incomplete by an interrupted
    run (see :func:`output_folder`), else None."""
    try:
        return (Path(folder) / MARKER).read_text(encoding="utf-8", errors="replace")
    except (FileNotFoundError, NotADirectoryError, IsADirectoryError):
        return None
