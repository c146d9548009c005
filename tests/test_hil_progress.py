"""A replay shows its progress on stderr while it runs: cycles done of the
total, estimates back, losses; at a modest rate; on a terminal by itself
(one line rewritten in place, cleared at the end), elsewhere only when
asked (``--progress``: a line every 2 s), never with ``--quiet``."""
from __future__ import annotations

import io
import re

import pytest

pytest.importorskip("can")
pytest.importorskip("cantools")

from pyrhonn.cli import main as pyrhonn_main  # noqa: E402

from hil import progress as prog  # noqa: E402


class _Clock:
    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


class _Tty(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_progress_is_shown_at_most_once_an_interval_and_always_at_the_end() -> None:
    clock, out = _Clock(), io.StringIO()
    p = prog.Progress(10_000, out, tty=False, interval=2.0, clock=clock)
    for k in range(0, 10_000, 256):   # every 256 cycles, 77 ms apart: 3 s in all
        clock.now = k * 3e-4
        p(k + 1, k + 1, k, 0)
    p(10_000, 9_990, 9_985, 10)
    lines = out.getvalue().splitlines()
    assert len(lines) == 2                        # at 2 s, and the last one
    assert lines[-1] == "hil replay: 10000/10000 cycles (100 %), 9985 estimates back, 10 lost (injected), 5 unanswered"


def test_on_a_terminal_one_line_is_rewritten_in_place_and_cleared_at_the_end() -> None:
    clock, out = _Clock(), _Tty()
    p = prog.Progress(100, out, tty=True, interval=0.5, clock=clock)
    for k in range(100):
        clock.now = k * 0.1
        p(k + 1, k + 1, k, 0)
    p.close()
    text = out.getvalue()
    assert "\n" not in text and text.count("\r") >= 20
    assert text.endswith("\r") and text.rstrip("\r").split("\r")[-1].strip() == ""   # the line is blanked


def test_auto_shows_progress_on_a_terminal_only_always_everywhere_never_nowhere() -> None:
    assert isinstance(prog.progress_for("auto", 10, _Tty()), prog.Progress)
    assert prog.progress_for("auto", 10, io.StringIO()) is None
    p = prog.progress_for("always", 10, io.StringIO())
    assert p is not None and not p.tty and p.interval == prog.LINE_INTERVAL_S
    assert prog.progress_for("never", 10, _Tty()) is None
    with pytest.raises(ValueError, match="progress: expected one of auto, always, never"):
        prog.progress_for("sometimes", 10)


def test_a_replay_reports_progress_on_stderr_when_asked_and_not_otherwise(capsys, cli_error) -> None:
    argv = ["hil", "replay", "--transport", "virtual", "--duration", "0.1", "--start", "1.95", "--frame-loss",
            "0.05", "--seed", "2"]
    assert pyrhonn_main(argv + ["--progress"]) in (0, 1)
    err = capsys.readouterr().err
    assert re.search(r"^hil replay: (\d+)/\1 cycles \(100 %\), \d+ estimates back, \d+ lost \(injected\), ", err,
                     re.M), err
    assert pyrhonn_main(argv) in (0, 1)                      # stderr is not a terminal here: nothing
    assert "cycles (" not in capsys.readouterr().err
    assert pyrhonn_main(argv + ["--quiet"]) in (0, 1)
    assert "cycles (" not in capsys.readouterr().err
    assert "not allowed with argument" in cli_error(argv + ["--quiet", "--progress"])
