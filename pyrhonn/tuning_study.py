"""Where a tuning study lives (a journal file, SQLite, PostgreSQL), how it is
opened, and the lock that lets workers share it. :mod:`pyrhonn.tuning`
describes it (The study: files, databases, workers)."""
from __future__ import annotations

import fcntl
import hashlib
import importlib.util
import os
import re
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Any


from .validation import fail

__all__ = ["STUDY_NAME", "STUDY_SUFFIXES", "StudyStorage", "check_study", "check_study_path"]

STUDY_NAME = "pyrhonn-tune"
STUDY_SUFFIXES = {".db": "sqlite", ".sqlite": "sqlite", ".sqlite3": "sqlite", ".log": "journal"}


@dataclass(frozen=True)
class StudyStorage:
    """Where a study lives: ``kind`` is ``"journal"`` (an optuna journal
    file), ``"sqlite"`` or ``"postgresql"``; ``path`` is the file of a
    journal or SQLite study, ``url`` the SQLAlchemy URL of a database
    (the driver resolved), ``shown`` how messages name it (no password)."""

    kind: str
    shown: str
    path: Path | None = None
    url: str | None = None


_URL = re.compile(r"^[A-Za-z][A-Za-z0-9+.\-]*://")
_PG_DRIVERS = {"psycopg": "psycopg", "psycopg2": "psycopg2", "pg8000": "pg8000"}


def _storage_kind(path: Path) -> str:
    kind = STUDY_SUFFIXES.get(path.suffix.lower())
    if kind is None:
        raise fail("study_path", f"{str(path)!r}: unknown study file type {path.suffix!r}; use .log (optuna journal "
                                 "file), .db (SQLite) or a database URL (postgresql://user@host/db, "
                                 "sqlite:///path)")
    return kind


def _check_folder(shown: str, p: Path) -> None:
    if p.is_dir():
        raise fail("study_path", f"{shown!r} is a directory")
    parent = p.parent if str(p.parent) else Path(".")
    if not parent.is_dir():
        raise fail("study_path", f"{shown!r}: folder {str(parent)!r} does not exist")


def check_study_path(path: str | Path) -> Path:
    """The study file path, checked before any work: a known suffix, an
    existing folder, not a folder itself. Returns it as a Path."""
    if not isinstance(path, (str, Path)) or not str(path):
        raise fail("study_path", f"expected a file path, got {path!r}")
    p = Path(path)
    _storage_kind(p)
    _check_folder(str(p), p)
    return p


def _check_url(text: str) -> StudyStorage:
    from sqlalchemy.engine import make_url
    from sqlalchemy.exc import ArgumentError

    try:
        url = make_url(text)
    except (ArgumentError, ValueError) as exc:
        raise fail("study_path", f"{text!r} is not a database URL ({exc}); expected postgresql://user@host/db or "
                                 "sqlite:///path") from None
    shown = url.render_as_string(hide_password=True)
    backend = url.get_backend_name()
    if backend == "sqlite":
        if not url.database or url.database == ":memory:":
            raise fail("study_path", f"{shown!r} names no database file (sqlite:///relative/path.db or "
                                     "sqlite:////absolute/path.db); a study in memory is not kept")
        p = Path(url.database)
        _check_folder(shown, p)
        return StudyStorage("sqlite", shown, path=p, url=text)
    if backend == "postgresql":
        if not url.database:
            raise fail("study_path", f"{shown!r} names no database (postgresql://user@host/DATABASE)")
        if "+" in url.drivername:
            driver = url.get_driver_name()
        else:  # SQLAlchemy's default is psycopg2; take psycopg (3) when only it is installed
            driver = next((d for d in ("psycopg2", "psycopg") if importlib.util.find_spec(d) is not None), "psycopg")
            url = url.set(drivername=f"postgresql+{driver}")
        module = _PG_DRIVERS.get(driver)
        if module is None:
            raise fail("study_path", f"{shown!r}: driver {driver!r} is not supported; use postgresql:// or "
                                     "postgresql+psycopg://")
        if importlib.util.find_spec(module) is None:
            raise fail("study_path", f"{shown!r}: the PostgreSQL driver {module!r} is not installed "
                                     "(pip install 'psycopg[binary]')")
        return StudyStorage("postgresql", shown, url=url.render_as_string(hide_password=False))
    raise fail("study_path", f"{shown!r}: database {backend!r} is not supported; use postgresql://user@host/db or "
                             "sqlite:///path")


