"""Public benchmarks: ``pyrhonn select`` with its default options against
SysIdentPy's FROLS, each model built on an estimation record and scored on a
separate validation record.

Data sets (estimation and validation are different experiments, never parts
of one record):

- **Cascaded tanks**, measured data (``bench/data/cascaded_tanks/``, with its
  SOURCE.md): M. Schoukens, P. Mattson, T. Wigren and J.-P. Noel, "Cascaded
  tanks benchmark combining soft and hard nonlinearities", Workshop on
  Nonlinear System Identification Benchmarks, 2016; published with the
  nonlinear system identification benchmark collection and on
  4TU.ResearchData. Pump voltage u -> lower-tank level y, Ts = 4 s, 1,024
  samples per record. The published free-run RMS errors on the validation
  record are printed beside the rows. The collection's data loader leaves the
  first 5 validation samples to initialise a model; so does this bench.
- **Bouc-Wen hysteretic oscillator**, simulated: J.-P. Noel and M. Schoukens,
  "Hysteretic benchmark with a dynamic nonlinearity", Workshop on Nonlinear
  System Identification Benchmarks, 2016 (data: 4TU.ResearchData,
  doi:10.4121/12967592): a mass on a spring and a damper with a Bouc-Wen
  hysteretic force, like a hysteretic damper,

      m y'' + c y' + k y + z = u(t),
      z' = alpha y' - beta (gamma |y'| |z|^(nu-1) z + delta y' |z|^nu),

  m = 2 kg, c = 10 N s/m, k = 5e4 N/m, alpha = 5e4 N/m, beta = 1e3 1/m,
  gamma = 0.8, delta = -1.1, nu = 1. The force u is a random-phase multisine
  with a flat amplitude spectrum on every frequency line from 5 to 150 Hz,
  50 N RMS, sampled at 750 Hz, as in the benchmark. Chosen here: one period
  of 4,096 samples per record (1,024 with --quick), taken once the response
  is periodic (after at least 3 s of simulated transient); the equations
  integrated by RK4 at 15 kHz (20 steps per sample; the benchmark uses a
  Newmark scheme at the same rate) with the multisine evaluated between the
  samples; white Gaussian noise of standard deviation 8e-6 m added to y
  (about 38 dB below the response). Estimation and validation are different
  phase realisations (seeds 1 and 2) with their own noise (seeds 11 and 12).
  Units are the benchmark's (m, N): y is of the order of 1e-3.
- **Narendra-Li**, simulated: K. S. Narendra and S.-M. Li, "Neural networks
  in control systems", in P. Smolensky, M. C. Mozer and D. E. Rumelhart
  (eds.), Mathematical Perspectives on Neural Networks, Lawrence Erlbaum,
  1996:

      x1(k+1) = (x1(k) / (1 + x1(k)^2) + 1) sin x2(k)
      x2(k+1) = x2(k) cos x2(k) + x1(k) exp(-(x1(k)^2 + x2(k)^2) / 8)
                + u(k)^3 / (1 + u(k)^2 + 0.5 cos(x1(k) + x2(k)))
      y(k)    = x1(k) / (1 + 0.5 sin x2(k)) + x2(k) / (1 + 0.5 sin x1(k)) + e(k)

  with u uniform in [-2.5, 2.5] and e white Gaussian of standard deviation
  0.1, as the benchmark is commonly used. Chosen here: 2,000 samples per
  record (500 with --quick) after 100 dropped from the zero initial state;
  estimation and validation from different seeds (21 and 22) for both the
  input and the noise. Ts = 1 (a discrete-time system).

Methods, per data set, in the same run:

- **pyrhonn**: the estimation record alone is written as a CSV (columns t, y,
  u) and ``pyrhonn select estimation.csv --states y --inputs u --out
  config.toml --json select.json`` runs through the installed command line,
  with no other option: whatever select does by default is what is measured.
  The validation record reaches the disk only after select has returned. The
  written config is then read back (:mod:`pyrhonn.configfile`), the
  validation CSV read for it as ``pyrhonn identify`` reads data
  (:mod:`pyrhonn.datafile`), and an :class:`~pyrhonn.Identifier` with
  learning off (the weights select wrote, w0, frozen) is run over
  it by :func:`pyrhonn.simulation.simulate` with ``free_run_from`` = K, the
  config's deepest delay + 1: the first sample whose taps all read measured
  samples. The time of select is the wall time of the command (interpreter
  start included) and the time select reports for its own work. The same
  config also runs learning online (as ``pyrhonn identify`` runs it), with
  ``wait_for_history`` as select writes it and off. The same command with
  ``--tie`` at each width of TIE_SWEEP but the default shows how much the
  tie between candidate spaces moves the result (``tie_sweep``).
- **SysIdentPy FROLS** (polynomial NARX of degree 2, least squares; the
  model length is SysIdentPy's own choice, where its AIC over up to 15 terms
  first rises) on a grid of output lags ylag and input lags xlag (1..3
  each; 1..2 with --quick); its free run is ``predict(steps_ahead=None)``,
  its one-step prediction ``predict(steps_ahead=1)``.
  (a) "AIC on est.": the grid point with the smallest AIC of its chosen model
  on the estimation record: the honest baseline, which never sees the
  validation record. (b) "best on val.": the grid point with the smallest
  free-run RMSE on the validation record, an optimistic reference (the
  validation record chose it).

Scoring: one-step and free-run RMSE and RRSE (root relative squared error,
sqrt(sum e^2 / sum (y - mean y)^2)) of y on the validation record, every
method on the same samples k >= S, S = max(K, the grid's deepest lag, the
benchmark's initialisation window). Each free run starts from the measured
samples before its own first prediction (pyrhonn: the K first; SysIdentPy:
its max_lag first) and from then on reads only the measured input. A free
run that is not finite, or that strays further than 100 times the
validation record's range from the middle of that range, is reported as
diverged (with the sample where it left), not as a number.

    python bench/bench_real_data.py                 # the full run (a few minutes)
    python bench/bench_real_data.py --quick         # smoke run: shorter simulated records, smaller grid
    python bench/bench_real_data.py --json out.json --keep work/
    python bench/bench_real_data.py --results       # also bench/results/real_data.json, which the docs quote
"""
from __future__ import annotations

