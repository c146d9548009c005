"""The commands the README and the docs show that a test's own folder cannot run as
they are (a developer's checkout and its Makefile, an install, the C library's CMake
build into a prefix, the VM tier): each test here reads its block from the page
(`<!-- docs-test: by test_docs_commands.py::TEST -->`, docs_blocks.blocks_by) and runs
or checks that very text, so the page cannot drift from what works."""
from __future__ import annotations

import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from docs_blocks import ROOT, blocks_by, commands, run


def _make_targets() -> set[str]:
    text = (ROOT / "Makefile").read_text(encoding="utf-8")
    return {name for line in re.findall(r"^([A-Za-z0-9_.%-][^:=\n]*):(?!=)", text, flags=re.M)
            for name in line.split()}


def _check_make(line: str, where: str) -> None:
    words = shlex.split(line, comments=True)
    targets = [w for w in words[1:] if not w.startswith("-") and "=" not in w]
    assert targets, f"{where}: `{line}` names no target"
    missing = [t for t in targets if t not in _make_targets()]
    assert not missing, f"{where}: `{line}`: the Makefile has no target {missing}"


def test_make_target_reader_reads_the_makefile() -> None:
    targets = _make_targets()
    assert {"venv", "lint", "test", "test-python", "reproduce", "docs", "fuzz-xcp"} <= targets
    with pytest.raises(AssertionError, match="no target"):
        _check_make("make no-such-target", "here")


def test_readme_make_commands_name_makefile_targets() -> None:
    for body in blocks_by("README.md", "test_docs_commands.py::test_readme_make_commands_name_makefile_targets"):
        for line in commands(body):
            assert line.startswith("make "), line
            _check_make(line, "README.md")


@pytest.mark.skipif(Path(sys.prefix).resolve() != (ROOT / ".venv").resolve(),
                    reason="the development page's commands run in a checkout set up with `make venv`")
def test_development_commands_run_in_the_checkout() -> None:
    # `make X` names a target (running `make venv` or `make test` here would rebuild or rerun the
    # suite); every other line is run in the checkout, as the page says
    for body in blocks_by("docs/development.md", "test_docs_commands.py::test_development_commands_run_in_the_checkout"):
        for line in commands(body):
            if line.startswith("make "):
                _check_make(line, "docs/development.md")
            else:
                out = run(["bash", "-ec", line], ROOT, f"docs/development.md: `{line}`")
                if "--version" in line or "__version__" in line:
                    assert re.search(r"\d+\.\d+", out), out


def test_install_commands_install_this_package() -> None:
    # `pip install path/to/pyrhonn`: a clone is a pip project (pyproject.toml) named pyrhonn; the git
    # URL form names the same repository (installing here would rebuild the extensions: minutes)
    import tomllib

    bodies = [*blocks_by("README.md", "test_docs_commands.py::test_install_commands_install_this_package"),
              *blocks_by("docs/index.md", "test_docs_commands.py::test_install_commands_install_this_package")]
    assert len(set(bodies)) == 1, "the README and the docs' home page show other install commands"
    lines = commands(bodies[0])
    assert [shlex.split(line, comments=True)[:2] for line in lines] == [["pip", "install"]] * len(lines)
    assert shlex.split(lines[0], comments=True)[2:] == ["path/to/pyrhonn"], lines[0]
    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    assert project["name"] == "pyrhonn"
    remote = shlex.split(lines[1], comments=True)[2:]
    assert len(remote) == 1 and re.fullmatch(r"git\+https://<git host>/<owner>/pyrhonn\.git", remote[0]), remote


def test_xcp_test_commands_name_tests_and_targets_that_exist() -> None:
    # the suite and CI run these; here each names what exists: test files, make targets, the VM
    # runner and CTest names
    ctests = set(re.findall(r"add_test\(NAME (\S+)", "".join(
        p.read_text(encoding="utf-8") for p in ROOT.rglob("CMakeLists.txt") if ".venv" not in p.parts)))
    for body in blocks_by("docs/xcp.md", "test_docs_commands.py::test_xcp_test_commands_name_tests_and_targets_that_exist"):
        for line in commands(body):
            words = shlex.split(line, comments=True)
            if words[0] == "make":
                _check_make(line, "docs/xcp.md")
            elif words[0] == "ctest":
                pattern = words[words.index("-R") + 1]
                assert any(re.search(pattern, name) for name in ctests), f"docs/xcp.md: `{line}` selects no CTest test"
            else:
                scripts = [w for word in words for w in word.split() if w.endswith(".py")]
                assert scripts, line
                for script in scripts:
                    assert (ROOT / "tests" / script).exists() or (ROOT / script).exists(), \
                        f"docs/xcp.md: `{line}`: no {script}"


