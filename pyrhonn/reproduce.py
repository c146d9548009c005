"""Reproduce the paper's simulation tables (Tables 1-6) with the C identifier.

One scenario is: plant (:mod:`pyrhonn.plants`) -> identifier (the C core,
:meth:`pyrhonn.Identifier.run`) -> metrics (:mod:`pyrhonn.metrics`), side by
side with the paper's figures. Example 1 also runs the HONN observer of the
paper's section 6.1.1 (:mod:`pyrhonn.baselines.honn_observer`) on the same
trajectory, and every scenario carries a naive *persistence* predictor
x̂(k+1) = x(k) as a scale reference (what predicting "no change" scores).

Scenarios (:data:`SCENARIOS`)
-----------------------------
- ``example1-dt0.2``: eq. 15 at T = 0.2 s, 100 s; Tables 1 (RMSE), 2 (AD).
- ``example1-dt0.02``: eq. 15 at T = 0.02 s, 100 s; Table 3 (RMSE, absent
  in the OCR text, so not compared), Table 4 (AD).
- ``example2``: the robot at T = 0.01 s, 15 s (the paper's); Table 5.
- ``example3``: the LIM at T = 1e-4 s, 5 s (PROPOSED); Table 6 (position
  and velocity only).

Alignment and metrics
---------------------
The identifier's row k is its prediction x̂(k+1), made from data up to
sample k (series-parallel, one step ahead). Every estimator is therefore
scored on the targets x(1) .. x(T-1): ``truth = X[1:]`` against the
identifier's rows ``[:-1]``, the observer's rows ``[1:]`` (its row k is x̂(k)
from data up to k-1; :func:`~pyrhonn.baselines.honn_observer.common_targets`)
and the persistence rows ``X_meas[:-1]``. RMSE and absolute deviation (mean
absolute deviation of the error about its mean, :mod:`pyrhonn.metrics`) are
taken over all those samples, as the paper does (no warm-up). The first
predictions, made while the weights are still at w(0) = 0, are included; the
JSON also reports the RMSE after a warm-up of :data:`DIAGNOSTIC_WARMUP`
samples and over the targets whose measurement was valid (outside the hold
windows), to show where an error comes from.

Holds ("information not updated", Examples 2 and 3): by default the
identifier is told which samples are stale (``valid`` flags, so it neither
learns from them nor feeds them back; it bridges the window on its own
predictions, see ``csrc/include/rhonn.h``). ``mask_holds=False`` feeds the
held readings as if they were fresh, as an identifier that is not told would
see them. Metrics always compare against the true state.

Example 1 horizon: the paper does not state it. 100 s is the oscillator
module's default (chosen before any identifier was run, see
:mod:`pyrhonn.plants.oscillator`); :func:`horizon_study` reports every figure
at 10, 20, 50, 100 and 150 s as well (docs/plants.md#oscillator-horizon).

Outputs (:func:`write_outputs`): ``<key>.json`` (all numbers), one PNG per
identifier / observer with the real and the estimated state per subplot,
like the paper's Fig. 1-17 (real: black solid, estimate: grey dotted, hold
windows shaded), and ``<key>-errors.png`` with the error of every estimator.
Every y axis carries the state's unit (:data:`STATE_UNITS`), and the legend
names the shading.
"""
from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from . import atomic, metrics
from .baselines.honn_observer import HonnObserverParams, observe_oscillator
from .config import DTYPES, IdentifierConfig
from .configfile import ConfigFile, load_named, load_shipped
from .identifier import Identifier
from .plants import lim, oscillator, robot
from .plants.trajectory import Corruption, HoldWindow, Trajectory
from .validation import check_int, check_real, fail

__all__ = [
    "DIAGNOSTIC_WARMUP",
    "EXAMPLES",
    "EstimatorResult",
    "HORIZONS",
    "HorizonPoint",
    "IdentifierSpec",
    "PAPER",
    "check_identifiers",
    "check_output_dir",
    "horizon_study",
    "PaperFigures",
    "SCENARIOS",
    "STATE_UNITS",
    "Scenario",
    "ScenarioResult",
    "format_horizon_study",
    "format_table",
    "identifier_from_file",
    "run",
    "run_scenario",
    "scenario_keys",
    "shipped_identifiers",
    "simulate",
    "write_outputs",
]

