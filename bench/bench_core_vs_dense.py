"""The LIM identifier step through pyrhonn's core against a textbook dense
EKF (bench/c/dense_ekf.c) and a generic-library EKF (bench/c/generic_ekf.c),
in one process and one run, on the same samples.

For each shipped LIM config (``firmware-lim``, ``example3``) and precision,
the LIM trajectory of ``pyrhonn.plants.lim`` (from 2.0 s, when the inputs
switch on; no dropouts) runs through pyrhonn's Identifier, which records the
regressors z_i(k) it forms at every sample. A C harness (bench/c/
core_vs_dense.c), compiled here with the system cc into a temporary folder,
links the core (csrc/src/rhonn.c, -ffp-contract=off, the unrolled and the
generic kernel, the config's smallest capacities) and the dense EKF, and runs
the same samples through:

  core    rhonn_step per sample: forms the regressors from x and u itself
          (activations included), runs each neuron's update (packed P, or
          U D U^T where the config says so) with its positive-definiteness
          check, predicts;
          built three ways: "unrolled" (per-size kernels), "generic" (loops)
          and "fixed" (the core compiled for this one configuration,
          RHONN_FIXED_CONFIG, as the firmware builds it), all three giving
          the Identifier's predictions bit for bit;
  dense   per neuron, on the recorded regressors (handed to it, so it does
          no activation or regressor work): S = H P H^T + R,
          K = P H^T / S, w += eta K e, P = (I - K H) P + Q with full L x L
          matrices and general matrix products, then w^T z. F = I, so no
          F P F^T is formed;
  generic the same filter in the form of a generic embedded EKF library
          (TinyEKF's sequence of update then predict, from general matrix
          routines): P H^T and H P both formed, S inverted by Cholesky,
          P <- (I - G H) P, then P <- F P F^T + Q with F = I multiplied out.
          The same regressors are handed to it.

It prints the predictions' agreement (largest over states of
max_k |dense - core| / max_k |core|, and the same for generic), the best ns
per LIM step of each (the three timed alternately, best of the repeats), the
ratios dense / core and generic / core (how many times faster the core is),
and, when valgrind is installed, the instructions per step from callgrind
(load-independent). Below each row, what learning itself takes in the core
and in the dense EKF, in time and in instructions: each run minus the same
run with learning off (the core with rhonn_set_learning(0), the dense EKF
only predicting), so the regressor, the activations and the prediction,
which the core does and the dense EKF is handed, are out of that ratio. The
machine load (os.getloadavg) is printed beside every row.

    python bench/bench_core_vs_dense.py               # -O2 (about a minute)
    python bench/bench_core_vs_dense.py --native      # also -O3 -march=native (about two minutes)
    python bench/bench_core_vs_dense.py --quick       # smoke run
    python bench/bench_core_vs_dense.py --covariance full   # every neuron of the core in eq. 7's full form
    python bench/bench_core_vs_dense.py --json out.json
    python bench/bench_core_vs_dense.py --results     # also bench/results/core_vs_dense.json, which the docs quote
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import re
import shlex
import shutil
import subprocess
import sys
import tempfile
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from pyrhonn import CovarianceForm, Identifier, IdentifierConfig, IdentifierError, atomic
from pyrhonn.configfile import load_shipped
from pyrhonn.export import export_header
from pyrhonn.plants import lim

ROOT = Path(__file__).resolve().parent.parent
C_DIR = ROOT / "bench" / "c"
CORE = ROOT / "csrc" / "src" / "rhonn.c"
INCLUDE = ROOT / "csrc" / "include"
CONFIGS = ("firmware-lim", "example3")
START_S = 2.0  # the inputs of eq. 21-22 switch on
WARNINGS = ["-Wall", "-Wextra", "-Wpedantic", "-Wconversion", "-Wshadow", "-Wdouble-promotion"]
OPT_LEVELS = {"O2": ["-O2"], "O3-native": ["-O3", "-march=native"]}


@dataclass(frozen=True)
class Samples:
    """One config's run: samples, the regressors pyrhonn formed and its predictions."""
    config: IdentifierConfig
    X: np.ndarray      # (T, n)
    U: np.ndarray      # (T, m)
    Z: np.ndarray      # (T, sum L_i): z_0(k) .. z_{n-1}(k)
    Xhat: np.ndarray   # (T, n): pyrhonn's predictions of x(k+1)


