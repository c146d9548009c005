"""Pure-NumPy reference implementation of the RHONN identifier (eq. 3-12).

An independent, deliberately plain, full-matrix rewrite of the equations the
C core (``csrc/include/rhonn.h``) implements with packed, double-buffered
storage. It is the oracle for cross-checking the core and the baseline in
benchmarks; it never imports the C extension and always computes in float64.
"""
from __future__ import annotations

import numpy as np
import numpy.typing as npt

from .config import Activation, FactorKind, IdentifierConfig

__all__ = ["ReferenceIdentifier", "activate"]


def activate(activation: Activation, beta: float, s: npt.ArrayLike) -> np.ndarray:
    """Activation S of eq. 6 (logistic) or eq. 19 (bipolar), elementwise.

    With a = beta |s| and t = exp(-a) in [0, 1] nothing can overflow:

        logistic: S(s) = 1 / (1 + t)                   for s >= 0
                  S(s) = t / (1 + t)                   for s < 0
        bipolar:  S(s) = sign(s) (1 - t) / (1 + t),    1 - t = -expm1(-a)

    so S is finite (in [0, 1], resp. [-1, 1]) for every finite s, however
    large. Returns a float64 array, or a 0-d scalar for scalar s.
    """
    s = np.asarray(s, dtype=np.float64)
    with np.errstate(over="ignore"):
        a = beta * np.abs(s)  # may round to inf; exp(-inf) = 0 is exact
    t = np.exp(-a)
    if activation is Activation.LOGISTIC:
        out = np.where(s >= 0.0, 1.0 / (1.0 + t), t / (1.0 + t))
    else:
        out = np.copysign(-np.expm1(-a) / (1.0 + t), s)
    return out[()]


def _array(name: str, value: object, shape: tuple[int, ...], kind: str) -> np.ndarray:
    """Check a numpy input (kind "f": real floating, "b": bool) and copy it."""
    want = "a real floating" if kind == "f" else "a bool"
    if not isinstance(value, np.ndarray):
        raise ValueError(f"{name}: expected {want} numpy array of shape {shape}, got {type(value).__name__}")
    if value.dtype.kind != kind:
        raise ValueError(f"{name}: expected {want} array, got dtype {value.dtype}")
    if value.shape != shape:
        raise ValueError(f"{name}: expected shape {shape}, got {value.shape}")
    return value.astype(np.float64) if kind == "f" else value.copy()