def check_study(spec: str | Path) -> StudyStorage:
    """Where the study named by ``spec`` lives, checked before any work.

    A string of the form ``scheme://...`` is a database URL:
    ``postgresql://user[:password]@host[:port]/database`` (the driver
    psycopg2 if installed, else psycopg; ``postgresql+psycopg://`` names
    it) or ``sqlite:///path``. Anything else is a file path whose suffix
    chooses the storage (:data:`STUDY_SUFFIXES`). ``ValueError`` names
    ``study_path`` otherwise.
    """
    if not isinstance(spec, (str, Path)) or not str(spec):
        raise fail("study_path", f"expected a file path or a database URL, got {spec!r}")
    if isinstance(spec, str) and _URL.match(spec):
        return _check_url(spec)
    p = check_study_path(spec)
    kind = _storage_kind(p)
    return StudyStorage(kind, str(p), path=p, url=f"sqlite:///{p.resolve()}" if kind == "sqlite" else None)


def _unusable(loc: StudyStorage | None, exc: BaseException) -> ValueError:
    text = str(exc).strip()
    reason = text.splitlines()[0] if text else type(exc).__name__
    if loc is not None and loc.kind == "postgresql":
        return fail("study_path", f"cannot use the database {loc.shown!r} ({reason})")
    shown = "<memory>" if loc is None else loc.shown
    return fail("study_path", f"{shown!r} is not a readable optuna study file ({reason})")


def _open_storage(loc: StudyStorage) -> Any:
    import optuna

    try:
        if loc.kind in ("postgresql", "sqlite"):
            url = loc.url
            assert url is not None  # a database's StudyStorage always has its URL (check_study)
            timeout = {"connect_timeout": 10} if loc.kind == "postgresql" else {"timeout": 60}
            return optuna.storages.RDBStorage(url, engine_kwargs={"connect_args": timeout})
        try:
            from optuna.storages.journal import JournalFileBackend, JournalFileOpenLock
        except ImportError:  # optuna 3.x names (not tested here: this environment has optuna 5)
            from optuna.storages import JournalFileOpenLock  # type: ignore[attr-defined,no-redef,unused-ignore]
            from optuna.storages import JournalFileStorage as JournalFileBackend  # type: ignore[no-redef,unused-ignore]

        path = str(loc.path)
        backend = JournalFileBackend(path, lock_obj=JournalFileOpenLock(path))
        return optuna.storages.JournalStorage(backend)
    except Exception as exc:  # SQLAlchemy, JSON and optuna errors alike: not a usable study
        raise _unusable(loc, exc) from None


_LOCK_KEY = int.from_bytes(hashlib.sha256(STUDY_NAME.encode()).digest()[:8], "big", signed=True)


class _Claim:
    """Serialises "count the study's trials, then ask for one" (and joining
    the study) across this run's threads and every worker sharing the study:
    a PostgreSQL advisory lock, or ``flock`` on the study file."""

    def __init__(self, loc: StudyStorage | None) -> None:
        self._thread = threading.Lock()
        self._fd: int | None = None
        self._conn: Any = None
        self._engine: Any = None
        if loc is None:
            return
        if loc.kind == "postgresql":
            import sqlalchemy
            from sqlalchemy.pool import NullPool

            assert loc.url is not None  # a database's StudyStorage always has its URL (check_study)
            try:
                self._engine = sqlalchemy.create_engine(loc.url, poolclass=NullPool,
                                                        connect_args={"connect_timeout": 10})
                self._conn = self._engine.connect().execution_options(isolation_level="AUTOCOMMIT")
            except Exception as exc:
                self.close()
                raise _unusable(loc, exc) from None
        else:
            assert loc.path is not None
            try:
                self._fd = os.open(loc.path, os.O_RDWR | os.O_CREAT, 0o666)
            except OSError as exc:
                raise fail("study_path", f"{loc.shown!r}: cannot open ({exc.strerror or exc})") from None

    def _sql(self, statement: str) -> None:
        import sqlalchemy

        self._conn.execute(sqlalchemy.text(statement), {"k": _LOCK_KEY})

    def __enter__(self) -> _Claim:
        self._thread.acquire()
        try:
            if self._conn is not None:
                self._sql("SELECT pg_advisory_lock(:k)")
            elif self._fd is not None:
                fcntl.flock(self._fd, fcntl.LOCK_EX)
        except BaseException:
            self._thread.release()
            raise
        return self

    def __exit__(self, *exc: object) -> None:
        try:
            if self._conn is not None:
                self._sql("SELECT pg_advisory_unlock(:k)")
            elif self._fd is not None:
                fcntl.flock(self._fd, fcntl.LOCK_UN)
        finally:
            self._thread.release()

    def close(self) -> None:
        if self._conn is not None:
            self._conn.close()
            self._conn = None
        if self._engine is not None:
            self._engine.dispose()
            self._engine = None
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None