def lim_config(name: str, dtype: str, covariance: str = "config") -> IdentifierConfig:
    """A shipped LIM config in the precision asked; ``covariance`` "full" or
    "ud" puts every neuron in that form ("config": as shipped)."""
    config = load_shipped(name).config.replace(dtype=dtype)
    if covariance == "config":
        return config
    return config.replace(neurons=tuple(replace(nr, covariance=CovarianceForm(covariance)) for nr in config.neurons))


def record(config: IdentifierConfig, T: int) -> Samples:
    """T samples of the LIM from START_S, stepped through pyrhonn's
    Identifier; the regressors z_i(k) it forms and its predictions."""
    traj = lim.simulate(dt=1e-4, horizon=START_S + (T + 1) * 1e-4, holds=())
    k0 = int(round(START_S / traj.dt))
    X = np.ascontiguousarray(traj.X_meas[k0:k0 + T].astype(config.dtype))
    U = np.ascontiguousarray(traj.U[k0:k0 + T].astype(config.dtype))
    ident = Identifier(config)
    Z = np.empty((T, sum(nr.n_terms for nr in config.neurons)), dtype=config.dtype)
    Xhat = np.empty_like(X)
    for k in range(T):
        Xhat[k] = ident.step(X[k], U[k])
        Z[k] = np.concatenate(ident.regressors)  # z(k), which produced xhat(k+1)
    return Samples(config, X, U, Z, Xhat)


def compiler() -> list[str]:
    return shlex.split(os.environ.get("CC", "cc"))


KERNELS = ("fixed", "unrolled", "generic")


def build(samples: Samples, folder: Path, opt: str, unroll: bool = True, fixed: bool = False) -> tuple[Path, Path]:
    """Compile the harness for ``samples``' config into ``folder``; returns
    (the program, its data file). ``fixed``: the core compiled for that one
    configuration (RHONN_FIXED_CONFIG, as the firmware builds it; unrolled)."""
    folder.mkdir(parents=True, exist_ok=True)
    cfg = samples.config
    export_header(cfg, folder / "bench_config.h", name="bench_config")
    data = folder / "data.bin"
    atomic.write_bytes(data, samples.X.tobytes() + samples.U.tobytes() + samples.Z.tobytes())
    kernel = "fixed" if fixed else "unrolled" if unroll else "generic"
    exe = folder / f"core_vs_dense-{opt}-{kernel}"
    single = ["-DRHONN_SINGLE", "-DDENSE_SINGLE"] if cfg.dtype == "float32" else []
    pinned = ["-DRHONN_FIXED_CONFIG=bench_config", '-DRHONN_FIXED_CONFIG_HEADER="bench_config.h"'] if fixed else []
    cmd = [*compiler(), "-std=c99", *OPT_LEVELS[opt], "-ffp-contract=off", *WARNINGS, *single, *pinned,
           f"-DRHONN_UNROLL={int(unroll or fixed)}", '-DRHONN_USER_CAPACITY="bench_config_capacity.h"',
           f"-I{folder}", f"-I{INCLUDE}", f"-I{C_DIR}",
           str(CORE), str(C_DIR / "dense_ekf.c"), str(C_DIR / "generic_ekf.c"),
           str(C_DIR / "core_vs_dense.c"), "-o", str(exe), "-lm"]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0 or proc.stderr.strip():
        raise RuntimeError(f"compiling the harness failed or warned:\n{' '.join(cmd)}\n{proc.stderr}")
    return exe, data


@dataclass(frozen=True)
class Predictions:
    """One harness run's predictions (T, n) of each filter, and what it said."""
    core: np.ndarray
    dense: np.ndarray
    generic: np.ndarray
    status: str            # "core: <status> after <steps> steps"
    generic_refused: int   # updates the generic EKF skipped (S not positive), over all neurons


def predictions(exe: Path, data: Path, samples: Samples) -> Predictions:
    """The three filters' predictions on ``samples``, from one run of ``exe``."""
    T, n = samples.X.shape
    proc = subprocess.run([str(exe), "predict", str(data), str(T)], capture_output=True)
    if proc.returncode != 0:
        raise RuntimeError(f"{exe.name} predict: {proc.stderr.decode(errors='replace')}")
    out = np.frombuffer(proc.stdout, dtype=samples.config.dtype).reshape(3, T, n)
    said = proc.stderr.decode().splitlines()
    m = re.fullmatch(r"generic: (\d+) updates refused", said[1]) if len(said) == 2 else None
    if m is None:
        raise RuntimeError(f"{exe.name} predict said: {said}")
    return Predictions(out[0], out[1], out[2], said[0], int(m.group(1)))