EXAMPLES = ("example1", "example2", "example3")
#: horizons of the Example 1 study (docs/plants.md#oscillator-horizon; 10 s: before x4's first spike)
HORIZONS = (10.0, 20.0, 50.0, 100.0, 150.0)
DIAGNOSTIC_WARMUP = 10  #: samples skipped by the ``rmse_after_warmup`` diagnostic
EXAMPLE1_PERIODS = (0.2, 0.02)
RMSE_TARGET = {"example1": 1.0, "example2": 2.0, "example3": 2.0}  #: paper-example target: identifier RMSE / paper
AD_TARGET = {"example1": 1.0}  #: paper-example target: identifier absolute deviation / paper (Example 1 only)
#: Unit of each state, in the order of the plant's state names (docs/plants.md): the oscillator's
#: states are dimensionless (the paper gives no units), the robot's and the LIM's are SI.
STATE_UNITS = {
    "example1": ("dimensionless",) * 4,
    "example2": ("m", "m", "rad", "rad/s", "rad/s", "A", "A"),
    "example3": ("m", "m/s", "Wb", "Wb", "A", "A"),
}
HOLD_LABEL = "not updated (hold)"  #: legend entry of the shaded samples whose measurement was not valid

Progress = Callable[[str], None]


# -- the paper's figures --------------------------------------------------------------------------


@dataclass(frozen=True)
class PaperFigures:
    """The paper's figures for one scenario, transcribed from the OCR text.

    Each tuple has one entry per plant state, in the plant's state order;
    ``None`` where the paper prints no figure (Table 3 is absent from the
    OCR text; Table 6 reports only position and velocity; the observer
    exists only in Example 1).
    """

    rmse_table: str
    ad_table: str
    identifier_rmse: tuple[float | None, ...]
    identifier_ad: tuple[float | None, ...]
    observer_rmse: tuple[float | None, ...] | None = None
    observer_ad: tuple[float | None, ...] | None = None
    notes: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        return {"rmse_table": self.rmse_table, "ad_table": self.ad_table,
                "identifier_rmse": list(self.identifier_rmse), "identifier_ad": list(self.identifier_ad),
                "observer_rmse": None if self.observer_rmse is None else list(self.observer_rmse),
                "observer_ad": None if self.observer_ad is None else list(self.observer_ad),
                "notes": list(self.notes)}


_NONE4: tuple[None, None, None, None] = (None, None, None, None)

PAPER: dict[str, PaperFigures] = {
    "example1-dt0.2": PaperFigures(
        rmse_table="Table 1", ad_table="Table 2",
        identifier_rmse=(0.32413, 0.32221, 0.32818, 0.36338),
        identifier_ad=(0.19940, 0.19558, 0.20089, 0.36338),
        observer_rmse=(0.12869, 0.53040, 0.18226, 1.52967),
        observer_ad=(0.06331, 0.32323, 0.09719, 0.71550),
        notes=("The identifier's x4 figure is 0.36338 in both Table 1 (RMSE) and Table 2 (absolute "
               "deviation); every other entry has AD < RMSE, so one of the two is probably a copy error.",),
    ),
    "example1-dt0.02": PaperFigures(
        rmse_table="Table 3 (absent in the OCR text)", ad_table="Table 4",
        identifier_rmse=_NONE4,
        identifier_ad=(0.04952, 0.03965, 0.03586, 0.03708),
        observer_rmse=_NONE4,
        observer_ad=(0.54382, 0.03168, 0.77253, 0.07352),
        notes=("Table 3 (RMSE at T = 0.02 s) is empty in the OCR text: only its absolute-deviation twin, "
               "Table 4, can be compared.",),
    ),
    "example2": PaperFigures(
        rmse_table="Table 5", ad_table="Table 5",
        identifier_rmse=(2.31102e-2, 7.59874e-3, 6.93572e-3, 1.19412e-2, 1.63750e-2, 2.26067e-2, 2.03897e-2),
        identifier_ad=(1.72779e-3, 7.16522e-4, 1.63137e-3, 2.62689e-3, 1.02881e-2, 3.60196e-3, 6.64885e-3),
        notes=("RMSE / AD is 3-13 for most states (13 for X): the paper's errors are dominated by a few "
               "large samples (e.g. a start-up transient), not by a steady error.",),
    ),
    "example3": PaperFigures(
        rmse_table="Table 6", ad_table="Table 6",
        identifier_rmse=(6.8560e-5, 1.5947e-4, None, None, None, None),
        identifier_ad=(8.7961e-6, 4.4238e-5, None, None, None, None),
        notes=("The OCR prints Table 6 without row labels; the caption names position and velocity, in "
               "that order, and the column order is absolute deviation, RMSE.",
               "Only position and velocity are reported; fluxes and currents have no paper figure.",
               "Table 7 (real-time LIM prototype) is not reproduced: it needs the laboratory hardware."),
    ),
}


# -- scenarios ------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Scenario:
    """One simulation of the paper: an example at one sampling period."""

    key: str
    example: str
    dt: float
    horizon: float
    title: str

    @property
    def paper(self) -> PaperFigures:
        return PAPER[self.key]


