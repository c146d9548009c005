"""Hardware-in-the-loop replay of the LIM rig, on python-can.

The rig side of the paper's real-time LIM experiment (section 6.3.2, Table 7):
a seeded :class:`~hil.scenario.Scenario` (LIM trajectory at 0.3 ms, encoder
quantisation, velocity by differencing, the measurement hold from 1.1 s,
frame loss, transport delay) is replayed as the DBC's Measurement frames on an
absolute 0.3 ms schedule (:mod:`hil.rig`), the Estimate frames that come back
are matched by sequence counter and everything is logged (BLF/ASC), and a run
is scored (:mod:`hil.score`) and reported (:mod:`hil.report`). Transports
(:mod:`hil.transport`): ``virtual`` (in-process FirmwareApp), ``udp_multicast``
(``python -m hil.firmware_node``), ``socketcan`` (firmware_sim's rhonn_runner).

``hil`` depends on pyrhonn, never the reverse; ``pyrhonn hil`` is registered
through the ``pyrhonn.commands`` entry point (:mod:`hil.cli`).
"""
from __future__ import annotations

__all__ = ["Scenario", "Plan", "run_replay"]

from .scenario import Plan, Scenario  # noqa: E402


def run_replay(*args, **kwargs):
    from .transport import run_replay as _run

    return _run(*args, **kwargs)
