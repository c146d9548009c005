"""Kill a writer in the middle of its writes, at a moment tied to its progress.

A test that forks a writer and kills it after a random *time* depends on how fast
the machine is: on a loaded one, the writer may never finish the second write
before the kill, so the test never sees the state that write leaves. Here the
child reports each finished write through a pipe; the parent waits for a random
number of them (0, 1 or 2) and only then for a random time, so every state comes
up on a busy machine as on an idle one, and the kill still lands at any moment.
"""
from __future__ import annotations

import os
import signal
import time
from typing import Callable, Sequence

import numpy as np


def kill_while_writing(writes: Sequence[Callable[[], None]], rng: np.random.Generator,
                       max_delay: float) -> int:
    """Fork a child that calls ``writes`` in turn, forever; kill it (SIGKILL) after
    it has finished 0, 1 or 2 writes (drawn from ``rng``) and a further random
    delay of up to ``max_delay`` seconds. Returns how many writes it had finished
    when the parent last heard from it."""
    done_r, done_w = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: write, write, write ... until killed
        try:
            os.close(done_r)
            while True:
                for write in writes:
                    write()
                    os.write(done_w, b".")
        finally:
            os._exit(1)
    os.close(done_w)
    heard = 0
    try:
        for _ in range(int(rng.integers(0, 3))):
            if not os.read(done_r, 1):
                raise AssertionError("the writing child died before it was killed")
            heard += 1
        time.sleep(float(rng.uniform(0.0, max_delay)))
        os.kill(pid, signal.SIGKILL)
    finally:
        _, status = os.waitpid(pid, 0)
        os.close(done_r)
    assert os.WIFSIGNALED(status) and os.WTERMSIG(status) == signal.SIGKILL, \
        "the writing child ended on its own, not by the kill"
    return heard