def relative_difference(a: np.ndarray, b: np.ndarray) -> float:
    """Largest over states of max_k |a - b| / max_k |b| (inf if a is not finite)."""
    a64, b64 = a.astype(np.float64), b.astype(np.float64)
    if not np.all(np.isfinite(a64)):
        return float("inf")
    scale = np.maximum(np.max(np.abs(b64), axis=0), np.finfo(np.float64).tiny)
    return float(np.max(np.max(np.abs(a64 - b64), axis=0) / scale))


def timed(exe: Path, data: Path, T: int, repeats: int) -> dict[str, str]:
    proc = subprocess.run([str(exe), "time", str(data), str(T), str(repeats)], capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"{exe.name} time: {proc.stderr}")
    return dict(line.split(None, 1) for line in proc.stdout.splitlines())


def instructions_per_step(exe: Path, data: Path, T: int, which: str, frozen: bool = False) -> float | None:
    """Instructions of one run of bench_run_<which> over T steps, from
    callgrind, per step; None without valgrind, or for a build it cannot
    run (an instruction it does not decode, such as AVX-512's). ``frozen``:
    the same run with learning off (``which`` "core" or "dense")."""
    if frozen and which not in ("core", "dense"):
        raise ValueError(f"frozen: only the core and the dense EKF run with learning off, not {which!r}")
    valgrind = shutil.which("valgrind")
    if valgrind is None:
        return None
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "callgrind.out"
        proc = subprocess.run([valgrind, "--tool=callgrind", f"--callgrind-out-file={out}",
                               f"--toggle-collect=bench_run_{which}", str(exe),
                               f"count-{which}-frozen" if frozen else f"count-{which}", str(data), str(T)],
                              capture_output=True, text=True)
        if proc.returncode != 0:
            if "Unrecognised instruction" in proc.stderr:  # e.g. AVX-512 in an -march=native build
                return None
            raise RuntimeError(f"callgrind on {exe.name}: {proc.stderr[-2000:]}")
        m = re.search(r"^(?:totals|summary):\s*(\d+)", out.read_text(), flags=re.M)
    if m is None:
        raise RuntimeError(f"callgrind on {exe.name}: no totals in its output")
    return int(m.group(1)) / T


@dataclass
class Row:
    config: str
    dtype: str
    opt: str
    kernel: str
    core_ns: float
    dense_ns: float
    generic_ns: float
    core_ir: float | None
    dense_ir: float | None
    generic_ir: float | None
    max_rel_diff: float
    generic_max_rel_diff: float
    generic_refused: int
    core_vs_identifier: float
    core_status: str
    load_1min: float
    core_frozen_ns: float = 0.0             # the same runs with learning off
    dense_frozen_ns: float = 0.0
    core_frozen_ir: float | None = None
    dense_frozen_ir: float | None = None
    core_vs_float64: float | None = None    # float32 rows: against the float64 Identifier
    dense_vs_float64: float | None = None
    generic_vs_float64: float | None = None

    @property
    def ratio(self) -> float:
        return self.dense_ns / self.core_ns

    @property
    def ir_ratio(self) -> float | None:
        return None if self.core_ir is None or self.dense_ir is None else self.dense_ir / self.core_ir

    @property
    def core_learn_ns(self) -> float:
        """Learning alone: the run minus the same run with learning off."""
        return self.core_ns - self.core_frozen_ns

    @property
    def dense_learn_ns(self) -> float:
        return self.dense_ns - self.dense_frozen_ns

    @property
    def core_learn_ir(self) -> float | None:
        return None if self.core_ir is None or self.core_frozen_ir is None else self.core_ir - self.core_frozen_ir

    @property
    def dense_learn_ir(self) -> float | None:
        return None if self.dense_ir is None or self.dense_frozen_ir is None else self.dense_ir - self.dense_frozen_ir

    @property
    def learn_ratio(self) -> float | None:
        """Dense / core time of learning alone (None if a difference is not positive: noise)."""
        if self.core_learn_ns <= 0 or self.dense_learn_ns <= 0:
            return None
        return self.dense_learn_ns / self.core_learn_ns

    @property
    def learn_ir_ratio(self) -> float | None:
        """Dense / core instructions of learning alone."""
        if self.core_learn_ir is None or self.dense_learn_ir is None or self.core_learn_ir <= 0:
            return None
        return self.dense_learn_ir / self.core_learn_ir

    @property
    def generic_ratio(self) -> float:
        return self.generic_ns / self.core_ns

    @property
    def generic_ir_ratio(self) -> float | None:
        return None if self.core_ir is None or self.generic_ir is None else self.generic_ir / self.core_ir


