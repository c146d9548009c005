"""A replay's progress on stderr while it runs.

The rig offers its counts every :data:`hil.rig.PROGRESS_EVERY` cycles, right
after sending a frame (the most slack before the next deadline);
:class:`Progress` shows them at most every ``interval`` seconds:

- on a terminal, one line rewritten in place (carriage return) every 0.5 s,
  cleared when the replay ends, so that the report that follows starts on a
  clean line;
- elsewhere (a pipe, a file, CI) nothing, unless asked (``hil replay
  --progress``): then one line every 2 s, each on its own line, which a log
  keeps readable;
- ``--quiet``: nothing.

A line reads ``hil replay: 6144/13333 cycles (46 %), 5980 estimates back, 120
lost (injected), 44 unanswered``: cycles done of the scenario's, Estimates
received so far, frames the scenario dropped on purpose, and frames sent
whose Estimate has not come (yet: the one in flight counts until it lands).
"""
from __future__ import annotations

import sys
import time
from typing import Callable, TextIO

__all__ = ["MODES", "Progress", "progress_for"]

MODES = ("auto", "always", "never")   #: auto: on a terminal only
TTY_INTERVAL_S = 0.5
LINE_INTERVAL_S = 2.0


class Progress:
    """Callable as the rig's progress hook: ``(cycles done, frames sent,
    estimates back, frames lost by the scenario)``. ``total``: the scenario's
    cycles; ``stream``: where to write; ``tty``: rewrite one line in place
    (else a line each time); ``interval``: the least time between two
    updates, s; ``clock``: seconds, monotonic (tests give their own)."""

    def __init__(self, total: int, stream: TextIO, *, tty: bool, interval: float,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.total = int(total)
        self.stream = stream
        self.tty = bool(tty)
        self.interval = float(interval)
        self.clock = clock
        self._next = clock() + self.interval
        self._shown = False
        self._width = 0

    def line(self, done: int, sent: int, back: int, lost: int) -> str:
        pct = 100.0 * done / self.total if self.total else 100.0
        return (f"hil replay: {done}/{self.total} cycles ({pct:.0f} %), {back} estimates back, {lost} lost "
                f"(injected), {max(sent - back, 0)} unanswered")

    def __call__(self, done: int, sent: int, back: int, lost: int) -> None:
        now = self.clock()
        if now < self._next and done < self.total:
            return
        self._next = now + self.interval
        text = self.line(done, sent, back, lost)
        try:
            if self.tty:
                self.stream.write("\r" + text.ljust(self._width))
                self._width = len(text)
            else:
                self.stream.write(text + "\n")
            self.stream.flush()
        except (OSError, ValueError):  # a closed or broken stderr: the replay goes on without it
            return
        self._shown = True

    def close(self) -> None:
        """Clear the in-place line (a terminal), so that what follows starts at column 0."""
        if self.tty and self._shown:
            try:
                self.stream.write("\r" + " " * self._width + "\r")
                self.stream.flush()
            except (OSError, ValueError):
                pass
        self._shown = False


def progress_for(mode: str, total: int, stream: TextIO | None = None) -> Progress | None:
    """The Progress for ``--progress``/``--quiet`` (``mode`` in MODES) on ``stream`` (stderr), or None:
    ``auto`` shows it on a terminal only, ``always`` also elsewhere (a line every 2 s), ``never`` not."""
    if mode not in MODES:
        raise ValueError(f"progress: expected one of {', '.join(MODES)}, got {mode!r}")
    stream = sys.stderr if stream is None else stream
    try:
        tty = bool(stream.isatty())
    except (AttributeError, ValueError, OSError):
        tty = False
    if mode == "never" or (mode == "auto" and not tty):
        return None
    return Progress(total, stream, tty=tty, interval=TTY_INTERVAL_S if tty else LINE_INTERVAL_S)