SCENARIOS: dict[str, Scenario] = {
    "example1-dt0.2": Scenario("example1-dt0.2", "example1", 0.2, oscillator.DEFAULT_HORIZON,
                               "Example 1 (delayed chaotic oscillator, eq. 15), T = 0.2 s"),
    "example1-dt0.02": Scenario("example1-dt0.02", "example1", 0.02, oscillator.DEFAULT_HORIZON,
                                "Example 1 (delayed chaotic oscillator, eq. 15), T = 0.02 s"),
    "example2": Scenario("example2", "example2", 0.01, 15.0,
                         "Example 2 (differential robot), T = 0.01 s"),
    "example3": Scenario("example3", "example3", 1e-4, 5.0,
                         "Example 3 (linear induction motor), T = 0.1 ms"),
}


def scenario_keys(example: str, dt: float | None = None) -> tuple[str, ...]:
    """The scenario keys of ``example`` ("example1".."example3" or "all").

    ``dt`` selects one sampling period of Example 1 (0.2 or 0.02; both when
    None). Examples 2 and 3 have the paper's single period, so ``dt`` must be
    None for them. ValueError naming the argument otherwise.
    """
    if example not in (*EXAMPLES, "all"):
        raise fail("example", f"expected one of {', '.join((*EXAMPLES, 'all'))}, got {example!r}")
    if dt is not None:
        if example != "example1":
            raise fail("dt", f"only example1 has a choice of sampling period (0.2 or 0.02 s); {example} "
                             "runs at the paper's period (example2 0.01 s, example3 0.0001 s)")
        value = check_real("dt", dt, positive=True)
        for period in EXAMPLE1_PERIODS:
            if abs(value - period) <= 1e-12:
                return (f"example1-dt{period:g}",)
        raise fail("dt", f"example1 was simulated at T = 0.2 s and T = 0.02 s in the paper; got {value!r}")
    if example == "all":
        return tuple(SCENARIOS)
    return tuple(k for k, s in SCENARIOS.items() if s.example == example)


def _scenario(scenario: str | Scenario) -> Scenario:
    if isinstance(scenario, Scenario):
        return scenario
    if not isinstance(scenario, str) or scenario not in SCENARIOS:
        raise fail("scenario", f"expected one of {', '.join(SCENARIOS)}, got {scenario!r}")
    return SCENARIOS[scenario]


def _paper_holds(example: str) -> tuple[HoldWindow, ...]:
    if example == "example2":
        return robot.paper_holds()
    if example == "example3":
        return lim.paper_holds()
    return ()


def simulate(scenario: str | Scenario, *, horizon: float | None = None, noise: float = 0.0,
             seed: int = 0) -> Trajectory:
    """The plant trajectory of a scenario (the paper's scenario, with its holds).

    horizon:
        Seconds; None for the scenario's default. Must be a whole number of
        sampling periods.
    noise:
        Additive Gaussian measurement noise, as a fraction of each state's
        standard deviation over the run (0: none, as the paper). Seeded by
        ``seed``; the true states are unaffected.
    """
    sc = _scenario(scenario)
    h = sc.horizon if horizon is None else check_real("horizon", horizon, positive=True)
    noise = check_real("noise", noise, nonnegative=True)
    seed = check_int("seed", seed, 0)
    if sc.example == "example1":
        traj = oscillator.simulate(dt=sc.dt, horizon=h)
    elif sc.example == "example2":
        traj = robot.simulate(dt=sc.dt, horizon=h)
    else:
        traj = lim.simulate(dt=sc.dt, horizon=h)
    if noise > 0.0:
        std = traj.X.std(axis=0)
        traj = traj.remeasure(holds=_paper_holds(sc.example), corruption=Corruption(noise_std=noise * std, seed=seed))
    return traj


# -- identifier configurations --------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class IdentifierSpec:
    """An identifier to run: a key (``identifier``, ``identifier-tuned``), a
    label for tables, where its config came from, and the config."""

    key: str
    label: str
    source: str
    config: IdentifierConfig

    def __post_init__(self) -> None:
        for name in ("key", "label", "source"):
            if not isinstance(getattr(self, name), str) or not getattr(self, name):
                raise fail(name, "expected a non-empty string")
        if not isinstance(self.config, IdentifierConfig):
            raise fail("config", f"expected an IdentifierConfig, got {type(self.config).__name__}")


def shipped_identifiers(example: str) -> tuple[IdentifierSpec, ...]:
    """The shipped configs of an example (``pyrhonn/configs``).

    Example 1: the paper's eq. 20 tuning (``example1``) and the tuned variant
    (``example1-tuned``); Examples 2 and 3: ``example2``, ``example3``.
    """
    if example not in EXAMPLES:
        raise fail("example", f"expected one of {', '.join(EXAMPLES)}, got {example!r}")
    if example == "example1":
        return (
            IdentifierSpec("identifier", "identifier (eq. 20)", "pyrhonn/configs/example1.toml",
                           load_shipped("example1").config),
            IdentifierSpec("identifier-tuned", "identifier (tuned)", "pyrhonn/configs/example1-tuned.toml",
                           load_shipped("example1-tuned").config),
        )
    return (IdentifierSpec("identifier", "identifier", f"pyrhonn/configs/{example}.toml",
                           load_shipped(example).config),)


