"""A scenario file (TOML) for ``hil replay --scenario`` and ``hil score --scenario``:
the replay's scenario and the thresholds its verdicts are judged by.

    [scenario]                 # hil.scenario.Scenario's fields; every one optional
    duration = 0.3
    start = 0.9
    frame_loss = 0.01
    seed = 4
    trajectory = "run.csv"     # relative to this file's folder (so are identifier and dbc)

    [thresholds]               # hil.verdicts.Thresholds; every one optional
    lost_frames = 0
    rmse = { position = 2e-3, velocity = 3e-2 }
    bridging_ratio = { position = 1.0 }
    latency_us = { p99 = 300, "p99.9" = 1000 }

Either table may be left out. Any other table or key is refused by name.
"""
from __future__ import annotations

import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .scenario import Scenario, identifier_defaults
from .verdicts import Thresholds

__all__ = ["ScenarioFile", "read_scenario_file"]

MAX_BYTES = 1 << 20  #: a scenario file holds a few settings: refused beyond this


@dataclass(frozen=True)
class ScenarioFile:
    """What a scenario file holds: its path, its ``[scenario]`` fields (None: no such table) and thresholds."""

    path: Path
    scenario: dict[str, Any] | None
    thresholds: Thresholds

    def make_scenario(self, **given: Any) -> Scenario:
        """The Scenario of the file's fields and ``given`` (the command line's), refusing one set in both."""
        fields = dict(self.scenario or {})
        both = sorted(set(fields) & set(given))
        if both:
            raise ValueError(f"{self.path}: [scenario].{both[0]} is also given on the command line; set it in one "
                             "place")
        merged = {**fields, **given}
        if merged.get("trajectory") and "input_start" in merged:
            where = "--input-start" if "input_start" in given else f"{self.path}: [scenario].input_start"
            raise ValueError(f"{where}: applies to the simulated plant, not to a trajectory file")
        try:
            return Scenario.from_dict(identifier_defaults(merged))
        except ValueError as exc:
            raise ValueError(f"{self.path}: [scenario].{exc}") from None

    def check_recorded(self, recorded: Scenario) -> None:
        """For ``hil score``: the file's [scenario] table, if any, must be the log's own scenario."""
        if not self.scenario:
            return
        d = {**recorded.to_dict(), **self.scenario}
        for key in ("trajectory", "identifier", "dbc"):
            if key in self.scenario and f"{key}_sha256" not in self.scenario:
                d[f"{key}_sha256"] = ""   # pinned anew from the file named here
        try:
            mine = Scenario.from_dict(d)
        except ValueError as exc:
            raise ValueError(f"{self.path}: [scenario].{exc}") from None
        differ = sorted(k for k, v in mine.to_dict().items() if recorded.to_dict()[k] != v)
        if differ:
            raise ValueError(f"{self.path}: [scenario].{differ[0]} is not the recorded run's "
                             f"({recorded.to_dict()[differ[0]]!r}); hil score scores a log against its own scenario")


def read_scenario_file(path: Path) -> ScenarioFile:
    """Read and check a scenario file; a ValueError naming the file and the key."""
    from pyrhonn.validation import decode_text, read_file

    try:
        data = read_file(path, str(path), limit=MAX_BYTES)
    except OSError as exc:
        raise ValueError(f"--scenario: cannot read {path}: {exc.strerror or exc}") from None
    try:
        doc = tomllib.loads(decode_text(data, str(path)))
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{path}: not valid TOML ({exc})") from None
    unknown = sorted(set(doc) - {"scenario", "thresholds"})
    if unknown:
        raise ValueError(f"{path}: unknown table [{unknown[0]}]; a scenario file has [scenario] and [thresholds]")
    sc = doc.get("scenario")
    if sc is not None:
        if not isinstance(sc, dict):
            raise ValueError(f"{path}: scenario: expected a table [scenario]")
        sc = dict(sc)
        for key in ("trajectory", "identifier", "dbc"):   # relative to the file, not the cwd
            if isinstance(sc.get(key), str) and sc[key]:
                sc[key] = str((path.parent / Path(sc[key]).expanduser()).resolve())
    try:
        thresholds = Thresholds.from_dict(doc.get("thresholds", {}))
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from None
    return ScenarioFile(path=path, scenario=sc, thresholds=thresholds)
