"""Baselines the paper compares its RHONN identifier against.

- :mod:`pyrhonn.baselines.honn_observer`: the HONN observer of the paper's section 6.1.1
  (eq. 16-19, design of reference [20]), run on Example 1.
"""
from __future__ import annotations

from . import honn_observer
from .honn_observer import (
    HonnObserver,
    HonnObserverParams,
    common_targets,
    observe_oscillator,
    paper_delay_functions,
)

__all__ = [
    "HonnObserver",
    "HonnObserverParams",
    "common_targets",
    "honn_observer",
    "observe_oscillator",
    "paper_delay_functions",
]