def identifier_from_file(name_or_path: str) -> IdentifierSpec:
    """An identifier from a config file path or a shipped config name."""
    if not isinstance(name_or_path, str) or not name_or_path:
        raise fail("config", "expected a config file path or a shipped config name")
    cf: ConfigFile = load_named(name_or_path)
    return IdentifierSpec("identifier", "identifier (--config)", name_or_path, cf.config)


def _plant_names(example: str) -> tuple[tuple[str, ...], tuple[str, ...]]:
    module = {"example1": oscillator, "example2": robot, "example3": lim}[example]
    return tuple(module.STATE_NAMES), tuple(module.INPUT_NAMES)


def check_identifiers(example: str, specs: Sequence[IdentifierSpec]) -> None:
    """ValueError unless every spec has the plant's number of states and inputs."""
    if example not in EXAMPLES:
        raise fail("example", f"expected one of {', '.join(EXAMPLES)}, got {example!r}")
    states, inputs = _plant_names(example)
    for i, spec in enumerate(specs):
        if not isinstance(spec, IdentifierSpec):
            raise fail(f"identifiers[{i}]", f"expected an IdentifierSpec, got {type(spec).__name__}")
        cfg = spec.config
        if cfg.n_states != len(states) or cfg.n_inputs != len(inputs):
            raise fail(f"config {spec.source}",
                       f"has {cfg.n_states} states and {cfg.n_inputs} inputs, but {example}'s plant has "
                       f"{len(states)} states ({', '.join(states)}) and {len(inputs)} inputs")


# -- results --------------------------------------------------------------------------------------


def _ratio(ours: np.ndarray, paper: tuple[float | None, ...] | None) -> np.ndarray:
    out = np.full(ours.shape, np.nan)
    if paper is not None:
        for j, p in enumerate(paper):
            if p is not None:
                out[j] = ours[j] / p
    return out


@dataclass(frozen=True, eq=False)
class EstimatorResult:
    """One estimator on one scenario, aligned on the targets x(1)..x(T-1).

    ``estimate`` is (T-1, n) float64: row k estimates x(k+1) from data up to
    sample k. ``kind`` is "identifier", "observer" or "baseline".
    """

    key: str
    label: str
    kind: str
    source: str
    estimate: np.ndarray
    rmse: np.ndarray
    ad: np.ndarray
    paper_rmse: tuple[float | None, ...] | None
    paper_ad: tuple[float | None, ...] | None
    rmse_after_warmup: np.ndarray
    rmse_valid_targets: np.ndarray
    seconds: float

    @property
    def rmse_ratio(self) -> np.ndarray:
        """ours / paper per state (NaN where the paper has no figure)."""
        return _ratio(self.rmse, self.paper_rmse)

    @property
    def ad_ratio(self) -> np.ndarray:
        return _ratio(self.ad, self.paper_ad)

    def to_dict(self, state_names: Sequence[str], scale: np.ndarray) -> dict[str, Any]:
        states = {}
        for j, name in enumerate(state_names):
            states[name] = {
                "rmse": float(self.rmse[j]),
                "paper_rmse": None if self.paper_rmse is None else self.paper_rmse[j],
                "rmse_ratio": _num(self.rmse_ratio[j]),
                "ad": float(self.ad[j]),
                "paper_ad": None if self.paper_ad is None else self.paper_ad[j],
                "ad_ratio": _num(self.ad_ratio[j]),
                "rmse_over_std": _num(self.rmse[j] / scale[j]) if scale[j] > 0 else None,
                "rmse_after_warmup": _num(self.rmse_after_warmup[j]),
                "rmse_valid_targets": _num(self.rmse_valid_targets[j]),
            }
        return {"key": self.key, "label": self.label, "kind": self.kind, "source": self.source,
                "seconds": self.seconds, "states": states}


@dataclass(frozen=True)
class HorizonPoint:
    """Metrics of one estimator at one horizon (the Example 1 horizon study)."""

    horizon: float
    key: str
    label: str
    rmse: tuple[float, ...]
    ad: tuple[float, ...]

    def to_dict(self) -> dict[str, Any]:
        return {"horizon": self.horizon, "key": self.key, "label": self.label, "rmse": list(self.rmse),
                "ad": list(self.ad)}


