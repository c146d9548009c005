"""``pyrhonn.atomic``: a file is replaced whole or not at all, its temporary
file never outlives an exception nor looks like an output, and an output
folder is marked INCOMPLETE until its last file is in place. Every writer of
pyrhonn and hil goes through it."""
from __future__ import annotations

import os
import re
from pathlib import Path

import pytest

from pyrhonn import atomic

ROOT = Path(__file__).resolve().parent.parent


def _names(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


def test_a_write_replaces_the_file_whole_and_leaves_no_temporary(tmp_path: Path) -> None:
    target = tmp_path / "out.txt"
    target.write_text("old\n")
    atomic.write_text(target, "new\n")
    assert target.read_text() == "new\n" and _names(tmp_path) == ["out.txt"]


@pytest.mark.parametrize("error", [RuntimeError, KeyboardInterrupt])
def test_an_exception_mid_write_leaves_the_previous_file_and_removes_the_temporary(tmp_path: Path, error) -> None:
    target = tmp_path / "out.bin"
    target.write_bytes(b"previous")
    with pytest.raises(error):
        with atomic.replacing(target) as fh:
            fh.write(b"half of the new")
            temps = [p.name for p in tmp_path.iterdir() if p.name != "out.bin"]
            assert len(temps) == 1 and re.fullmatch(rf"\.out\.bin\.tmp-{os.getpid()}-[0-9a-f]{{8}}", temps[0])
            raise error
    assert target.read_bytes() == b"previous" and _names(tmp_path) == ["out.bin"]
    with pytest.raises(error):
        with atomic.replacing_path(target) as tmp:
            tmp.write_bytes(b"half")
            raise error
    assert target.read_bytes() == b"previous" and _names(tmp_path) == ["out.bin"]


def test_a_new_file_gets_the_usual_mode_and_a_replaced_one_keeps_its_own(tmp_path: Path) -> None:
    umask = os.umask(0)
    os.umask(umask)
    new = atomic.write_text(tmp_path / "new.txt", "x")
    assert new.stat().st_mode & 0o777 == 0o666 & ~umask
    kept = tmp_path / "private.txt"
    kept.write_text("secret")
    kept.chmod(0o600)
    atomic.write_text(kept, "still secret")
    assert kept.stat().st_mode & 0o777 == 0o600


def test_a_symbolic_link_stays_a_link_to_the_new_file(tmp_path: Path) -> None:
    real = tmp_path / "real.txt"
    real.write_text("old")
    link = tmp_path / "link.txt"
    link.symlink_to(real)
    atomic.write_text(link, "new")
    assert link.is_symlink() and real.read_text() == "new"


def test_a_folder_or_a_missing_folder_is_an_error_naming_the_target(tmp_path: Path) -> None:
    (tmp_path / "d").mkdir()
    with pytest.raises(IsADirectoryError, match=re.escape(str(tmp_path / "d"))):
        atomic.write_text(tmp_path / "d", "x")
    with pytest.raises(FileNotFoundError, match=re.escape(str(tmp_path / "nodir" / "f.txt"))):
        atomic.write_text(tmp_path / "nodir" / "f.txt", "x")
    assert _names(tmp_path) == ["d"]


def test_an_output_folder_is_marked_incomplete_until_the_block_ends_normally(tmp_path: Path) -> None:
    out = tmp_path / "new" / "out"
    with atomic.output_folder(out, "pyrhonn test") as folder:
        assert "pyrhonn test" in atomic.incomplete(folder) and "interrupted" in atomic.incomplete(folder)
        atomic.write_text(folder / "a.txt", "a")
    assert atomic.incomplete(out) is None and _names(out) == ["a.txt"]
    with pytest.raises(KeyboardInterrupt):
        with atomic.output_folder(out, "pyrhonn test"):
            atomic.write_text(out / "a.txt", "b")
            raise KeyboardInterrupt
    assert atomic.incomplete(out) is not None and _names(out) == [atomic.MARKER, "a.txt"]


def test_a_figure_is_saved_in_the_format_its_suffix_names(tmp_path: Path) -> None:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure()
    FigureCanvasAgg(fig)
    fig.subplots().plot([0, 1], [1, 0])
    assert atomic.save_figure(fig, tmp_path / "f.png").read_bytes().startswith(b"\x89PNG")
    assert atomic.save_figure(fig, tmp_path / "f.svg").read_text().lstrip().startswith("<?xml")
    assert _names(tmp_path) == ["f.png", "f.svg"]


# what may still write a file directly: the writes into a temporary file this module hands out, the
# write probes of output folders, and the build script's stubs
ALLOWED = {("pyrhonn/statefile.py", "np.savez(fh"), ("pyrhonn/reproduce.py", "probe.write_bytes"),
           ("pyrhonn/_build.py", ".write_text(\"\")"), ("hil/rig.py", "Writer(target)"),
           ("hil/rig.py", "_LogWriter(path, tmp"),  # tmp: the temporary file of atomic.replacing_path
           ("hil/rig.py", "class _ASCWriter(can.ASCWriter)"),  # a class line, not a write
           # scratch files of the size probe, in a TemporaryDirectory
           ("pyrhonn/export.py", '(t / "capacity.h").write_text'), ("pyrhonn/export.py", '(t / "probe.c").write_text'),
           # the FMU's sources compiled in a TemporaryDirectory; the .fmu itself goes through atomic.replacing
           ("pyrhonn/fmu.py", "(tmp / name).write_bytes")}
WRITES = re.compile(r"\.write_text\(|\.write_bytes\(|\bopen\([^)]*,\s*(mode=)?[\"'][wax]|\.open\(\s*[\"'][wax]|"
                    r"savefig\(|np\.save|json\.dump\(|Writer\(|tofile\(")


def test_every_writer_of_pyrhonn_and_hil_goes_through_the_atomic_module() -> None:
    direct = []
    for path in sorted([*ROOT.glob("pyrhonn/**/*.py"), *ROOT.glob("hil/**/*.py")]):
        rel = path.relative_to(ROOT).as_posix()
        if rel == "pyrhonn/atomic.py":
            continue
        for n, line in enumerate(path.read_text().splitlines(), 1):
            if WRITES.search(line) and "atomic." not in line and not any(
                    rel == f and s in line for f, s in ALLOWED):
                direct.append(f"{rel}:{n}: {line.strip()}")
    assert not direct, "files written without pyrhonn.atomic:\n" + "\n".join(direct)