def measure(samples: Samples, name: str, folder: Path, opt: str, kernel: str, *, repeats: int,
            count_steps: int, float64_xhat: np.ndarray | None = None) -> Row:
    """One build's row (``kernel``: one of KERNELS); ``float64_xhat``: the
    float64 Identifier's predictions on the same samples, to measure a
    float32 row's rounding against."""
    exe, data = build(samples, folder, opt, unroll=kernel != "generic", fixed=kernel == "fixed")
    T = samples.X.shape[0]
    p = predictions(exe, data, samples)
    core, dense, generic = p.core, p.dense, p.generic
    t = timed(exe, data, T, repeats)
    n_count = min(count_steps, T)
    return Row(config=name, dtype=samples.config.dtype, opt=opt, kernel=kernel,
               core_ns=float(t["core_ns_per_step"]), dense_ns=float(t["dense_ns_per_step"]),
               generic_ns=float(t["generic_ns_per_step"]),
               core_frozen_ns=float(t["core_frozen_ns_per_step"]),
               dense_frozen_ns=float(t["dense_frozen_ns_per_step"]),
               core_ir=instructions_per_step(exe, data, n_count, "core"),
               dense_ir=instructions_per_step(exe, data, n_count, "dense"),
               core_frozen_ir=instructions_per_step(exe, data, n_count, "core", frozen=True),
               dense_frozen_ir=instructions_per_step(exe, data, n_count, "dense", frozen=True),
               generic_ir=instructions_per_step(exe, data, n_count, "generic"),
               max_rel_diff=relative_difference(dense, core),
               generic_max_rel_diff=relative_difference(generic, core),
               generic_refused=p.generic_refused,
               core_vs_identifier=relative_difference(core, samples.Xhat),
               core_status=f"{t['core_status']} after {t['core_steps']} of {T} steps",
               load_1min=os.getloadavg()[0],
               core_vs_float64=None if float64_xhat is None else relative_difference(core, float64_xhat),
               dense_vs_float64=None if float64_xhat is None else relative_difference(dense, float64_xhat),
               generic_vs_float64=None if float64_xhat is None else relative_difference(generic, float64_xhat))