@dataclass(frozen=True, eq=False)
class ScenarioResult:
    """Everything one scenario produced: the trajectory, the aligned estimates
    and metrics of every estimator, the horizon study and the timings."""

    scenario: Scenario
    horizon: float
    dtype: str
    seed: int
    noise: float
    mask_holds: bool
    trajectory: Trajectory
    truth: np.ndarray
    estimators: tuple[EstimatorResult, ...]
    horizon_study: tuple[HorizonPoint, ...]
    timings: dict[str, float] = field(default_factory=dict)

    @property
    def state_names(self) -> tuple[str, ...]:
        return self.trajectory.state_names

    @property
    def signal_std(self) -> np.ndarray:
        """Standard deviation of each true state over the compared samples."""
        return self.truth.std(axis=0)

    def estimator(self, key: str) -> EstimatorResult:
        for e in self.estimators:
            if e.key == key:
                return e
        raise fail("key", f"no estimator {key!r}; have {[e.key for e in self.estimators]}")

    def targets(self) -> list[dict[str, Any]]:
        """The paper-example targets (:data:`RMSE_TARGET`, :data:`AD_TARGET`) for every
        identifier: per state, whether met."""
        ex = self.scenario.example
        out = []
        for e in self.estimators:
            if e.kind != "identifier":
                continue
            for j, name in enumerate(self.state_names):
                for metric, ratio, limit in (("rmse", e.rmse_ratio[j], RMSE_TARGET.get(ex)),
                                             ("ad", e.ad_ratio[j], AD_TARGET.get(ex))):
                    if limit is None or not math.isfinite(ratio):
                        continue
                    out.append({"estimator": e.key, "state": name, "metric": metric, "ratio": float(ratio),
                                "limit": limit, "met": bool(ratio <= limit)})
        return out

    def to_dict(self) -> dict[str, Any]:
        traj = self.trajectory
        scale = self.signal_std
        return {
            "scenario": self.scenario.key,
            "title": self.scenario.title,
            "example": self.scenario.example,
            "dt": self.scenario.dt,
            "horizon": self.horizon,
            "samples": traj.n_samples,
            "compared_targets": int(self.truth.shape[0]),
            "dtype": self.dtype,
            "seed": self.seed,
            "noise": self.noise,
            "mask_holds": self.mask_holds,
            "alignment": "identifier row k predicts x(k+1); all estimators are scored on x(1)..x(T-1)",
            "diagnostic_warmup": DIAGNOSTIC_WARMUP,
            "paper": self.scenario.paper.to_dict(),
            "states": list(self.state_names),
            "signal": {name: {"std": float(scale[j]), "min": float(self.truth[:, j].min()),
                              "max": float(self.truth[:, j].max())}
                       for j, name in enumerate(self.state_names)},
            "holds": traj.metadata.get("holds", []),
            "estimators": [e.to_dict(self.state_names, scale) for e in self.estimators],
            "targets": self.targets(),
            "horizon_study": [p.to_dict() for p in self.horizon_study],
            "timings": dict(self.timings),
            "plant": _jsonable(traj.metadata),
        }


def _num(v: float) -> float | None:
    v = float(v)
    return v if math.isfinite(v) else None


def _jsonable(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist())
    if isinstance(obj, (np.floating, float)):
        return _num(float(obj))
    if isinstance(obj, (np.integer,)):
        return int(obj)
    return obj


# -- running ----------------------------------------------------------------------------------------


def _metrics(truth: np.ndarray, est: np.ndarray, valid_targets: np.ndarray) -> tuple[np.ndarray, ...]:
    rmse = metrics.rmse(truth, est)
    ad = metrics.absolute_deviation(truth, est)
    warm = min(DIAGNOSTIC_WARMUP, truth.shape[0] - 1)
    after = metrics.rmse(truth, est, warm)
    e = truth - est
    on = np.where(valid_targets, e * e, 0.0)
    count = valid_targets.sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        valid_rmse = np.where(count > 0, np.sqrt(on.sum(axis=0) / np.maximum(count, 1)), np.nan)
    return rmse, ad, after, valid_rmse


def _run_identifier(spec: IdentifierSpec, traj: Trajectory, dtype: str, mask_holds: bool) -> np.ndarray:
    """Identifier rows (T, n) as float64: row k is x̂(k+1)."""
    cfg = spec.config if spec.config.dtype == dtype else spec.config.replace(dtype=dtype)
    real = np.dtype(dtype)
    # The requested precision is explicit (--dtype), so the conversion is too.
    X = np.ascontiguousarray(traj.X_meas.astype(real))
    U = np.ascontiguousarray(traj.U.astype(real))
    valid = traj.valid if mask_holds else None
    if valid is None and not np.all(np.isfinite(X)):
        raise fail("mask_holds", "False needs a measurement at every sample, but some are missing (NaN)")
    try:
        return Identifier(cfg).run(X, U, valid).astype(np.float64)
    except ValueError as exc:  # IdentifierError included: say which config failed
        raise ValueError(f"{spec.label} ({spec.source}): {exc}") from None


