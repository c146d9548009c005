"""Recorded LIM trajectories: the truth a replay can take instead of the plant.

A scenario normally simulates the LIM (:mod:`pyrhonn.plants.lim`). With
``Scenario(trajectory=PATH)`` it replays a recorded trajectory instead: a
log from another simulator, or from a rig with a reference sensor, put
through the same rig model (encoder quantisation, velocity by differencing,
hold, frame loss, delay) and scored against the file's states.

File format
-----------
The CSV of ``pyrhonn identify`` for the ``firmware-lim`` config (see
:mod:`pyrhonn.datafile`): a header, then one line per sample, with the
columns

    t, q_m, v, lambda_a, lambda_b, i_a, i_b, u_a, u_b

(SI units: s, m, m/s, Wb, A, V; other columns are ignored). ``t`` is
required and uniform: every step equals the first to within 1e-6 of it.
The sampling step must divide the rig's period (0.3 ms: a 0.3 ms, 0.1 ms or
0.05 ms log); a finer log is read every period/step-th sample, as an ADC
sampling at the rig's period would. Every state is given on every line: a
trajectory is the truth, so it has no validity columns set to 0 and no
missing values.

:func:`write_trajectory` writes the format (``pyrhonn hil trajectory``
exports the plant's trajectory with it, a template for your own files).
Every defect raises ``ValueError`` naming the file and, where there is one,
the line.

For another identifier (``Scenario(identifier=...)``) the columns are ``t``
and that config file's own state and input names (``pyrhonn select
data.csv --states y1,y2 --inputs u`` names them after the data's columns),
read by :func:`read_trajectory` with the config file given.
"""
from __future__ import annotations

import functools
import hashlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pyrhonn import atomic
from pyrhonn.plants.lim import INPUT_NAMES, STATE_NAMES

__all__ = ["COLUMNS", "RecordedTrajectory", "file_sha256", "read_trajectory", "samples_per_period",
           "write_trajectory"]

#: the columns a trajectory file must have, in the order write_trajectory writes them
COLUMNS = ("t", *STATE_NAMES, *INPUT_NAMES)
#: the relative tolerance on the uniformity of t and on step dividing the period
STEP_TOLERANCE = 1e-6


@dataclass(frozen=True, eq=False)
class RecordedTrajectory:
    """A trajectory file sampled at the rig's period: ``t`` (N,), ``X``
    (N, n), ``U`` (N, m) float64 (the LIM: n = 6, m = 2); ``step`` the file's own sampling step,
    ``every`` how many file samples make one period."""

    path: str
    t: np.ndarray
    X: np.ndarray
    U: np.ndarray
    step: float
    every: int


def samples_per_period(step: float, period: float) -> int:
    """How many samples of ``step`` make one ``period``; ValueError when
    ``step`` is not positive or does not divide ``period``."""
    ratio = period / step if step > 0 else 0.0
    every = int(round(ratio))
    if every < 1 or abs(ratio - every) > STEP_TOLERANCE * ratio:
        raise ValueError(f"sampling step {step!r} s does not divide the rig's period {period!r} s "
                         "(use a step of the period or of an integer fraction of it)")
    return every


def file_sha256(path: str | Path) -> str:
    """The SHA-256 of a file's bytes (hex); OSError when it cannot be read."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


@functools.cache
def _lim_file_config():
    from pyrhonn.configfile import load_shipped

    return load_shipped("firmware-lim")


def read_trajectory(path: str | Path, period: float, config_file: Any = None) -> RecordedTrajectory:
    """Read, check and sample at ``period`` the trajectory file ``path``: the LIM's columns, or with
    ``config_file`` (a pyrhonn.configfile.ConfigFile) that identifier's states and inputs."""
    from pyrhonn.datafile import read_data

    source = str(path)
    if config_file is None:
        cf = _lim_file_config()
        if tuple(cf.state_names) + tuple(cf.input_names) != COLUMNS[1:]:  # the DBC's order, guarded
            raise RuntimeError("firmware-lim's state/input names no longer match the LIM's (hil.trajectory.COLUMNS)")
        what = "a LIM trajectory"
    else:
        cf, what = config_file, "the identifier's trajectory"
    columns = ("t", *cf.state_names, *cf.input_names)
    data = read_data(path, cf, config_source=what)
    if data.t is None:
        raise ValueError(f"{source}: line 1: missing column 't' (a trajectory needs its sample times, in s)")
    if not data.valid.all():
        k, j = np.argwhere(~data.valid)[0]
        raise ValueError(f"{source}: line {int(data.lines[k])}: {columns[1 + j]} marked not valid: a trajectory is "
                         "the truth, every state on every line (the rig model adds the hold)")
    t = data.t
    if t.size < 2:
        raise ValueError(f"{source}: one sample only: a trajectory needs at least two to have a sampling step")
    steps = np.diff(t)
    step = float(steps[0])
    off = np.flatnonzero(np.abs(steps - step) > STEP_TOLERANCE * step)
    if off.size:
        k = int(off[0]) + 1
        raise ValueError(f"{source}: line {int(data.lines[k])}: time step {float(steps[k - 1])!r} s differs from the "
                         f"first, {step!r} s (the samples must be uniform)")
    try:
        every = samples_per_period(step, period)
    except ValueError as exc:
        raise ValueError(f"{source}: {exc}") from None
    keep = slice(0, None, every)
    return RecordedTrajectory(path=source, t=t[keep].copy(), X=data.X[keep].copy(), U=data.U[keep].copy(),
                              step=step, every=every)


def write_trajectory(path: str | Path, t: np.ndarray, X: np.ndarray, U: np.ndarray) -> None:
    """Write ``t`` (N,), ``X`` (N, 6), ``U`` (N, 2) in the trajectory format;
    every value round-trips exactly (17 significant digits)."""
    t, X, U = (np.asarray(a, dtype=np.float64) for a in (t, X, U))
    n = t.shape[0] if t.ndim == 1 else -1
    if n < 2 or X.shape != (n, 6) or U.shape != (n, 2):
        raise ValueError(f"trajectory: expected t (N,), X (N, 6), U (N, 2) with N >= 2, got {t.shape}, {X.shape}, "
                         f"{U.shape}")
    rows = np.column_stack([t, X, U])
    if not np.isfinite(rows).all():
        k = int(np.argwhere(~np.isfinite(rows))[0][0])
        raise ValueError(f"trajectory: sample {k} is not finite")
    with atomic.replacing(path, "w", newline="") as f:  # an interrupted write leaves the previous file or none
        f.write(",".join(COLUMNS) + "\n")
        for row in rows:
            f.write(",".join(repr(float(v)) for v in row) + "\n")
