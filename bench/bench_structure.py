"""Structure selection from data: ``pyrhonn select`` + the online EKF
against SysIdentPy's FROLS, on the same data and the same split.

Each case is simulated, split in time (the first 70% selects/estimates, the
last 30% is scored), and both methods are scored on the same one-step
targets of the last 30%:

- pyrhonn: :func:`pyrhonn.structure.select` on the first 70%, then the C
  identifier with the selected config (least-squares w0) runs over the whole
  trajectory, learning online, and its one-step predictions are scored;
  its free run (:func:`pyrhonn.simulation.simulate`): weights learnt
  online up to the split, then frozen, and the whole network (every state)
  fed its own predictions from the split on;
- SysIdentPy: ``FROLS`` (polynomial NARX, the same degree, information
  criterion BIC, least squares) fitted per state on the first 70%, with the
  other states and the inputs as exogenous inputs and the same lags, then
  ``predict(steps_ahead=1)`` on the last 30%; its free run is
  ``predict(steps_ahead=None)`` per state equation, which feeds back that
  state's own predictions but reads the *measured* other states (its model
  is one MISO equation per state): an easier test than pyrhonn's MIMO free
  run, where a drift in one state propagates to the others.

Columns: one-step RRSE (root relative squared error, sqrt(sum e^2 / sum (y -
mean y)^2), mean over the states), free-run RRSE, selection time, terms used (sum over the
neurons), delays found (the estimated delay of each state, ``-`` where no
delayed tap was chosen). For Example 1 the one-step RMSE of x4 is printed too.

Cases: Example 1 (pyrhonn/plants/oscillator.py) at T = 0.2 s and 0.02 s,
100 s; the robot (pyrhonn/plants/robot.py, the paper's 15 s at 0.01 s); the LIM
(pyrhonn/plants/lim.py, from 2 s, when its inputs switch on, to 4 s); and two
classic NARX benchmarks, simulated here:

- Example 2 of K. S. Narendra and K. Parthasarathy, "Identification and
  control of dynamical systems using neural networks", IEEE Trans. Neural
  Networks 1(1), 1990: y(k+1) = y(k) y(k-1) (y(k) + 2.5) / (1 + y(k)^2 +
  y(k-1)^2) + u(k), u uniform in [-2, 2];
- the system of S. Chen, S. A. Billings and P. M. Grant, "Non-linear system
  identification using neural networks", Int. J. Control 51(6), 1990:
  y(k+1) = (0.8 - 0.5 exp(-y(k)^2)) y(k) - (0.3 + 0.9 exp(-y(k)^2)) y(k-1)
  + u(k) + 0.2 u(k-1) + 0.1 u(k) u(k-1), u uniform in [-1, 1], noise-free:
  an input read one sample back, so the candidates include u(k-1).

    pip install sysidentpy             # optional: the baseline (skipped cleanly without it)
    python bench/bench_structure.py            # all cases
    python bench/bench_structure.py --quick    # the smallest cases only
    python bench/bench_structure.py --speed    # also the 10^4-sample, 4-state, 2-input, delay-20 timing
    python bench/bench_structure.py --results  # also bench/results/structure.json, which the docs quote
                                               # (each case under its name in letters, digits, _ and -)
"""
from __future__ import annotations

import argparse
import json
import re
import time
from dataclasses import dataclass
from typing import Callable

import numpy as np

from pyrhonn import Activation, Identifier, atomic, metrics
from pyrhonn.plants import lim, oscillator, robot
from pyrhonn.simulation import simulate
from pyrhonn.structure import CandidateSpace, select

try:
    from sysidentpy.basis_function import Polynomial
    from sysidentpy.model_structure_selection import FROLS
    from sysidentpy.parameter_estimation import LeastSquares
except ImportError:  # the baseline is optional
    FROLS = None

SPLIT = 0.7


@dataclass
class Case:
    name: str
    data: Callable[[], tuple[np.ndarray, np.ndarray]]
    space: CandidateSpace
    max_terms: int = 16