import argparse
import csv
import json
import math
import os
import platform
import sys
import tempfile
import time
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

import pyrhonn
from pyrhonn import Identifier, atomic
from pyrhonn.configfile import load_config
from pyrhonn.datafile import read_data
from pyrhonn.search import TIE
from pyrhonn.simulation import simulate



def _sysidentpy() -> Any:
    """The SysIdentPy package, or None (reported by main(): the baseline is part of this benchmark).
    Imported when the baseline runs, not with this module: importing SysIdentPy sets matplotlib's global
    rcParams (its plotting module), which would change every plot drawn later in the same process."""
    try:
        import sysidentpy  # type: ignore[import-untyped]
        import sysidentpy.basis_function  # type: ignore[import-untyped]
        import sysidentpy.model_structure_selection  # type: ignore[import-untyped]
        import sysidentpy.parameter_estimation  # type: ignore[import-untyped]
    except ImportError:
        return None
    return sysidentpy

DATA = Path(__file__).resolve().parent / "data"
STATE, INPUT = "y", "u"
#: The select command, exactly as a user types it (after ``pyrhonn``): files relative to its folder.
SELECT_ARGS = ("select", "estimation.csv", "--states", STATE, "--inputs", INPUT, "--out", "config.toml",
               "--json", "select.json")
#: A free run further than this many record ranges from the middle of the range has diverged.
DIVERGED_RANGES = 100.0
#: select's tie between candidate spaces (``--tie``) measured at these widths besides its default (TIE)
TIE_SWEEP = (0.01, 0.02, TIE, 0.10)
DEGREE = 2  # SysIdentPy's polynomial degree
N_INFO = 15  # SysIdentPy's default n_info_values: model lengths its AIC compares


@dataclass
class Record:
    """One experiment: input u and measured output y, (T,) each."""

    u: np.ndarray
    y: np.ndarray