def test_reproduce_all_commands_run_on_short_horizons(tmp_path: Path) -> None:
    # the pages' `pyrhonn reproduce all` runs every table's full horizon (15 s on an idle 2-core
    # machine, minutes on a loaded one); here the same command runs on 1 s horizons, with no horizon study
    label = "test_docs_commands.py::test_reproduce_all_commands_run_on_short_horizons"
    lines = {line.split("#")[0].strip() for page in ("docs/output-files.md", "docs/reproduce.md", "docs/reproduction.md")
             for body in blocks_by(page, label) for line in commands(body)}
    assert lines == {"pyrhonn reproduce all --out reproduce-out"}, lines
    [line] = lines
    run(["bash", "-ec", f"{line} --horizon 1 --no-horizon-study"], tmp_path, f"`{line}`", timeout=900)
    written = {p.name for p in (tmp_path / "reproduce-out").rglob("*")}
    assert any(name.endswith(".json") for name in written) and any(name.endswith(".png") for name in written), written


def _plant_csv(path: Path, n: int, states: int, seed: int) -> None:
    """A small stand-in record: ``states`` coupled first-order states driven by a staircase input u."""
    rng = np.random.default_rng(seed)
    u = np.repeat(rng.uniform(-1, 1, n // 10 + 1), 10)[:n]
    x = np.zeros((n, states))
    for k in range(n - 1):
        x[k + 1, 0] = 0.8 * x[k, 0] + 0.3 * np.tanh(u[k])
        for i in range(1, states):
            x[k + 1, i] = 0.9 * x[k, i] + 0.1 * x[k, i - 1]
    names = ["y"] if states == 1 else [f"x{i + 1}" for i in range(states)]
    np.savetxt(path, np.column_stack([np.arange(n) * 0.01, x, u]), delimiter=",",
               header=",".join(["t", *names, "u"]), comments="")


def _few_trials(line: str) -> str:
    """``line`` with 2 tuning trials instead of its number (or the default)."""
    if not line.startswith("pyrhonn tune"):
        return line
    line = line.split(" #")[0]
    return re.sub(r"--trials \d+", "--trials 2", line) if "--trials" in line else f"{line} --trials 2"


def test_selection_and_tuning_commands_run_on_small_records(tmp_path: Path) -> None:
    # the page's commands on small stand-ins of the user's records (est.csv and val.csv: one output
    # y and one input u; data.csv and run.csv: states x1..x4), with 2 tuning trials instead of 60 to 200
    label = "test_docs_commands.py::test_selection_and_tuning_commands_run_on_small_records"
    _plant_csv(tmp_path / "est.csv", 800, 1, 1)
    _plant_csv(tmp_path / "val.csv", 400, 1, 2)
    for name in ("data.csv", "run.csv"):
        _plant_csv(tmp_path / name, 300, 4, 3)
    ran = 0
    for body in blocks_by("docs/selection-and-tuning.md", label):
        for line in commands(body):
            if line.startswith("pyrhonn tune") and "--config base.toml" in line and not (tmp_path / "base.toml").exists():
                shutil.copy(tmp_path / "selected.toml", tmp_path / "base.toml")
            run(["bash", "-ec", _few_trials(line)], tmp_path, f"docs/selection-and-tuning.md: `{line}`", timeout=600)
            ran += 1
    assert ran >= 10 and (tmp_path / "tuned.h").exists() and (tmp_path / "tune.json").exists()


def test_capacities_of_the_install_command_are_read_by_the_build() -> None:
    # `PYRHONN_CAPACITIES=... pip install .` rebuilds the extensions (minutes): here the build reads the
    # page's value as the capacities it names
    from pyrhonn import _build

    [body] = blocks_by("docs/selection-and-tuning.md",
                       "test_docs_commands.py::test_capacities_of_the_install_command_are_read_by_the_build")
    [line] = commands(body)
    m = re.match(r'PYRHONN_CAPACITIES="([^"]+)" pip install \.', line)
    assert m, line
    caps = _build.capacities(m.group(1))
    for item in m.group(1).split(","):
        name, value = item.split("=")
        assert caps[f"RHONN_MAX_{name}"] == int(value), (name, caps)


def _recordings(folder: Path) -> None:
    """Small stand-ins of docs/recordings.md's files: lim.toml (the firmware's LIM identifier with the
    page's [bus] table), rhonn_id.dbc, run.blf (60 Measurement frames), run.mf4 (channels x1, x2,
    pos3, x4, u at 10 ms), export.csv (a tool's export: `;`, decimal commas and a unit row)."""
    can = pytest.importorskip("can")
    cantools = pytest.importorskip("cantools")
    from docs_blocks import code_blocks
    from pyrhonn.configfile import shipped_text

    page = (ROOT / "docs" / "recordings.md").read_text(encoding="utf-8")
    bus = next(body for lang, body, _, _ in code_blocks(page) if lang == "toml" and body.startswith("[bus]"))
    (folder / "lim.toml").write_text(shipped_text("firmware-lim") + "\n" + bus, encoding="utf-8")
    shutil.copy(ROOT / "firmware_sim" / "rhonn_id.dbc", folder / "rhonn_id.dbc")
    msg = cantools.database.load_file(str(folder / "rhonn_id.dbc")).get_message_by_name("Measurement")
    with can.BLFWriter(str(folder / "run.blf")) as log:
        for k in range(60):
            values = {s.name: (k if s.name == "Seq" else 1 if s.length == 1 else 0.01 * np.sin(0.1 * k + i))
                      for i, s in enumerate(msg.signals)}
            log.on_message_received(can.Message(timestamp=1.0 + 3e-4 * k, arbitration_id=msg.frame_id,
                                                data=msg.encode(values), is_extended_id=False, is_fd=True))
    rng = np.random.default_rng(0)
    t = np.arange(200) * 0.01
    x = np.cumsum(rng.normal(0, 0.01, (200, 5)), axis=0)
    rows = ["t;x1;x2;x3;x4;u", "s;m;m;m;m;V"] + [";".join(f"{v:.4f}".replace(".", ",") for v in (t[k], *x[k]))
                                                  for k in range(200)]
    (folder / "export.csv").write_text("\n".join(rows) + "\n", encoding="utf-8")
    asammdf = pytest.importorskip("asammdf")
    with asammdf.MDF(version="4.10") as mdf:
        mdf.append([asammdf.Signal(x[:, i], t, name=name, unit="m")
                    for i, name in enumerate(("x1", "x2", "pos3", "x4", "u"))])
        mdf.save(folder / "run.mf4", overwrite=True)


def test_recordings_commands_run_on_small_recordings(tmp_path: Path) -> None:
    label = "test_docs_commands.py::test_recordings_commands_run_on_small_recordings"
    _recordings(tmp_path)
    (tmp_path / "firmware_sim").symlink_to(ROOT / "firmware_sim", target_is_directory=True)
    *shell, excerpt = blocks_by("docs/recordings.md", label)
    for body in shell:
        for line in commands(body):
            run(["bash", "-ec", line], tmp_path, f"docs/recordings.md: `{line}`")
    # the header excerpt: its lines, in order, in the header the export wrote ("..." for lines left out)
    header = (tmp_path / "lim_id.h").read_text(encoding="utf-8").splitlines()
    at = 0
    for line in excerpt.splitlines():
        if line.strip() == "...":
            continue
        assert line in header[at:], f"docs/recordings.md: the excerpt's line {line!r} is not in the written lim_id.h"
        at = header.index(line, at) + 1


def _start(line: str, cwd: Path) -> subprocess.Popen[str]:
    """Start a page's `COMMAND &` line; returns once the runner says where its XCP slave listens."""
    argv = shlex.split(line.split("#")[0].strip().rstrip("&"))
    proc = subprocess.Popen(argv, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert proc.stdout is not None
    first = proc.stdout.readline()
    assert first.startswith("xcp: "), (line, first, proc.stderr.read() if proc.poll() is not None and proc.stderr else "")
    return proc


def _stop(proc: subprocess.Popen[str]) -> None:
    if proc.poll() is None:
        proc.terminate()
    proc.communicate(timeout=30)


def _xcp_session(tmp_path: Path, blocks: list[str], session: str, runner: Path | None = None) -> str:
    """Run a page's shell block (the runner started in the background, the A2L written) and then
    its pyxcp session; the session's output. With ``runner``, that runner is linked in as the page's
    build/xcp/rhonn_runner (and its build line is left out)."""
    pytest.importorskip("pyxcp")
    if shutil.which("cc") is None and shutil.which("gcc") is None:
        pytest.skip("no C compiler to build rhonn_runner")
    (tmp_path / "firmware_sim").symlink_to(ROOT / "firmware_sim", target_is_directory=True)
    (tmp_path / "build" / "xcp").mkdir(parents=True)
    if runner is not None:
        (tmp_path / "build" / "xcp" / "rhonn_runner").symlink_to(runner)
    procs = []
    try:
        for body in blocks:
            for line in commands(body):
                if line.split("#")[0].strip().endswith("&"):
                    procs.append(_start(line, tmp_path))
                elif runner is None or "build_runner.py" not in line:
                    run(["bash", "-ec", line], tmp_path, f"docs/xcp.md: `{line}`", timeout=600)
        (tmp_path / "session.py").write_text(session, encoding="utf-8")
        return run([sys.executable, "session.py"], tmp_path, "docs/xcp.md: the pyxcp session", timeout=120)
    finally:
        for proc in procs:
            _stop(proc)


def test_xcp_session_of_the_page_runs_against_the_runner(tmp_path: Path) -> None:
    # the page's runner (built, started bus-less with XCP on UDP 5555), its A2L and its pyxcp session
    label = "test_docs_commands.py::test_xcp_session_of_the_page_runs_against_the_runner"
    shell, session = blocks_by("docs/xcp.md", label)
    out = _xcp_session(tmp_path, [shell], session)
    assert "RHONN_LIM" in out and re.search(r"^\d+ steps so far", out, re.M), out
    assert re.search(r"^\d+ samples; the last:", out, re.M), out
    assert (tmp_path / "build" / "xcp" / "rhonn_lim.a2l").exists()


@pytest.mark.vcan
def test_xcp_session_of_the_page_runs_over_can_fd(vcan0: str, runner: Path, tmp_path: Path) -> None:
    # the page's CAN variant: the same session with the CAN transport (the page shows only the lines
    # that change), against the runner this tier built
    udp = "test_docs_commands.py::test_xcp_session_of_the_page_runs_against_the_runner"
    label = "test_docs_commands.py::test_xcp_session_of_the_page_runs_over_can_fd"
    _, udp_session = blocks_by("docs/xcp.md", udp)
    shell, can_session = blocks_by("docs/xcp.md", label)
    setup = udp_session.split("with Master(")[0]
    out = _xcp_session(tmp_path, [shell], setup + can_session, runner=runner)
    assert "RHONN_LIM" in out, out


def test_commands_at_a_glance_run_on_a_small_record(tmp_path: Path) -> None:
    # docs/output-files.md's list on a stand-in record (states x1, x2, input u, 600 samples) and a
    # config cfg.toml selected from it, with 2 tuning trials instead of the default
    rng = np.random.default_rng(0)
    u = np.repeat(rng.uniform(-1, 1, 60), 10)
    x = np.zeros((600, 2))
    for k in range(599):
        x[k + 1] = 0.9 * x[k, 0] + 0.1 * x[k, 1], 0.8 * x[k, 1] + 0.2 * np.tanh(u[k])
    x += rng.normal(0, 1e-3, x.shape)
    np.savetxt(tmp_path / "data.csv", np.column_stack([np.arange(600) * 0.01, x, u]), delimiter=",",
               header="t,x1,x2,u", comments="")
    run(["pyrhonn", "select", "data.csv", "--states", "x1,x2", "--inputs", "u", "--max-delay", "1", "--degree", "1",
         "--out", "cfg.toml"], tmp_path, "a config for the record")
    [body] = blocks_by("docs/output-files.md", "test_docs_commands.py::test_commands_at_a_glance_run_on_a_small_record")
    for line in commands(body):
        run(["bash", "-ec", _few_trials(line)], tmp_path, f"docs/output-files.md: `{line}`", timeout=600)
    assert (tmp_path / "tuned.h").exists() and (tmp_path / "results" / "metrics.json").exists()