def narendra(T: int = 4000, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    U = rng.uniform(-2.0, 2.0, (T, 1))
    y = np.zeros(T)
    for k in range(1, T - 1):
        y[k + 1] = y[k] * y[k - 1] * (y[k] + 2.5) / (1.0 + y[k] ** 2 + y[k - 1] ** 2) + U[k, 0]
    return y[:, None], U


def chen_billings(T: int = 4000, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    U = rng.uniform(-1.0, 1.0, (T, 1))
    y = np.zeros(T)
    for k in range(1, T - 1):
        g = np.exp(-y[k] ** 2)
        y[k + 1] = ((0.8 - 0.5 * g) * y[k] - (0.3 + 0.9 * g) * y[k - 1] + U[k, 0] + 0.2 * U[k - 1, 0]
                    + 0.1 * U[k, 0] * U[k - 1, 0])
    return y[:, None], U


def robot_data() -> tuple[np.ndarray, np.ndarray]:
    tr = robot.simulate()
    return tr.X, tr.U


def example1(dt: float) -> Callable[[], tuple[np.ndarray, np.ndarray]]:
    def make() -> tuple[np.ndarray, np.ndarray]:
        tr = oscillator.simulate(dt=dt)
        return tr.X, tr.U
    return make


def lim_data() -> tuple[np.ndarray, np.ndarray]:
    tr = lim.simulate(horizon=4.0)
    on = int(round(2.0 / tr.dt))  # the inputs switch on at 2 s; before, every state rests at 0
    return tr.X[on:], tr.U[on:]


BOTH = (Activation.BIPOLAR, Activation.LOGISTIC)
CASES = [
    Case("example1 T=0.2 s", example1(0.2), CandidateSpace(max_delay=20, delay_step=5, degree=3,
                                                           factors=("S", "x", "u", "1"), activations=BOTH)),
    Case("example1 T=0.02 s", example1(0.02), CandidateSpace(max_delay=60, delay_step=15, degree=2,
                                                             factors=("S", "x", "u", "1"), activations=BOTH)),
    Case("robot", robot_data, CandidateSpace(max_delay=1, degree=2, factors=("S", "x", "u", "1"), activations=BOTH)),
    Case("LIM", lim_data, CandidateSpace(max_delay=1, degree=2, factors=("x", "u", "1"))),
    Case("Narendra-Parthasarathy ex. 2", narendra, CandidateSpace(max_delay=2, degree=3, factors=("S", "x", "u", "1"),
                                                                  activations=BOTH)),
    Case("Chen-Billings-Grant", chen_billings, CandidateSpace(max_delay=1, degree=3, factors=("S", "x", "u", "1"),
                                                              input_max_delay=1, activations=BOTH)),
]


def rrse(y: np.ndarray, yhat: np.ndarray) -> float:
    """Mean over the states of :func:`pyrhonn.metrics.rrse`."""
    return float(np.mean(metrics.rrse(y, yhat)))


def run_pyrhonn(case: Case, X: np.ndarray, U: np.ndarray, cut: int, first: int) -> dict[str, object]:
    t0 = time.perf_counter()
    sel = select(X[:cut], U[:cut], space=case.space, max_terms=case.max_terms)
    seconds = time.perf_counter() - t0
    ident = Identifier(sel.config())
    Xhat = ident.run(X, U)  # row k: the prediction of x(k+1), learning online all along
    truth, pred = X[first + 1:], Xhat[first:-1]
    free = simulate(Identifier(sel.config()), X, U, free_run_from=cut).free_run
    assert free is not None
    free_rrse = rrse(truth, free[first + 1:]) if np.all(np.isfinite(free[first + 1:])) else float("inf")
    return {"rrse": rrse(truth, pred), "free_rrse": free_rrse, "seconds": seconds,
            "terms": sum(len(n.terms) for n in sel.neurons),
            "delays": ["-" if d is None else d for d in sel.state_delays()],
            "rmse": metrics.rmse(truth, pred).tolist()}


def run_sysidentpy(case: Case, X: np.ndarray, U: np.ndarray, cut: int, first: int) -> dict[str, object] | None:
    if FROLS is None:
        return None
    lags = [d + 1 for d in case.space.delays]  # NARX lag l reads x(k+1-l): our delay d is lag d+1
    n = X.shape[1]
    preds, frees, terms, seconds, delays = [], [], 0, 0.0, []
    for i in range(n):
        others = np.hstack([np.delete(X, i, axis=1), U])
        ulags = list(range(1, case.space.input_max_delay + 2))  # our u(k-d) is NARX lag d+1
        xlag = [list(lags) for _ in range(n - 1)] + [list(ulags) for _ in range(U.shape[1])]
        model = FROLS(order_selection=True, n_info_values=case.max_terms, ylag=list(lags),
                      xlag=xlag if len(xlag) > 1 else xlag[0], info_criteria="bic", estimator=LeastSquares(),
                      basis_function=Polynomial(degree=case.space.degree))
        t0 = time.perf_counter()
        model.fit(X=others[:cut], y=X[:cut, i:i + 1])
        seconds += time.perf_counter() - t0
        # one-step predictions over the scored part; SysIdentPy copies its first max_lag samples
        start = first + 1 - model.max_lag
        yhat = model.predict(X=others[start:], y=X[start:, i:i + 1], steps_ahead=1)
        preds.append(yhat[model.max_lag:, 0])
        with np.errstate(all="ignore"):
            sim = model.predict(X=others[start:], y=X[start:, i:i + 1], steps_ahead=None)
        frees.append(sim[model.max_lag:, 0])
        terms += len(model.final_model)
        found = [int(code) % 1000 - 1 for row in model.final_model for code in row if code and int(code) % 1000 > 1]
        delays.append(max(found) if found else "-")
    pred, free = np.column_stack(preds), np.column_stack(frees)
    truth = X[first + 1:]
    free_rrse = rrse(truth, free) if np.all(np.isfinite(free)) else float("inf")
    return {"rrse": rrse(truth, pred), "free_rrse": free_rrse, "seconds": seconds, "terms": terms, "delays": delays,
            "rmse": metrics.rmse(truth, pred).tolist()}


def example1_full_run(case: Case, paper: str) -> dict[str, list[float]]:
    """The paper's setting (Tables 1-4): Example 1, 100 s, terms selected on the whole run and the
    identifier run over it, learning online; the one-step RMSE and absolute deviation per state over
    every sample after the selection window, beside the paper's identifier figures."""
    from pyrhonn.reproduce import PAPER

    X, U = case.data()
    tap = int(round(oscillator.OscillatorParams().tau / (0.2 if paper == "example1-dt0.2" else 0.02)))
    sel = select(X, U, space=case.space, max_terms=case.max_terms)
    Xhat = Identifier(sel.config()).run(X, U)
    w = case.space.window + 1
    truth, est = X[w + 1:], Xhat[w:-1]
    rmse = metrics.rmse(truth, est)
    ad = metrics.absolute_deviation(truth, est)
    fig = PAPER[paper]
    print(f"{case.name}, 100 s, selected on the whole run, the identifier learning online: "
          + "; ".join(f"x{j + 1} RMSE {rmse[j]:.3g}"
                      + (f" ({rmse[j] / fig.identifier_rmse[j]:.2g}x {fig.rmse_table})"
                         if fig.identifier_rmse[j] is not None else "")
                      + f", AD {ad[j]:.3g} ({ad[j] / fig.identifier_ad[j]:.2g}x {fig.ad_table})"
                      for j in range(4))
          + "; delays " + " ".join("-" if d is None else str(d) for d in sel.state_delays())
          + (f"; neurons with a tap at tau / T = {tap} samples: " + " ".join(
              f"x{nr.state + 1}" for nr in sel.neurons if any(d == tap for _, d in nr.delays))
             if tap <= case.space.max_delay else
             f"; tau / T = {tap} samples is beyond the candidate delays (up to {case.space.max_delay})"))
    return {"rmse": rmse.tolist(), "absolute_deviation": ad.tolist(),
            "rmse_over_paper": [None if f is None else float(r / f) for r, f in zip(rmse, fig.identifier_rmse)],
            "absolute_deviation_over_paper": [float(a / f) for a, f in zip(ad, fig.identifier_ad)],
            "delays": [None if d is None else int(d) for d in sel.state_delays()]}


def speed() -> float:
    """The selection target: 10^4 samples, 4 states, 2 inputs, delays up to 20, degree 2."""
    rng = np.random.default_rng(1)
    T = 10_000
    U = rng.uniform(-1, 1, (T, 2))
    X = np.zeros((T, 4))
    S = np.tanh
    for k in range(T - 1):
        xd = X[max(k - 12, 0)]
        X[k + 1] = (0.5 * S(X[k, 0]) + 0.4 * U[k, 0], 0.6 * S(X[k, 1]) - 0.5 * S(xd[0]) + 0.3 * U[k, 1],
                    0.7 * S(X[k, 2]) + 0.4 * S(X[k, 1]) * U[k, 0], 0.5 * S(X[k, 3]) + 0.5 * S(xd[2]) * S(X[k, 0]))
    t0 = time.perf_counter()
    sel = select(X, U, space=CandidateSpace(max_delay=20, degree=2))
    seconds = time.perf_counter() - t0
    print(f"speed: {sel.n_candidates} candidates x {sel.rows} rows, 2 activations: {seconds:.2f} s")
    return seconds


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="the smallest cases only")
    ap.add_argument("--speed", action="store_true", help="also time the 10^4-sample selection target")
    ap.add_argument("--json", metavar="FILE", help="also write the figures as JSON")
    ap.add_argument("--results", action="store_true", help="also write the figures to bench/results/structure.json")
    args = ap.parse_args(argv)
    if args.results:  # imported now: it notes the load average at the start of the run
        from results_file import save  # noqa: E402 - beside this script
    if FROLS is None:
        print("SysIdentPy is not installed (pip install sysidentpy): its columns are skipped")
    cases = [c for c in CASES if not args.quick or c.name in ("example1 T=0.2 s", "Narendra-Parthasarathy ex. 2")]
    print("one-step and free-run scores on the last 30%; delays: pyrhonn's estimated delay per state, SysIdentPy's deepest "
          "lag - 1 per state equation")
    print(f"{'case':30} {'method':11} {'RRSE':>8} {'free RRSE':>9} {'select s':>9} {'terms':>6}  delays found   "
          "x4 RMSE")
    results = {}
    for case in cases:
        X, U = case.data()
        cut = int(SPLIT * X.shape[0])
        first = cut + case.space.window + 1  # the first scored prediction: both methods have a full window
        row = {"pyrhonn": run_pyrhonn(case, X, U, cut, first), "sysidentpy": run_sysidentpy(case, X, U, cut, first)}
        results[case.name] = row
        for method, r in row.items():
            if r is None:
                continue
            x4 = f"{r['rmse'][3]:.3f}" if case.name.startswith("example1") else ""
            print(f"{case.name:30} {method:11} {r['rrse']:8.3g} {r['free_rrse']:9.3g} {r['seconds']:9.2f} "
                  f"{r['terms']:6d}  "
                  f"{' '.join(str(d) for d in r['delays']):14} {x4}")
    results["example1_full_run"] = example1_full_run(CASES[0], "example1-dt0.2")
    if not args.quick:
        results["example1_dt0.02_full_run"] = example1_full_run(CASES[1], "example1-dt0.02")
    if args.speed:
        results["speed_seconds"] = speed()
    if args.json:
        atomic.write_text(args.json, json.dumps(results, indent=2))
    if args.results:  # a reference's keys are joined by dots: "example1 T=0.2 s" is example1_T_0_2_s there
        save("structure", {re.sub(r"[^\w-]+", "_", k).strip("_"): v for k, v in results.items()}, argv)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