@dataclass
class Dataset:
    key: str
    title: str
    est: Record
    val: Record
    sampling_period: float
    source: dict[str, Any]
    init_window: int = 0  # validation samples the benchmark leaves to initialise a model
    published: list[dict[str, Any]] = field(default_factory=list)


# -- data sets ------------------------------------------------------------------------------------

def cascaded_tanks() -> Dataset:
    """The measured cascaded tanks records, read from the benchmark's CSV as it is."""
    path = DATA / "cascaded_tanks" / "dataBenchmark.csv"
    with open(path, newline="", encoding="utf-8") as fh:
        rows = [r for r in csv.reader(fh) if r]
    head = [h.strip() for h in rows[0]]
    body = rows[1:]

    def column(name: str) -> np.ndarray:
        c = head.index(name)
        return np.array([float(r[c]) for r in body])

    ts = float(body[0][head.index("Ts")])
    return Dataset(
        "cascaded_tanks", "cascaded tanks", Record(column("uEst"), column("yEst")),
        Record(column("uVal"), column("yVal")), ts,
        {"kind": "measured",
         "citation": "M. Schoukens, P. Mattson, T. Wigren and J.-P. Noel, \"Cascaded tanks benchmark combining "
                     "soft and hard nonlinearities\", Workshop on Nonlinear System Identification Benchmarks, 2016",
         "published_in": "nonlinear system identification benchmark collection; 4TU.ResearchData",
         "file": "bench/data/cascaded_tanks/dataBenchmark.csv (see SOURCE.md beside it)",
         "signals": "u: pump voltage (V); y: lower-tank level, sensor voltage (V); the upper tank is not measured",
         "scoring": "free-run RMS error of y on the validation record from the input only, the first 5 "
                    "validation samples left to initialise the model (the collection's data loader)"},
        init_window=5,
        published=[{"model": "best linear approximation", "free_run_rmse": 0.76},
                   {"model": "third-degree Volterra", "free_run_rmse": 0.54},
                   {"model": "polynomial nonlinear state space", "free_run_rmse": 0.45},
                   {"model": "NLSS2", "free_run_rmse": 0.34}])


BW_FS = 750.0  # Hz
BW_STEPS = 20  # integration steps per sample: 15 kHz
BW_NOISE = 8e-6  # m
BW = {"m": 2.0, "c": 10.0, "k": 5e4, "alpha": 5e4, "beta": 1e3, "gamma": 0.8, "delta": -1.1, "nu": 1.0}