def print_rows(rows: list[Row]) -> None:
    head = (f"{'config':13} {'dtype':8} {'build':10} {'kernel':9} {'core':>9} {'dense':>9} {'x':>6} "
            f"{'generic':>9} {'x':>6} {'core Ir':>8} {'dense Ir':>9} {'x Ir':>6} {'generic Ir':>10} {'x Ir':>6} "
            f"{'dense diff':>10} {'gen. diff':>10} {'load':>5}")
    print(head)
    print("-" * len(head))
    for r in rows:
        ir = lambda v: "-" if v is None else f"{v:.0f}"  # noqa: E731
        times = lambda v: "-" if v is None else f"{v:.2f}"  # noqa: E731
        print(f"{r.config:13} {r.dtype:8} {r.opt:10} {r.kernel:9} {r.core_ns:7.0f}ns {r.dense_ns:7.0f}ns "
              f"{r.ratio:6.2f} {r.generic_ns:7.0f}ns {r.generic_ratio:6.2f} {ir(r.core_ir):>8} {ir(r.dense_ir):>9} "
              f"{times(r.ir_ratio):>6} {ir(r.generic_ir):>10} {times(r.generic_ir_ratio):>6} "
              f"{r.max_rel_diff:10.2e} {r.generic_max_rel_diff:10.2e} {r.load_1min:5.2f}")
        print(f"  learning alone (the run minus the same run with learning off): core {r.core_learn_ns:.0f}ns, "
              f"dense {r.dense_learn_ns:.0f}ns, x {times(r.learn_ratio)}; core {ir(r.core_learn_ir)}, "
              f"dense {ir(r.dense_learn_ir)} instructions, x {times(r.learn_ir_ratio)}")
        if r.generic_refused:
            print(f"  the generic EKF skipped {r.generic_refused} updates (S not positive: its P lost "
                  "definiteness), so it ran fewer instructions than a full run")
        if not r.core_status.startswith("RHONN_OK"):
            print(f"  core stopped: {r.core_status} (its time is per sample asked, not per step run)")
        if r.core_vs_float64 is not None and r.dense_vs_float64 is not None:
            print(f"  against the float64 core on the same samples: core {r.core_vs_float64:.2e}, "
                  f"dense {r.dense_vs_float64:.2e}, generic {r.generic_vs_float64:.2e}")
        if r.core_vs_identifier != 0.0:
            print(f"  the harness's core differs from pyrhonn's Identifier by {r.core_vs_identifier:.2e}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small smoke run")
    ap.add_argument("--native", action="store_true", help="also build at -O3 -march=native")
    ap.add_argument("--samples", type=int, default=None, help="LIM samples per run (default 10000; --quick 1000)")
    ap.add_argument("--repeats", type=int, default=None, help="timed repeats, best kept (default 15; --quick 3)")
    ap.add_argument("--covariance", choices=("config", "full", "ud"), default="config",
                    help="the core's covariance form for every neuron (default: as each config says; "
                         "the dense EKF is always the full textbook form)")
    ap.add_argument("--json", metavar="FILE", help="also write the figures as JSON")
    ap.add_argument("--results", action="store_true",
                    help="also write the figures to bench/results/core_vs_dense.json (by config, dtype, opt, kernel)")
    args = ap.parse_args(argv)
    if args.results:  # imported now: it notes the load average at the start of the run
        from results_file import save  # noqa: E402 - beside this script
    T = args.samples or (1_000 if args.quick else 10_000)
    repeats = args.repeats or (3 if args.quick else 15)
    if T < 2 or repeats < 1:
        ap.error("--samples must be >= 2 and --repeats >= 1")
    opts = ["O2", "O3-native"] if args.native else ["O2"]
    cc = compiler()
    version = subprocess.run([*cc, "--version"], capture_output=True, text=True).stdout.splitlines()
    print(f"pyrhonn core vs textbook dense EKF and generic-library EKF, LIM step; {platform.machine()}, {' '.join(cc)} "
          f"({version[0] if version else '?'}), {T} samples from t = {START_S} s, best of {repeats}; "
          f"load average {' '.join(f'{v:.2f}' for v in os.getloadavg())}; core covariance form: {args.covariance}")
    print("valgrind: " + ("instructions per step over the first "
                          f"{min(T, 2000)} samples (none, '-', for a build whose instructions it does not decode)"
                          if shutil.which("valgrind") else "not installed, no counts"))
    rows: list[Row] = []
    float64_xhat: dict[str, np.ndarray] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for dtype in ("float64", "float32"):
            for name in CONFIGS:
                try:
                    samples = record(lim_config(name, dtype, args.covariance), T)
                except IdentifierError as exc:
                    print(f"{name} {dtype}: skipped, pyrhonn's Identifier refused the run: {exc}")
                    continue
                if dtype == "float64":
                    float64_xhat[name] = samples.Xhat
                for opt in opts:
                    for kernel in KERNELS:
                        folder = Path(tmp) / f"{name}-{dtype}-{opt}-{kernel}"
                        rows.append(measure(samples, name, folder, opt, kernel, repeats=repeats, count_steps=2000,
                                            float64_xhat=float64_xhat.get(name) if dtype == "float32" else None))
    for opt in opts:
        print(f"\n{opt}:")
        print_rows([r for r in rows if r.opt == opt])
    print("\ncore, dense, generic: best ns per LIM step; x: dense / core and generic / core (times faster the core "
          "is); Ir: instructions per step (callgrind); dense diff, gen. diff: max over states of "
          "max_k |dense - core| / max_k |core|, and the same for generic.")
    print(f"load average at the end {' '.join(f'{v:.2f}' for v in os.getloadavg())}")
    figures = [dict(asdict(r), ratio=r.ratio, ir_ratio=r.ir_ratio, generic_ratio=r.generic_ratio,
                    core_learn_ns=r.core_learn_ns, dense_learn_ns=r.dense_learn_ns,
                    core_learn_ir=r.core_learn_ir, dense_learn_ir=r.dense_learn_ir,
                    learn_ratio=r.learn_ratio, learn_ir_ratio=r.learn_ir_ratio,
                    generic_ir_ratio=r.generic_ir_ratio) for r in rows]
    if args.json:
        atomic.write_text(args.json, json.dumps(figures, indent=2))
    if args.results:
        nested: dict[str, Any] = {"samples": T, "repeats": repeats, "compiler": version[0] if version else "?"}
        for f in figures:
            nested.setdefault(f["config"], {}).setdefault(f["dtype"], {}).setdefault(f["opt"], {})[f["kernel"]] = f
        save("core_vs_dense", nested, argv)
    return 0


if __name__ == "__main__":
    sys.exit(main())