def _estimators(sc: Scenario, traj: Trajectory, specs: Sequence[IdentifierSpec], *, dtype: str,
                mask_holds: bool, with_baselines: bool,
                progress: Progress | None) -> tuple[np.ndarray, tuple[EstimatorResult, ...]]:
    paper = sc.paper
    truth = traj.X[1:]
    valid_targets = traj.valid[1:]
    out: list[EstimatorResult] = []
    check_identifiers(sc.example, specs)
    for spec in specs:
        if progress:
            progress(f"{spec.label}: {traj.n_samples} samples through the C core ({dtype})")
        t0 = time.perf_counter()
        rows = _run_identifier(spec, traj, dtype, mask_holds)
        seconds = time.perf_counter() - t0
        est = rows[:-1]
        if not np.all(np.isfinite(est)):
            raise fail(f"config {spec.source}", "the identifier's predictions are not finite")
        r, a, w, v = _metrics(truth, est, valid_targets)
        out.append(EstimatorResult(spec.key, spec.label, "identifier", spec.source, est, r, a,
                                   paper.identifier_rmse, paper.identifier_ad, w, v, seconds))
    if sc.example == "example1":
        if progress:
            progress("HONN observer (eq. 16-19)")
        t0 = time.perf_counter()
        params = HonnObserverParams(dt=traj.dt)
        measured = bool(np.any(traj.X_meas != traj.X))
        try:
            obs_rows = observe_oscillator(traj, params, measured=measured)
        except FloatingPointError as exc:
            raise ValueError(f"HONN observer: {exc}") from None
        seconds = time.perf_counter() - t0
        obs = obs_rows[1:]  # observer row k is x̂(k) from data up to k-1 (see common_targets)
        r, a, w, v = _metrics(truth, obs, valid_targets)
        out.append(EstimatorResult("observer", "HONN observer", "observer",
                                   "pyrhonn.baselines.honn_observer (paper values, see its docstring)",
                                   obs, r, a, paper.observer_rmse, paper.observer_ad, w, v, seconds))
    if with_baselines:
        est = traj.X_meas[:-1]
        if np.all(np.isfinite(est)):
            r, a, w, v = _metrics(truth, est, valid_targets)
            out.append(EstimatorResult("persistence", "persistence x(k)", "baseline",
                                       "x̂(k+1) = last measurement (scale reference)", est, r, a, None, None,
                                       w, v, 0.0))
    return truth, tuple(out)


def horizon_study(scenario: str | Scenario, specs: Sequence[IdentifierSpec], *,
                  horizons: Sequence[float] = HORIZONS, dtype: str = "float64", noise: float = 0.0, seed: int = 0,
                  mask_holds: bool = True, progress: Progress | None = None) -> tuple[HorizonPoint, ...]:
    """Every identifier (and, for Example 1, the observer) at each horizon."""
    sc = _scenario(scenario)
    points: list[HorizonPoint] = []
    for h in horizons:
        h = check_real("horizons[]", h, positive=True)
        if progress:
            progress(f"horizon study: {h:g} s")
        traj = simulate(sc, horizon=h, noise=noise, seed=seed)
        _, ests = _estimators(sc, traj, specs, dtype=dtype, mask_holds=mask_holds, with_baselines=False,
                              progress=None)
        for e in ests:
            points.append(HorizonPoint(h, e.key, e.label, tuple(float(v) for v in e.rmse),
                                       tuple(float(v) for v in e.ad)))
    return tuple(points)


def run_scenario(
    scenario: str | Scenario,
    *,
    dtype: str = "float64",
    seed: int = 0,
    noise: float = 0.0,
    horizon: float | None = None,
    identifiers: Sequence[IdentifierSpec] | None = None,
    mask_holds: bool = True,
    horizons: Sequence[float] | None = None,
    progress: Progress | None = None,
) -> ScenarioResult:
    """Run one scenario: plant -> identifier(s) (+ observer) -> metrics.

    identifiers:
        The identifiers to run; None for the shipped configs
        (:func:`shipped_identifiers`).
    horizons:
        Horizons of the horizon study; None for :data:`HORIZONS` on
        Example 1 and no study for Examples 2 and 3; ``()`` for none.
    progress:
        Called with a short message at each phase (the CLI prints them).
    """
    sc = _scenario(scenario)
    if dtype not in DTYPES:
        raise fail("dtype", f"expected one of {', '.join(DTYPES)}, got {dtype!r}")
    seed = check_int("seed", seed, 0)
    noise = check_real("noise", noise, nonnegative=True)
    if not isinstance(mask_holds, bool):
        raise fail("mask_holds", f"expected a bool, got {type(mask_holds).__name__}")
    specs = tuple(shipped_identifiers(sc.example) if identifiers is None else identifiers)
    if not specs:
        raise fail("identifiers", "expected at least one identifier")
    check_identifiers(sc.example, specs)
    if len({s.key for s in specs}) != len(specs):
        raise fail("identifiers", "keys must be unique")
    if horizons is None:
        horizons = HORIZONS if sc.example == "example1" else ()
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    if progress:
        progress("simulating the plant")
    traj = simulate(sc, horizon=horizon, noise=noise, seed=seed)
    timings["plant"] = time.perf_counter() - t0
    t1 = time.perf_counter()
    truth, ests = _estimators(sc, traj, specs, dtype=dtype, mask_holds=mask_holds, with_baselines=True,
                              progress=progress)
    timings["estimators"] = time.perf_counter() - t1
    t2 = time.perf_counter()
    study = horizon_study(sc, specs, horizons=horizons, dtype=dtype, noise=noise, seed=seed,
                          mask_holds=mask_holds, progress=progress) if horizons else ()
    timings["horizon_study"] = time.perf_counter() - t2
    timings["total"] = time.perf_counter() - t0
    h = sc.horizon if horizon is None else float(horizon)
    return ScenarioResult(sc, h, dtype, seed, noise, mask_holds, traj, truth, ests, study, timings)


