"""Plant simulators for the paper's three examples, one module per plant.

- :mod:`pyrhonn.plants.oscillator`: Example 1, the delayed chaotic oscillator (eq. 15), a DDE.
- :mod:`pyrhonn.plants.robot`: Example 2, the electrically driven differential robot.
- :mod:`pyrhonn.plants.lim`: Example 3, the linear induction motor.

Each has a validated parameter dataclass and a ``simulate(...)`` returning a
:class:`Trajectory` (true states, inputs, measured states and the valid mask).
Sensor effects (noise, quantisation, dropouts, hold windows) are applied in
one place, :func:`pyrhonn.plants.trajectory.measure`. Every run samples
through :func:`pyrhonn.plants.trajectory.sample_times`, which refuses a run of
more than :data:`~pyrhonn.plants.trajectory.MAX_SAMPLES` samples up front.

Every equation and number of the three plants, where each comes from and how
sure it is: docs/plants.md.
"""
from __future__ import annotations

from . import lim, oscillator, robot
from .trajectory import MAX_SAMPLES, Corruption, HoldWindow, Trajectory, measure, sample_times

__all__ = ["MAX_SAMPLES", "Corruption", "HoldWindow", "Trajectory", "lim", "measure", "oscillator", "robot",
           "sample_times"]