def multisine(n: int, rng: np.random.Generator, oversample: int, f_lo: float = 5.0, f_hi: float = 150.0,
              rms: float = 50.0) -> np.ndarray:
    """One period of a random-phase multisine of n samples at BW_FS, flat amplitude on every line from
    f_lo to f_hi, scaled to ``rms``, evaluated ``oversample`` times per sample (exact: the signal is
    band-limited and periodic, so the inverse FFT of the longer period is the multisine itself)."""
    lines = np.arange(math.ceil(f_lo * n / BW_FS), math.floor(f_hi * n / BW_FS) + 1)
    spectrum = np.zeros(n * oversample // 2 + 1, dtype=complex)
    spectrum[lines] = np.exp(1j * rng.uniform(0.0, 2.0 * np.pi, lines.size))
    u = np.fft.irfft(spectrum, n=n * oversample)
    return u * (rms / np.sqrt(np.mean(u * u)))


def bouc_wen_record(n: int, seed: int, noise_seed: int) -> Record:
    """One steady-state period of the Bouc-Wen benchmark driven by a multisine of phase seed ``seed``."""
    p = BW
    assert p["nu"] == 1.0  # |z|^(nu-1) z = z and |z|^nu = |z| below
    m, c, k, alpha, beta, gamma, delta = (p[key] for key in ("m", "c", "k", "alpha", "beta", "gamma", "delta"))
    fine = multisine(n, np.random.default_rng(seed), 2 * BW_STEPS).tolist()  # u at every half step
    span = len(fine)
    h = 1.0 / (BW_FS * BW_STEPS)
    periods = 1 + math.ceil(3.0 * BW_FS / n)  # >= 3 s of transient, then the recorded period

    def f(v: float, y: float, z: float, u: float) -> tuple[float, float, float]:
        return v, (u - c * v - k * y - z) / m, alpha * v - beta * (gamma * abs(v) * z + delta * v * abs(z))

    y = v = z = 0.0
    out = np.empty(n)
    i = 0
    for sample in range(periods * n):
        if sample >= (periods - 1) * n:
            out[sample - (periods - 1) * n] = y
        for _ in range(BW_STEPS):
            u0, um, u1 = fine[i % span], fine[(i + 1) % span], fine[(i + 2) % span]
            i += 2
            a1, b1, c1 = f(v, y, z, u0)
            a2, b2, c2 = f(v + 0.5 * h * b1, y + 0.5 * h * a1, z + 0.5 * h * c1, um)
            a3, b3, c3 = f(v + 0.5 * h * b2, y + 0.5 * h * a2, z + 0.5 * h * c2, um)
            a4, b4, c4 = f(v + h * b3, y + h * a3, z + h * c3, u1)
            y += h / 6.0 * (a1 + 2.0 * a2 + 2.0 * a3 + a4)
            v += h / 6.0 * (b1 + 2.0 * b2 + 2.0 * b3 + b4)
            z += h / 6.0 * (c1 + 2.0 * c2 + 2.0 * c3 + c4)
    u = np.array(fine[:: 2 * BW_STEPS])
    noise = np.random.default_rng(noise_seed).normal(0.0, BW_NOISE, n)
    return Record(u, out + noise)


def bouc_wen(quick: bool) -> Dataset:
    n = 1024 if quick else 4096
    return Dataset(
        "bouc_wen", "Bouc-Wen", bouc_wen_record(n, 1, 11), bouc_wen_record(n, 2, 12), 1.0 / BW_FS,
        {"kind": "simulated",
         "citation": "J.-P. Noel and M. Schoukens, \"Hysteretic benchmark with a dynamic nonlinearity\", Workshop "
                     "on Nonlinear System Identification Benchmarks, 2016 (data: 4TU.ResearchData, "
                     "doi:10.4121/12967592)",
         "equations": "m y'' + c y' + k y + z = u; z' = alpha y' - beta (gamma |y'| |z|^(nu-1) z + delta y' |z|^nu)",
         "parameters": dict(BW),
         "input": "random-phase multisine, flat on every line from 5 to 150 Hz, 50 N RMS, fs = 750 Hz",
         "simulation": f"RK4 at {BW_FS * BW_STEPS:.0f} Hz, multisine evaluated between samples; one steady-state "
                       f"period of {n} samples per record after >= 3 s of transient",
         "noise": f"white Gaussian on y, standard deviation {BW_NOISE} m",
         "seeds": {"estimation_phases": 1, "validation_phases": 2, "estimation_noise": 11, "validation_noise": 12},
         "units": "y in m, u in N (the benchmark's)"})


NL_NOISE = 0.1
NL_BURN = 100


def narendra_li_record(n: int, seed: int) -> Record:
    rng = np.random.default_rng(seed)
    u = rng.uniform(-2.5, 2.5, n + NL_BURN)
    e = rng.normal(0.0, NL_NOISE, n + NL_BURN)
    y = np.empty(n + NL_BURN)
    x1 = x2 = 0.0
    for k in range(n + NL_BURN):
        y[k] = x1 / (1.0 + 0.5 * math.sin(x2)) + x2 / (1.0 + 0.5 * math.sin(x1))
        uk = float(u[k])
        x1, x2 = ((x1 / (1.0 + x1 * x1) + 1.0) * math.sin(x2),
                  x2 * math.cos(x2) + x1 * math.exp(-(x1 * x1 + x2 * x2) / 8.0)
                  + uk ** 3 / (1.0 + uk * uk + 0.5 * math.cos(x1 + x2)))
    return Record(u[NL_BURN:], (y + e)[NL_BURN:])


def narendra_li(quick: bool) -> Dataset:
    n = 500 if quick else 2000
    return Dataset(
        "narendra_li", "Narendra-Li", narendra_li_record(n, 21), narendra_li_record(n, 22), 1.0,
        {"kind": "simulated",
         "citation": "K. S. Narendra and S.-M. Li, \"Neural networks in control systems\", in P. Smolensky, "
                     "M. C. Mozer and D. E. Rumelhart (eds.), Mathematical Perspectives on Neural Networks, "
                     "Lawrence Erlbaum, 1996",
         "equations": "x1(k+1) = (x1/(1+x1^2) + 1) sin x2; x2(k+1) = x2 cos x2 + x1 exp(-(x1^2+x2^2)/8) + "
                      "u^3/(1+u^2+0.5 cos(x1+x2)); y = x1/(1+0.5 sin x2) + x2/(1+0.5 sin x1) + e",
         "input": "uniform in [-2.5, 2.5]",
         "noise": f"white Gaussian on y, standard deviation {NL_NOISE}",
         "records": f"{n} samples each after {NL_BURN} dropped from x = 0",
         "seeds": {"estimation": 21, "validation": 22}})


# -- scoring --------------------------------------------------------------------------------------

def score(y: np.ndarray, yhat: np.ndarray, start: int) -> dict[str, Any]:
    """RMSE and RRSE of yhat against y over samples start..T-1; a prediction that is not finite or
    strays beyond DIVERGED_RANGES ranges of y makes it "diverged" at that sample, without figures."""
    truth, est = y[start:], np.asarray(yhat, dtype=np.float64)[start:]
    centre, span = 0.5 * (y.max() + y.min()), float(y.max() - y.min())
    with np.errstate(invalid="ignore", over="ignore"):
        bad = ~np.isfinite(est) | (np.abs(est - centre) > DIVERGED_RANGES * span)
    if bad.any():
        return {"rmse": None, "rrse": None, "diverged": True, "diverged_at": int(start + np.argmax(bad))}
    e = truth - est
    rmse = float(np.sqrt(np.mean(e * e)))
    spread = float(np.sqrt(np.mean((truth - truth.mean()) ** 2)))
    return {"rmse": rmse, "rrse": rmse / spread if spread > 0 else None, "diverged": False}


# -- pyrhonn --------------------------------------------------------------------------------------

def write_record(path: Path, rec: Record, ts: float) -> None:
    """The CSV that ``pyrhonn select`` and ``pyrhonn identify`` read: t, y, u, floats written exactly."""
    lines = [f"t,{STATE},{INPUT}"]
    lines += [f"{k * ts!r},{float(y)!r},{float(u)!r}" for k, (y, u) in enumerate(zip(rec.y, rec.u))]
    atomic.write_text(path, "\n".join(lines) + "\n")


def run_pyrhonn(ds: Dataset, folder: Path, extra: tuple[str, ...] = (), *, online: bool = True
                ) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """``pyrhonn select`` on the estimation record, then its config over the validation record:
    (figures, predictions of y aligned with the validation record). The predictions: ``one_step`` and
    ``free_run`` with the weights frozen; ``online`` one step ahead learning on (as ``pyrhonn identify``
    runs the config), and ``online_padded`` the same with ``wait_for_history`` off (learning from the
    second sample, the history before the first padded), only with ``online``; none when select failed."""
    folder.mkdir(parents=True, exist_ok=True)
    write_record(folder / "estimation.csv", ds.est, ds.sampling_period)
    out: dict[str, Any] = {"command": ["pyrhonn", *SELECT_ARGS, *extra], "estimation_file": "estimation.csv",
                           "estimation_samples": int(ds.est.y.size)}
    from cli_run import run_cli  # noqa: E402 - beside this script

    run = run_cli(*SELECT_ARGS, *extra, cwd=folder)
    out["select_wall_seconds"] = run.seconds
    if run.returncode != 0:
        out["error"] = run.failure()
        return out, {}
    sel = json.loads((folder / "select.json").read_text(encoding="utf-8"))
    out["select_seconds"] = sel.get("seconds")
    out["select_rows"] = sel.get("rows")
    cf = load_config(folder / "config.toml")
    cfg = cf.config
    out["terms"] = {name: list(terms) for name, terms in zip(cf.state_names, cf.term_strings)}
    out["n_terms"] = sum(len(t) for t in cf.term_strings)
    out["max_delay"] = cfg.max_delay
    # The validation record reaches the disk only now, after select has returned.
    write_record(folder / "validation.csv", ds.val, ds.sampling_period)
    data = read_data(folder / "validation.csv", cf)
    X, U = data.in_dtype(cfg.dtype, cf.state_names, cf.input_names, "validation.csv")
    K = min(cfg.max_delay + 1, data.n_samples - 1)
    ident = Identifier(cfg)
    ident.learning = False
    sim = simulate(ident, X, U if cfg.n_inputs else None, data.valid, free_run_from=K)
    assert sim.free_run is not None
    j = cf.state_names.index(STATE)
    out["free_run_from"] = K
    out["free_run_diverged_at"] = sim.free_run_diverged
    predictions = {"one_step": sim.one_step[:, j], "free_run": sim.free_run[:, j]}
    out["wait_for_history"] = [nr.wait_for_history for nr in cfg.neurons]
    if online:
        padded = replace(cfg, neurons=tuple(replace(nr, wait_for_history=False) for nr in cfg.neurons))
        for key, learning in (("online", cfg), ("online_padded", padded)):
            predictions[key] = simulate(Identifier(learning), X, U if cfg.n_inputs else None,
                                        data.valid).one_step[:, j]
    return out, {key: v.astype(np.float64) for key, v in predictions.items()}


# -- SysIdentPy -----------------------------------------------------------------------------------

def frols(ds: Dataset, ylag: int, xlag: int) -> tuple[dict[str, Any], np.ndarray, np.ndarray]:
    """FROLS fitted on the estimation record; (figures, one-step, free run) on the validation record."""
    candidates = math.comb(ylag + xlag + DEGREE, DEGREE)  # products of up to DEGREE lagged signals, with 1
    sid = _sysidentpy()
    model = sid.model_structure_selection.FROLS(
        order_selection=True, n_info_values=min(N_INFO, candidates), ylag=ylag, xlag=xlag, info_criteria="aic",
        estimator=sid.parameter_estimation.LeastSquares(), basis_function=sid.basis_function.Polynomial(degree=DEGREE))
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model.fit(X=ds.est.u[:, None], y=ds.est.y[:, None])
    seconds = time.perf_counter() - t0
    X, y = ds.val.u[:, None], ds.val.y[:, None]
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        one = model.predict(X=X, y=y, steps_ahead=1)[:, 0]
        free = model.predict(X=X, y=y, steps_ahead=None)[:, 0]
    assert one.shape == free.shape == ds.val.y.shape, (one.shape, free.shape)
    info = {"ylag": ylag, "xlag": xlag, "max_lag": int(model.max_lag), "n_terms": int(len(model.final_model)),
            "aic": float(model.info_values[model.n_terms - 1]), "fit_seconds": seconds}
    return info, one, free


# -- the run --------------------------------------------------------------------------------------

def run_dataset(ds: Dataset, folder: Path, lags: tuple[int, ...]) -> dict[str, Any]:
    py, predicted = run_pyrhonn(ds, folder)
    grid = [frols(ds, yl, xl) for yl in lags for xl in lags]
    K = py.get("free_run_from", 0)
    start = max(ds.init_window, K, max(lags))
    y = ds.val.y
    for key, yhat in predicted.items():
        py[key] = score(y, yhat, start)
    # select's tie between candidate spaces (--tie) at other widths than its default, same scoring
    sweep: dict[str, Any] = {}
    for tie in TIE_SWEEP:
        if tie == TIE:
            run = {key: py.get(key) for key in ("one_step", "free_run", "n_terms")}
        else:
            other, tied = run_pyrhonn(ds, folder / f"tie{tie:g}", ("--tie", f"{tie:g}"), online=False)
            first = max(start, other.get("free_run_from", 0))  # its own deepest tap may be deeper
            run = {"n_terms": other.get("n_terms"), "error": other.get("error"), "scored_from": first,
                   **{key: score(y, tied[key], first) for key in ("one_step", "free_run") if key in tied}}
        sweep[f"t{round(tie * 100):02d}"] = {"tie": tie, **run}
    py["tie_sweep"] = sweep
    rows = []
    for info, one, free in grid:
        rows.append({**info, "one_step": score(y, one, start), "free_run": score(y, free, start)})
    by_aic = min(rows, key=lambda r: r["aic"])
    by_val = min(rows, key=lambda r: (r["free_run"]["diverged"],
                                      r["free_run"]["rmse"] if not r["free_run"]["diverged"] else 0.0,
                                      -r["free_run"].get("diverged_at", 0)))
    return {
        "title": ds.title,
        "source": ds.source,
        "sampling_period": ds.sampling_period,
        "estimation_samples": int(ds.est.y.size),
        "validation_samples": int(y.size),
        "scored_from": start,
        "scored_samples": int(y.size - start),
        "validation_y_std": float(np.std(y[start:])),
        "pyrhonn": py,
        "sysidentpy_aic": {**by_aic, "chosen_by": "smallest AIC on the estimation record"},
        "sysidentpy_best_on_validation": {**by_val, "chosen_by": "smallest free-run RMSE on the validation "
                                                                 "record (optimistic: it saw the validation record)"},
        "sysidentpy_grid": rows,
        "sysidentpy_grid_fit_seconds": sum(r["fit_seconds"] for r in rows),
        "published": ds.published,
    }


def _cell(s: dict[str, Any] | None, key: str) -> str:
    if s is None:
        return "-"
    if s.get("diverged"):
        return f"div@{s['diverged_at']}" if key == "rmse" else "-"
    v = s.get(key)
    return "-" if v is None else f"{v:.4g}"


def print_table(results: dict[str, Any]) -> None:
    head = (f"{'data set':15} {'method':22} {'structure':32} {'1-step RMSE':>11} {'RRSE':>7} "
            f"{'free RMSE':>10} {'RRSE':>7} {'time s':>7}")
    print(head)
    print("-" * len(head))
    for r in results["datasets"].values():
        py = r["pyrhonn"]
        name = r["title"]
        if "error" in py:
            print(f"{name:15} {'pyrhonn select':22} {py['error']}")
        else:
            structure = f"{py['n_terms']} terms, delay {py['max_delay']}"
            print(f"{name:15} {'pyrhonn select':22} {structure:32} {_cell(py['one_step'], 'rmse'):>11} "
                  f"{_cell(py['one_step'], 'rrse'):>7} {_cell(py['free_run'], 'rmse'):>10} "
                  f"{_cell(py['free_run'], 'rrse'):>7} {py['select_wall_seconds']:7.2f}")
            for state, terms in py["terms"].items():
                print(f"{'':15} {'':22} {state}: " + " ".join(terms))
            print(f"{'':15} {'  learning online':22} {'as written / wait_for_history off':32} "
                  f"{_cell(py['online'], 'rmse'):>11} {_cell(py['online'], 'rrse'):>7} / "
                  f"{_cell(py['online_padded'], 'rmse')} {_cell(py['online_padded'], 'rrse')}")
        for key, label in (("sysidentpy_aic", "FROLS, AIC on est."), ("sysidentpy_best_on_validation",
                                                                       "FROLS, best on val. *")):
            s = r[key]
            structure = f"ylag {s['ylag']} xlag {s['xlag']}, {s['n_terms']} terms"
            print(f"{'':15} {label:22} {structure:32} {_cell(s['one_step'], 'rmse'):>11} "
                  f"{_cell(s['one_step'], 'rrse'):>7} {_cell(s['free_run'], 'rmse'):>10} "
                  f"{_cell(s['free_run'], 'rrse'):>7} {r['sysidentpy_grid_fit_seconds']:7.2f}")
        for p in r["published"]:
            print(f"{'':15} {'published':22} {p['model'][:32]:32} {'':>11} {'':>7} {p['free_run_rmse']:>10.4g}")
        print(f"{'':15} scored on validation samples {r['scored_from']}..{r['validation_samples'] - 1} "
              f"({r['scored_samples']}); validation y std {r['validation_y_std']:.4g}")
    print("* chosen on the validation record: an optimistic reference, not a fair competitor. time: pyrhonn, "
          "the wall time of the select command (interpreter start included); FROLS, the fits of its whole lag "
          "grid. div@k: the free run diverged at sample k.")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true",
                    help="smoke run: shorter simulated records, FROLS lags 1..2")
    ap.add_argument("--json", metavar="FILE", help="also write every figure as JSON")
    ap.add_argument("--keep", metavar="DIR", help="keep the CSV files, configs and select reports in DIR")
    ap.add_argument("--results", action="store_true",
                    help="also write every figure to bench/results/real_data.json, which the docs quote")
    args = ap.parse_args(argv)
    if args.results:  # imported now: it notes the load average at the start of the run
        from results_file import save  # noqa: E402 - beside this script
    sysidentpy = _sysidentpy()
    if sysidentpy is None:
        print("bench_real_data: SysIdentPy is needed for the baseline (pip install 'sysidentpy>=0.9', or the "
              "bench extra: pip install '.[bench]')", file=sys.stderr)
        return 2
    load_before = os.getloadavg()
    lags = (1, 2) if args.quick else (1, 2, 3)
    print(f"pyrhonn {pyrhonn.__version__}, SysIdentPy {sysidentpy.__version__}, numpy {np.__version__}, "
          f"Python {platform.python_version()}; load average {load_before[0]:.2f} {load_before[1]:.2f} "
          f"{load_before[2]:.2f}")
    t0 = time.perf_counter()
    datasets = [cascaded_tanks(), bouc_wen(args.quick), narendra_li(args.quick)]
    print(f"data ready in {time.perf_counter() - t0:.1f} s: " + "; ".join(
        f"{d.title} {d.est.y.size} + {d.val.y.size} samples" for d in datasets))
    results: dict[str, Any] = {
        "benchmark": "bench_real_data", "quick": args.quick,
        "versions": {"pyrhonn": pyrhonn.__version__, "sysidentpy": sysidentpy.__version__,
                     "numpy": np.__version__, "python": platform.python_version()},
        "machine": {"cpus": os.cpu_count(), "processor": platform.machine()},
        "sysidentpy_setup": {"model": "FROLS", "basis": f"Polynomial(degree={DEGREE})", "estimator": "LeastSquares",
                             "model_type": "NARMAX (its default; least squares without noise terms: a NARX model)",
                             "info_criteria": "aic", "n_info_values": N_INFO,
                             "model_length": "SysIdentPy's: where its AIC first rises",
                             "ylag_grid": list(lags), "xlag_grid": list(lags)},
        "pyrhonn_setup": {"command": ["pyrhonn", *SELECT_ARGS],
                          "scored_with": "configfile + datafile + Identifier(learning=False) + simulation.simulate, "
                                         "free_run_from = the config's deepest delay + 1"},
        "diverged_rule": f"not finite, or further than {DIVERGED_RANGES:g} validation ranges from its middle",
        "datasets": {},
    }
    with tempfile.TemporaryDirectory(prefix="bench_real_data_") as tmp:
        root = Path(args.keep) if args.keep else Path(tmp)
        for ds in datasets:
            results["datasets"][ds.key] = run_dataset(ds, root / ds.key, lags)
    load_after = os.getloadavg()
    results["load_average"] = {"before": list(load_before), "after": list(load_after)}
    results["seconds"] = time.perf_counter() - t0
    print()
    print_table(results)
    print(f"load average after: {load_after[0]:.2f} {load_after[1]:.2f} {load_after[2]:.2f}; "
          f"{results['seconds']:.0f} s in all")
    if args.json:
        atomic.write_text(args.json, json.dumps(results, indent=2, allow_nan=False) + "\n")
    if args.results:
        save("real_data", results, argv)
    return 0


if __name__ == "__main__":
    sys.exit(main())