def run(example: str, *, dt: float | None = None, **kwargs: Any) -> tuple[ScenarioResult, ...]:
    """Run every scenario of ``example`` ("example1".."example3", "all");
    ``dt`` picks one period of Example 1. Keyword arguments go to
    :func:`run_scenario`."""
    return tuple(run_scenario(key, **kwargs) for key in scenario_keys(example, dt))


# -- text ---------------------------------------------------------------------------------------------


def _fmt(v: float | None, width: int = 10) -> str:
    if v is None or not math.isfinite(v):
        return f"{'-':>{width}}"
    return f"{v:>{width}.5g}"


def _fmt_ratio(v: float, limit: float | None) -> str:
    if not math.isfinite(v):
        return f"{'-':>7}"
    mark = "!" if limit is not None and v > limit else " "
    return f"{v:>6.3g}{mark}"


def format_table(result: ScenarioResult) -> str:
    """The terminal table: for every state and estimator, the paper's figure,
    ours and ours/paper, for RMSE and absolute deviation. A ratio marked
    ``!`` misses the paper-example target for an identifier."""
    sc = result.scenario
    paper = sc.paper
    ex = sc.example
    head = (f"{sc.title}, {result.horizon:g} s ({result.trajectory.n_samples} samples), {result.dtype}"
            + (f", noise {result.noise:g} std (seed {result.seed})" if result.noise else "")
            + ("" if result.mask_holds else ", holds NOT masked"))
    lines = [head,
             f"paper: RMSE {paper.rmse_table}, absolute deviation {paper.ad_table}; ratio = ours / paper",
             f"{'state':<9} {'estimator':<22} {'RMSE paper':>10} {'ours':>10} {'ratio':>7}   "
             f"{'AD paper':>10} {'ours':>10} {'ratio':>7}"]
    for j, name in enumerate(result.state_names):
        for i, e in enumerate(result.estimators):
            ident = e.kind == "identifier"
            pr = None if e.paper_rmse is None else e.paper_rmse[j]
            pa = None if e.paper_ad is None else e.paper_ad[j]
            lines.append(
                f"{name if i == 0 else '':<9} {e.label:<22} {_fmt(pr)} {_fmt(float(e.rmse[j]))} "
                f"{_fmt_ratio(float(e.rmse_ratio[j]), RMSE_TARGET.get(ex) if ident else None)}   "
                f"{_fmt(pa)} {_fmt(float(e.ad[j]))} "
                f"{_fmt_ratio(float(e.ad_ratio[j]), AD_TARGET.get(ex) if ident else None)}")
    rt, at = RMSE_TARGET.get(ex), AD_TARGET.get(ex)
    target = f"identifier RMSE <= {rt:g} x paper" + (f" and AD <= {at:g} x paper" if at else "")
    missed = [t for t in result.targets() if not t["met"]]
    lines.append(f"target: {target}; " + (
        "met on every state with a paper figure" if not missed else
        "missed: " + ", ".join(f"{t['estimator']} {t['state']} {t['metric']} {t['ratio']:.3g}" for t in missed)))
    return "\n".join(lines)


def format_horizon_study(result: ScenarioResult) -> str:
    """The horizon study as a text table ("" when there is none)."""
    if not result.horizon_study:
        return ""
    names = result.state_names
    lines = [f"horizon study ({result.scenario.key}): the paper does not state its horizon; every figure at "
             + ", ".join(f"{h:g}" for h in sorted({p.horizon for p in result.horizon_study})) + " s",
             f"{'horizon':>8} {'estimator':<22} " + " ".join(f"{'RMSE ' + n:>10}" for n in names) + "   "
             + " ".join(f"{'AD ' + n:>10}" for n in names)]
    for p in result.horizon_study:
        lines.append(f"{p.horizon:>7g}s {p.label:<22} " + " ".join(_fmt(v) for v in p.rmse) + "   "
                     + " ".join(_fmt(v) for v in p.ad))
    return "\n".join(lines)


# -- files --------------------------------------------------------------------------------------------


HOLD_COLOR = "0.85"