class ReferenceIdentifier:
    """RHONN identifier (eq. 3-5) trained by the per-neuron EKF of eq. 7-9.

    One neuron per state, in series-parallel form (eq. 12)::

        xhat_i(k+1) = w_i^T z_i(k)                                       (3)
        z_ij(k)     = prod_{f in I_j} xi_f ^ d_f                         (4)
        xi          = [S(x_1) .. S(x_n), u_1 .. u_m], also x_j and 1     (5)

    where the states may be delayed, x_j(k - d) (Remark 1). The network is
    linear in its weights, so H_i = dxhat_i/dw_i = z_i (eq. 11) and, for the
    sample k, each neuron performs a scalar-measurement Kalman update::

        e_i(k)   = x_i(k) - xhat_i(k)                                    (9)
        M_i(k)   = [R_i + H_i^T P_i(k) H_i]^-1,  H_i = z_i(k-1)            (8)
        K_i(k)   = P_i(k) H_i M_i(k)                                      (7)
        w_i(k+1) = w_i(k) + eta_i K_i(k) e_i(k)                           (7)
        P_i(k+1) = P_i(k) - K_i(k) H_i^T P_i(k) + Q_i                     (7)

    With a forgetting factor lambda < 1 the last line is bounded forgetting:
    with P+ = P_i(k) - K_i(k) H_i^T P_i(k) and the ceiling c_i
    (p_trace_max when set, else trace P_i(0)),
    P_i(k+1) = P+ / lambda + Q_i when trace(P+) / lambda <= c_i, else
    P+ + Q_i; with a ceiling p_trace_max a P_i(k+1) of larger trace is
    then scaled down to it. With an innovation gate (``gate`` > 0), an
    update whose e_i^2 / (R_i + H_i^T P_i H_i) exceeds it is skipped (w_i
    and P_i unchanged). With ``skip_refused``, an update whose innovation
    variance, P_i or w_i is not finite is skipped for that neuron alone. The
    config's covariance form (full or U D U^T) does not matter here: the
    reference always updates the full P_i, in float64; automatic resets
    (reset_after) are not modelled.

    (the paper's w_i(k), w_i(k+1) are this class's weights before/after the
    step). K H^T P is computed as g g^T M with g = P H, which equals it for a
    symmetric P and keeps P exactly symmetric. One ``step`` for x(k), u(k):

    1. Learn, for each neuron whose x_i(k) is valid (skipped on the first
       step after construction/reset and while ``learning`` is False), unless
       its z_i(k-1) read a prediction of its own state in place of a missing
       x_i (x_i was not measured in each of the samples k-1 .. k-D_i, D_i the
       deepest delay at which neuron i reads x_i): then x̂_i(k) ends a free
       run of x_i and e_i(k) is its drift, not a one-step error.
    2. Effective state: x_j(k) where valid, else the prediction xhat_j(k)
       (config ``x0`` on the first step), so a dropout neither trains neuron
       j nor poisons the other regressors. Invalid x_j are ignored (may be NaN).
    3. z_i(k) from the effective x(k), x(k-d), u(k) and u(k-d); before the
       first sample the history is constant, equal to the first sample.
    4. xhat(k+1) = w(k+1)^T z(k), with the freshly updated weights.

    Every step is computed in full and committed only if it succeeded: on
    ``ValueError`` the identifier is exactly as before the call.

    Parameters
    ----------
    config : IdentifierConfig
        Terms, activations and EKF tuning. ``config.dtype`` is ignored: the
        reference always works in float64.

    Attributes
    ----------
    learning : bool
        When False, weights and covariances are frozen (no eq. 7-9 update),
        but predictions continue. ``reset`` switches it back on.
    weights : list of ndarray
        w_i, one (L_i,) array per neuron (copies).
    covariances : list of ndarray
        P_i, one full symmetric (L_i, L_i) array per neuron (copies).
    prediction : ndarray
        xhat(k), shape (n,): the last prediction, config ``x0`` before the
        first step (a copy).

    Examples
    --------
    >>> from pyrhonn import IdentifierConfig, terms
    >>> cfg = IdentifierConfig.uniform(terms.first_order(2, 1) + terms.bias(),
    ...                                n_states=2, n_inputs=1, p0=10.0, q=1e-3)
    >>> ident = ReferenceIdentifier(cfg)
    >>> xhat_next = ident.step(np.array([0.1, -0.2]), np.array([1.0]))
    """

    def __init__(self, config: IdentifierConfig) -> None:
        if not isinstance(config, IdentifierConfig):
            raise TypeError(f"config: expected an IdentifierConfig, got {type(config).__name__}")
        self._config = config
        self._n, self._m = config.n_states, config.n_inputs
        self._depth = config.max_delay + 1  # rows x(k), x(k-1), .., x(k-l)
        self._q = [np.diag(nr.q_diagonal()) for nr in config.neurons]
        # the ceiling of bounded forgetting: p_trace_max, else trace P_i(0)
        self._ceiling = [nr.p_trace_max if nr.p_trace_max is not None else float(np.trace(nr.p0_matrix()))
                         for nr in config.neurons]
        # neuron i reads its own state down to x_i(k - own_need[i] + 1); 0: not at all
        # (with wait_for_history: down to its deepest tap of any factor, and the runs start at 1)
        self._own_need = [max(((0 if f.kind is FactorKind.ONE else f.delay) + 1 for t in nr.terms for f in t
                               if nr.wait_for_history or f.kind in (FactorKind.S, FactorKind.X) and f.index == i),
                              default=0)
                          for i, nr in enumerate(config.neurons)]
        self._first_run = np.array([1 if nr.wait_for_history else 255 for nr in config.neurons])
        self.reset()

    def reset(self) -> None:
        """Back to w(0), P(0), xhat(0) = x0, empty history; learning on."""
        nrs = self._config.neurons
        self._w = [nr.w0_vector() for nr in nrs]
        self._P = [nr.p0_matrix() for nr in nrs]
        self._xhat = self._config.x0_vector()
        self._z: list[np.ndarray] | None = None  # z(k-1); None before the first step
        self._hist: np.ndarray | None = None  # (depth, n): effective x(k - d) in row d
        self._uhist: np.ndarray | None = None  # (depth, m): u(k - d) in row d
        self._valid_run = np.zeros(self._n, dtype=np.int64)  # samples in a row x_j was measured
        self.learning = True

    @property
    def config(self) -> IdentifierConfig:
        return self._config

    @property
    def learning(self) -> bool:
        return self._learning

    @learning.setter
    def learning(self, on: bool) -> None:
        self._learning = bool(on)

    @property
    def weights(self) -> list[np.ndarray]:
        return [w.copy() for w in self._w]

    @property
    def covariances(self) -> list[np.ndarray]:
        return [p.copy() for p in self._P]

    @property
    def prediction(self) -> np.ndarray:
        return self._xhat.copy()

    def _regressor(self, i: int, hist: np.ndarray, uhist: np.ndarray) -> np.ndarray:
        """z_i(k) of eq. 4 from the effective state and input histories."""
        nr = self._config.neurons[i]
        z = np.ones(nr.n_terms)
        for t, term in enumerate(nr.terms):
            for f in term:
                if f.kind is FactorKind.S:
                    v = activate(nr.activation, nr.beta, hist[f.delay, f.index])
                elif f.kind is FactorKind.X:
                    v = hist[f.delay, f.index]
                elif f.kind is FactorKind.U:
                    v = uhist[f.delay, f.index]
                else:  # FactorKind.ONE
                    continue
                z[t] *= np.float64(v) ** f.power
        return z

    def _learn(self, x: np.ndarray, valid: np.ndarray) -> tuple[list[np.ndarray], list[np.ndarray]]:
        """Eq. 7-9 for every valid neuron; returns new lists, changes nothing."""
        w_new, p_new = list(self._w), list(self._P)
        if self._z is None or not self._learning:
            return w_new, p_new
        for i, nr in enumerate(self._config.neurons):
            if not valid[i] or self._valid_run[i] < self._own_need[i]:
                continue
            H, P = self._z[i], self._P[i]
            e = x[i] - self._xhat[i]  # eq. 9
            g = P @ H
            s = nr.r + H @ g  # 1 / M_i, eq. 8
            if not (np.isfinite(s) and s > 0.0):
                if nr.skip_refused:
                    continue  # only this neuron's update is refused
                raise ValueError(f"neuron {i}: innovation R + z^T P z = {s!r} is not a positive finite number")
            if nr.gate > 0.0 and e * e / s > nr.gate:
                continue  # the innovation gate: an outlier is not learned
            K = g / s  # eq. 7
            # eq. 7 with the windup options: bounded forgetting, P+ / lambda
            # while trace(P+) / lambda stays within the ceiling, + Q, then
            # scaled down to the trace ceiling (lambda = 1, no ceiling: eq. 7)
            p_plus = P - np.outer(g, g) / s
            if nr.forgetting < 1.0 and np.trace(p_plus) / nr.forgetting <= self._ceiling[i]:
                p_plus = p_plus / nr.forgetting
            p_new[i] = p_plus + self._q[i]
            if nr.p_trace_max is not None and np.trace(p_new[i]) > nr.p_trace_max:
                p_new[i] = p_new[i] * (nr.p_trace_max / np.trace(p_new[i]))
            w_new[i] = self._w[i] + nr.eta * e * K  # eq. 7
            refusal = ("updated covariance P is not finite" if not np.all(np.isfinite(p_new[i])) else
                       "updated weights are not finite" if not np.all(np.isfinite(w_new[i])) else "")
            if refusal and nr.skip_refused:
                w_new[i], p_new[i] = self._w[i], self._P[i]  # only this neuron's update is refused
            elif refusal:
                raise ValueError(f"neuron {i}: {refusal}")
        return w_new, p_new

    def step(self, x: np.ndarray, u: np.ndarray | None = None, valid: np.ndarray | None = None) -> np.ndarray:
        """Process sample k: x(k) (n,), u(k) (m,; may be None when m == 0) and
        the validity mask (n,) bool (None: all valid). Returns xhat(k+1).

        Raises ValueError, leaving the identifier unchanged, on bad shapes or
        dtypes, a non-finite valid x_j or any non-finite u_j, a non-positive
        innovation, or non-finite updated P, w or prediction.
        """
        n, m = self._n, self._m
        x = _array("x", x, (n,), "f")
        u = np.empty(0) if u is None and m == 0 else _array("u", u, (m,), "f")
        valid = np.ones(n, dtype=bool) if valid is None else _array("valid", valid, (n,), "b")
        for name, bad in (("x", valid & ~np.isfinite(x)), ("u", ~np.isfinite(u))):
            if bad.any():
                raise ValueError(f"{name}[{int(np.argmax(bad))}]: not finite")
        with np.errstate(all="ignore"):  # overflow is detected explicitly below
            w_new, p_new = self._learn(x, valid)
            x_eff = np.where(valid, x, self._xhat)
            if self._hist is None:  # constant initial history
                hist, uhist = (np.tile(v, (self._depth, 1)) for v in (x_eff, u))
            else:
                hist = np.vstack((x_eff, self._hist[:-1]))
                assert self._uhist is not None  # kept with _hist
                uhist = np.vstack((u, self._uhist[:-1]))
            z = [self._regressor(i, hist, uhist) for i in range(n)]
            xhat = np.array([w_new[i] @ z[i] for i in range(n)])  # eq. 3
        if not np.all(np.isfinite(xhat)):
            raise ValueError(f"neuron {int(np.argmax(~np.isfinite(xhat)))}: prediction is not finite")
        first = self._z is None  # the history was just filled with this sample
        self._w, self._P, self._hist, self._z, self._xhat = w_new, p_new, hist, z, xhat
        self._uhist = uhist
        self._valid_run = np.where(valid, self._first_run if first else np.minimum(self._valid_run + 1, 255), 0)
        return xhat.copy()

    def run(self, X: np.ndarray, U: np.ndarray | None = None, valid: np.ndarray | None = None) -> np.ndarray:
        """``step`` over a trajectory: X (T, n), U (T, m; may be None when
        m == 0), valid (T, n) bool or None. Returns (T, n); row t is the
        prediction made at sample t, i.e. xhat(t+1).

        Like ``rhonn_run``, stops at the first failing step: the ValueError
        says which, and the identifier keeps the state after the steps before.
        """
        n, m = self._n, self._m
        if not isinstance(X, np.ndarray) or X.ndim != 2:
            raise ValueError(f"X: expected a real floating numpy array of shape (T, {n})")
        T = X.shape[0]
        X = _array("X", X, (T, n), "f")
        U = np.empty((T, 0)) if U is None and m == 0 else _array("U", U, (T, m), "f")
        if valid is not None:
            valid = _array("valid", valid, (T, n), "b")
        out = np.empty((T, n))
        for t in range(T):
            try:
                out[t] = self.step(X[t], U[t], None if valid is None else valid[t])
            except ValueError as exc:
                raise ValueError(f"step {t}: {exc} ({t} steps were applied)") from None
        return out
