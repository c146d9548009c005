"""``pyrhonn tune --study postgresql://...``: workers on a shared PostgreSQL study run the trials asked for
in total, not each.

A private PostgreSQL cluster is made in a temporary folder (``initdb``, ``pg_ctl``; as the user ``nobody``
when run as root, since the server refuses root), listens on a free port of 127.0.0.1 only, and is stopped
and deleted whatever happens. Two ``pyrhonn tune`` workers (the installed package, run from outside the
source tree) share one study there. Without the server binaries (Debian: ``apt-get install postgresql``) or
the psycopg driver the test is skipped, unless PYRHONN_REQUIRE_POSTGRES=1 (CI), where it fails instead.
"""
from __future__ import annotations

import glob
import importlib.util
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Iterator

import pytest

from docs_blocks import blocks_by, commands, run
from test_docs_commands import _few_trials, _plant_csv

REQUIRED = os.environ.get("PYRHONN_REQUIRE_POSTGRES") == "1"
TRIALS = 24


def unavailable(reason: str) -> None:
    if REQUIRED:
        pytest.fail(f"PYRHONN_REQUIRE_POSTGRES=1 but {reason}")
    pytest.skip(reason)


def server_binaries() -> Path | None:
    found = sorted(glob.glob("/usr/lib/postgresql/*/bin/initdb"),
                   key=lambda p: int(re.sub(r"\D", "", Path(p).parts[-3]) or 0))
    if found:
        return Path(found[-1]).parent
    initdb = shutil.which("initdb")
    return Path(initdb).parent if initdb and shutil.which("pg_ctl", path=str(Path(initdb).parent)) else None


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.fixture(scope="module")
def postgres_url() -> Iterator[str]:
    if importlib.util.find_spec("psycopg") is None and importlib.util.find_spec("psycopg2") is None:
        unavailable("no PostgreSQL driver for Python (pip install 'psycopg[binary]', in pyrhonn's test extras)")
    bindir = server_binaries()
    if bindir is None:
        unavailable("no PostgreSQL server binaries (Debian: apt-get install postgresql)")
    assert bindir is not None
    as_user: list[str] = []
    folder = Path(tempfile.mkdtemp(prefix="pyrhonn-pg-"))
    if os.geteuid() == 0:  # the server refuses to run as root
        runuser = shutil.which("runuser")
        if runuser is None:
            shutil.rmtree(folder)
            unavailable("running as root without runuser to start PostgreSQL as 'nobody'")
        assert runuser is not None
        as_user = [runuser, "-u", "nobody", "--"]
        os.chown(folder, 65534, -1)
    data = folder / "data"
    port = free_port()
    started = False
    try:
        init = subprocess.run([*as_user, str(bindir / "initdb"), "-D", str(data), "-U", "pyrhonn", "--auth=trust",
                               "-E", "UTF8", "--no-sync"], capture_output=True, text=True, timeout=120,
                              cwd=folder)  # a folder 'nobody' may enter (the checkout may be private)
        if init.returncode != 0:
            unavailable(f"initdb failed: {init.stderr.strip()[-300:]}")
        options = (f"-p {port} -k {folder} -c listen_addresses=127.0.0.1 -c fsync=off "
                   "-c synchronous_commit=off -c full_page_writes=off")
        start = subprocess.run([*as_user, str(bindir / "pg_ctl"), "-D", str(data), "-o", options, "-l",
                                str(folder / "server.log"), "-w", "-t", "60", "start"],
                               capture_output=True, text=True, timeout=120, cwd=folder)
        started = True  # pg_ctl may have started it even when it reports a failure
        if start.returncode != 0:
            log = (folder / "server.log").read_text(errors="replace") if (folder / "server.log").exists() else ""
            unavailable(f"the PostgreSQL server did not start: {(start.stderr + log).strip()[-400:]}")
        yield f"postgresql://pyrhonn@127.0.0.1:{port}/postgres"
    finally:
        if started:
            stop = subprocess.run([*as_user, str(bindir / "pg_ctl"), "-D", str(data), "-m", "immediate", "-w",
                                   "-t", "30", "stop"], capture_output=True, text=True, timeout=60, cwd=folder)
            pidfile = data / "postmaster.pid"
            if stop.returncode != 0 and pidfile.exists():  # last resort: the postmaster by its own pid
                try:
                    os.kill(int(pidfile.read_text().split()[0]), signal.SIGKILL)
                except (OSError, ValueError):
                    pass
        shutil.rmtree(folder, ignore_errors=True)


def tune_cmd(url: str, out: Path, *extra: str) -> list[str]:
    return [sys.executable, "-m", "pyrhonn.cli", "tune", "--example", "example1", "--horizon", "400",
            "--config", "example1", "--out", str(out), "--study", url, *extra]


def installed_env() -> dict[str, str]:
    env = dict(os.environ)
    env.pop("PYTHONPATH", None)  # the installed pyrhonn, not a source tree
    return env