def _shade_holds(ax: Any, traj: Trajectory, j: int) -> None:
    invalid = ~traj.valid[:, j]
    if not invalid.any():
        return
    t = traj.t
    edges = np.flatnonzero(np.diff(np.concatenate(([0], invalid.astype(np.int8), [0]))))
    for start, stop in zip(edges[::2], edges[1::2]):
        ax.axvspan(t[start], t[min(stop, t.shape[0] - 1)], color=HOLD_COLOR, lw=0)


def _axis_label(result: ScenarioResult, j: int, prefix: str = "") -> str:
    """The y-axis label of state j with its unit, e.g. ``v (m/s)``."""
    return f"{prefix}{result.state_names[j]} ({STATE_UNITS[result.scenario.example][j]})"


def _legend(result: ScenarioResult, ax: Any, ncol: int) -> None:
    """The legend of the top axes: its lines, and the hold shading when any state has one."""
    from matplotlib.patches import Patch

    handles, labels = ax.get_legend_handles_labels()
    if not result.trajectory.valid.all():
        handles.append(Patch(facecolor=HOLD_COLOR, edgecolor="none"))
        labels.append(HOLD_LABEL)
    ax.legend(handles, labels, loc="upper left", fontsize=8, ncol=ncol)


def _figure(n: int) -> Any:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(9.0, 1.9 * n + 0.8))
    FigureCanvasAgg(fig)
    axes = fig.subplots(n, 1, sharex=True, squeeze=False)[:, 0]
    return fig, axes


def _plot_states(result: ScenarioResult, e: EstimatorResult, path: Path) -> None:
    traj = result.trajectory
    t = traj.t[1:]
    n = traj.n_states
    fig, axes = _figure(n)
    verb = "observed" if e.kind == "observer" else "identified"
    for j, ax in enumerate(axes):
        _shade_holds(ax, traj, j)
        ax.plot(t, result.truth[:, j], color="black", lw=1.0, label="real")
        ax.plot(t, e.estimate[:, j], color="0.45", lw=1.2, ls=":", label=verb)
        ax.set_ylabel(_axis_label(result, j))
        ax.set_title(f"RMSE {e.rmse[j]:.4g}   AD {e.ad[j]:.4g}", loc="right", fontsize=8, pad=2)
        ax.grid(True, lw=0.3)
    _legend(result, axes[0], ncol=3)
    axes[-1].set_xlabel("time (s)")
    fig.suptitle(f"{result.scenario.title}: real (black solid) vs {verb} (grey dotted), {e.label}", fontsize=10)
    fig.tight_layout()
    atomic.save_figure(fig, path, dpi=110)


def _plot_errors(result: ScenarioResult, path: Path) -> None:
    traj = result.trajectory
    t = traj.t[1:]
    fig, axes = _figure(traj.n_states)
    shown = [e for e in result.estimators if e.kind != "baseline"]
    for j, ax in enumerate(axes):
        _shade_holds(ax, traj, j)
        for e in shown:
            ax.plot(t, result.truth[:, j] - e.estimate[:, j], lw=0.8, label=e.label)
        ax.set_ylabel(_axis_label(result, j, "e "))
        ax.grid(True, lw=0.3)
    _legend(result, axes[0], ncol=len(shown) + 1)
    axes[-1].set_xlabel("time (s)")
    fig.suptitle(f"{result.scenario.title}: error x(k+1) - estimate (hold windows shaded)", fontsize=10)
    fig.tight_layout()
    atomic.save_figure(fig, path, dpi=110)


def check_output_dir(out: str | Path) -> Path:
    """Create ``out`` if needed and prove it is writable (OSError naming it
    otherwise; ValueError for an empty name, which would mean the current folder)."""
    if not str(out).strip():
        raise ValueError("--out: empty; give a folder")
    path = Path(out)
    try:
        path.mkdir(parents=True, exist_ok=True)
        probe = path / ".pyrhonn-write-test"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        raise OSError(f"--out {str(out)!r}: cannot write there ({exc.strerror or exc})") from None
    return path


def write_outputs(result: ScenarioResult, out: str | Path) -> tuple[Path, ...]:
    """Write ``<key>.json``, ``<key>-<estimator>.png`` per identifier and
    observer, and ``<key>-errors.png`` into ``out``, each replaced whole
    (:mod:`pyrhonn.atomic`); returns the paths."""
    folder = check_output_dir(out)
    key = result.scenario.key
    written: list[Path] = []
    data = result.to_dict()
    path = folder / f"{key}.json"
    atomic.write_text(path, json.dumps(data, indent=2, allow_nan=False) + "\n")
    written.append(path)
    for e in result.estimators:
        if e.kind == "baseline":
            continue
        p = folder / f"{key}-{e.key}.png"
        _plot_states(result, e, p)
        written.append(p)
    p = folder / f"{key}-errors.png"
    _plot_errors(result, p)
    written.append(p)
    return tuple(written)