def test_two_workers_share_a_postgresql_study_and_run_the_trials_asked_in_total(
        postgres_url: str, tmp_path: Path) -> None:
    procs = [subprocess.Popen(tune_cmd(postgres_url, tmp_path / f"tuned{w}.toml", "--trials", str(TRIALS),
                                       "--structure", "--max-delay", "0:6", "--max-terms", "2:10"),
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=str(tmp_path),
                              env=installed_env())
             for w in range(2)]
    outputs = []
    try:
        for p in procs:
            out, err = p.communicate(timeout=240)
            assert p.returncode == 0, err
            outputs.append(out)
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
                p.wait()
    ran = [int(re.search(r"^ran (\d+) trials; the study has (\d+):", out, re.M).group(1)) for out in outputs]
    totals = [int(re.search(r"^ran (\d+) trials; the study has (\d+):", out, re.M).group(2)) for out in outputs]
    assert sum(ran) == TRIALS, outputs  # together, not each
    assert all(r > 0 for r in ran), f"a worker ran no trial: {ran}"
    assert max(totals) == TRIALS

    import optuna

    from pyrhonn import tuning

    study = optuna.load_study(study_name=tuning.STUDY_NAME,
                              storage=tuning._open_storage(tuning.check_study(postgres_url)))
    trials = study.get_trials(deepcopy=False)
    assert len(trials) == TRIALS
    assert sorted(t.number for t in trials) == list(range(TRIALS))
    workers = {t.user_attrs.get("worker") for t in trials}
    assert len(workers) == 2, workers
    assert all(t.state.is_finished() for t in trials)

    # A larger --trials resumes the shared study; the same number runs nothing more.
    again = subprocess.run(tune_cmd(postgres_url, tmp_path / "again.toml", "--trials", str(TRIALS + 2),
                                    "--structure", "--max-delay", "0:6", "--max-terms", "2:10"),
                           capture_output=True, text=True, cwd=str(tmp_path), env=installed_env(), timeout=240)
    assert again.returncode == 0, again.stderr
    assert f"ran 2 trials; the study has {TRIALS + 2}:" in again.stdout


def test_a_shared_study_of_another_problem_is_refused_naming_the_option(postgres_url: str, tmp_path: Path) -> None:
    # The study the test above made (or a fresh one made here) holds a structure search of example1's first 400 s.
    first = subprocess.run(tune_cmd(postgres_url, tmp_path / "a.toml", "--trials", "1", "--structure",
                                    "--max-delay", "0:6", "--max-terms", "2:10"),
                           capture_output=True, text=True, cwd=str(tmp_path), env=installed_env(), timeout=240)
    assert first.returncode == 0, first.stderr
    other = subprocess.run(tune_cmd(postgres_url, tmp_path / "b.toml", "--trials", "1"),
                           capture_output=True, text=True, cwd=str(tmp_path), env=installed_env(), timeout=240)
    assert other.returncode == 2
    assert "--study: " in other.stderr and "different tuning problem" in other.stderr, other.stderr
    assert "Traceback" not in other.stderr
    assert not (tmp_path / "b.toml").exists()


def test_an_unreachable_database_is_named_as_the_study_option(tmp_path: Path) -> None:
    if importlib.util.find_spec("psycopg") is None and importlib.util.find_spec("psycopg2") is None:
        unavailable("no PostgreSQL driver for Python (pip install 'psycopg[binary]')")
    url = f"postgresql://pyrhonn@127.0.0.1:{free_port()}/postgres"  # nothing listens there
    proc = subprocess.run(tune_cmd(url, tmp_path / "t.toml", "--trials", "1"), capture_output=True, text=True,
                          cwd=str(tmp_path), env=installed_env(), timeout=240)
    assert proc.returncode == 2
    assert f"--study: cannot use the database '{url}'" in proc.stderr, proc.stderr
    assert "Traceback" not in proc.stderr


def test_a_shared_study_command_of_the_docs_runs_on_the_server(postgres_url: str, tmp_path: Path) -> None:
    # docs/selection-and-tuning.md's command with its database URL pointed at this server and 2 trials;
    # the record is a small stand-in and base.toml a config selected from it
    [body] = blocks_by("docs/selection-and-tuning.md",
                       "test_tune_postgres.py::test_a_shared_study_command_of_the_docs_runs_on_the_server")
    [line] = commands(body)
    assert "postgresql://tuner@db.example/tuning" in line, line
    _plant_csv(tmp_path / "run.csv", 300, 4, 3)
    run(["pyrhonn", "select", "run.csv", "--states", "x1,x2,x3,x4", "--inputs", "u", "--max-delay", "1", "--degree", "1",
         "--out", "base.toml"], tmp_path, "a base config")
    import sqlalchemy

    engine = sqlalchemy.create_engine(postgres_url, isolation_level="AUTOCOMMIT")
    with engine.connect() as conn:   # the page's database, on this server (its own study)
        conn.execute(sqlalchemy.text("CREATE DATABASE tuning"))
    engine.dispose()
    url = postgres_url.rsplit("/", 1)[0] + "/tuning"
    out = run(["bash", "-ec", _few_trials(line.replace("postgresql://tuner@db.example/tuning", url))],
              tmp_path, f"docs/selection-and-tuning.md: `{line}`", timeout=600)
    assert re.search(r"^ran 2 trials; the study has 2", out, re.M), out[-2000:]
