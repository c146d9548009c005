"""The HONN observer of the paper's section 6.1.1 (eq. 16-19), design of reference [20].

Described, with the source and status of every value, in
docs/plants.md#honn-observer.

This is the baseline the paper compares its RHONN identifier against on
Example 1 (Tables 1-4). It sees only the outputs y = C x and the input u.

Math (paper eq. 16-17; symbols as in the paper)
-----------------------------------------------

Assumed discrete-time plant (n states, p outputs, m inputs):

.. math::

    x(k+1) = A x(k) + B [f(x(k), u(k)) + h(x(k-d))] + D u(k), \\qquad y(k) = C x(k)

Observer (eq. 16) and weight law (eq. 17):

.. math::

    \\hat x(k+1) = A \\hat x(k)
        + B [\\hat W_1^\\top(k) \\Phi_1(\\hat x(k), u(k)) + h(\\hat x(k - \\hat d))]
        + K [y(k) - \\hat y(k)] + D u(k), \\qquad \\hat y(k) = C \\hat x(k)

    \\hat W_1(k+1) = (1 - \\sigma_1) \\hat W_1(k)
        + \\Gamma_1 \\Phi_1(\\hat x(k), u(k)) \\tilde y^\\top(k) F^\\top,
        \\qquad \\tilde y(k) = y(k) - \\hat y(k)

Shapes: A (n, n), B (n, q), C (p, n), K (n, p), D (n, m), F (q, p),
W1 (l1, q), Phi1 (l1,), Gamma1 (l1, l1), h: R^n -> R^q. For the paper q = n = 4,
p = 2, m = 1, l1 = 16.

Basis Phi1 (the paper gives l1 = 16 but not the terms): with
z = [x̂_1 .. x̂_n, u_1 .. u_m] (5 entries for Example 1) and the bipolar sigmoid
of eq. 19, sigma(s) = (1 - exp(-beta s)) / (1 + exp(-beta s)), beta = 0.01,

.. math::

    \\Phi_1 = [\\,(1),\\ \\sigma(z_1), \\dots, \\sigma(z_5),\\
              \\sigma(z_i)\\sigma(z_j)\\ (i < j)\\,]

The leading constant (1) is included only with ``basis_bias=True``: that
gives 1 + 5 + 10 = 16 functions, the paper's l1. The default leaves
it out (5 + 10 = 15 functions); see choice 6 below for why. ``l1`` is derived
from the basis when None, and checked against it when given.

Paper values (the defaults of :class:`HonnObserverParams`, except l1)
---------------------------------------------------------------------
A = I + T A_c with A_c the chain x1' = x2, x3' = x4 (the printed A has T = 0.2;
rebuilt for any T), B = I4, C = [[1,1,0,0],[0,0,1,1]] (the OCR prints C^T),
D = 0, K = [[0.3,0],[1,0],[0,0.3],[0,1]], F = ones(4,2), Gamma1 = 0.2 I16,
sigma1 = 0.6, l1 = 16 (15 by default here: choice 6), beta = 0.01,
d̂ = 3.2 s (the true delay is d = 3 s), x̂(0) = 0, W1(0) = 0 (W1(0) is not printed: PROPOSED). The known delay
functions, eq. 18 with the OCR's second "h_3" read as h_4:

.. math::

    h_1 = 0,\\quad h_2(x) = 2\\cos x_1,\\quad h_3 = 0,\\quad
    h_4(x) = 2 (x_1^2 + x_2^2) \\sin x_2

Choices on the paper's ambiguities (docs/plants.md#honn-observer-readings)
--------------------------------------------------------------------------
1. **Weight law driven by the output error.** The OCR of eq. 17 prints
   ŷ^T(k); an observer's learning law is driven by ỹ = y - ŷ (otherwise the
   weights would learn from the estimate alone, even when it is exact), so ŷ
   is read as a typo for ỹ.
2. **h carries the factor T (``h_times_dt=True``, the default).** Eq. 18's
   functions are literally the continuous-time delayed terms of eq. 15
   (2 cos x1(t-3) in x2', 2(x1^2+x2^2) sin x2(t-3) in x4'). The observer's
   A = I + T A_c is the forward-Euler discretisation of the same model, in
   which every right-hand-side term, including the delayed one, is multiplied
   by T: x(k+1) ≈ x(k) + T [A_c x(k) + f_c + h_c(x(k-d))]. So the discrete h of
   eq. 16 is T * h_c. Without the factor the delayed term would be 5x too
   large at T = 0.2 s and 50x at T = 0.02 s, relative to the plant it models.
   ``h_times_dt=False`` uses eq. 18 unscaled, the literal reading.
3. **d̂ in samples.** d̂ = 3.2 s is 16 samples at T = 0.2 s and 160 at
   T = 0.02 s (the true 3 s: 15 and 150). ``d_hat`` must be a whole number of
   sampling periods (ValueError otherwise, no silent rounding).
4. **Pre-history.** Before the start the observer has no estimates; it uses
   x̂(j) = x̂(0) for j < 0 (the constant-history convention of the plant), so
   h(x̂(k - d̂)) = h(x̂(0)) for k < d̂.
5. **K is not rebuilt for T = 0.02 s** (only A is): the paper prints one K.
   With this K the error dynamics A - KC have eigenvalues {0.82, -0.12} per
   output block at T = 0.2 s but {0.984, -0.284} at T = 0.02 s, i.e. a slow
   mode at the smaller period.
6. **No constant in Phi1 by default (``basis_bias=False``, l1 = 15).** With
   the constant (the 16-term basis) and the paper's Gamma1 = 0.2,
   sigma1 = 0.6, F = ones(4, 2), the constant's weights become a leaky
   integrator of the output error, W1^T Phi1 ≈ (0.2 / 0.6) (ỹ_1 + ỹ_2) per
   state, which F = ones feeds into all four states. The channel-2 error
   (large, from x4) then reaches x̂1, x̂2, which h_4 = 2 (x̂1^2 + x̂2^2) sin x̂2
   amplifies quadratically through the delay: on Example 1 at T = 0.2 s over
   100 s the estimate grows to ~1e145 (|x̂| > 100 from about k = 356), and even
   over the first 20-50 s its RMSE is 1-4 per state, an order of magnitude
   above the paper's Table 1 observer row. Without the constant the observer
   stays bounded and lands near Table 1 on x1, x2. Kosmatopoulos-type HONNs
   (the family of [20]) are built from products of sigmoids without a free
   constant (RECALLED, not checked against [20]), so this reading is also
   the more literal one; the 15 functions are every sigma(z_j) and every
   distinct pair sigma(z_i) sigma(z_j). The price, stated plainly:
   with beta = 0.01 every bipolar basis function is below ~0.06 in magnitude
   on this plant, so the HONN term stays small (measured over 100 s: max
   |W1^T Phi1| ≈ 0.022 at T = 0.2 s and 0.001 at 0.02 s; the estimates stay
   within 0.06 of those with Gamma1 -> 0) and this observer behaves
   essentially as the Luenberger observer A - KC plus the known delay term
   T h(x̂(k - d̂)). ``basis_bias=True`` restores the 16-term reading.

Alignment with the identifier
-----------------------------
:meth:`HonnObserver.run` returns rows x̂(k), k = 0..T-1: row 0 is x̂(0) (the
initial estimate), row k is computed from y(0..k-1), u(0..k-1). The
identifier's ``run`` returns at row k the prediction x̂(k+1) made from data up
to k. So both estimate x(k) from data up to k-1 (one-step-ahead), and:

- the paper's "all samples" metric of the observer is
  ``metrics.rmse(traj.X, obs)`` (the row-0 mismatch x(0) - x̂(0) included);
- the identifier's is ``metrics.rmse(traj.X[1:], ident[:-1])``;
- on the common targets x(1)..x(T-1) use :func:`common_targets`:
  ``X, obs_c, ident_c = common_targets(traj.X, obs, ident)``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from ..plants.trajectory import Trajectory
from ..validation import check_array, check_data, check_real, fail

__all__ = [
    "HonnObserver",
    "HonnObserverParams",
    "basis",
    "basis_size",
    "bipolar",
    "chain_matrix",
    "common_targets",
    "observe_oscillator",
    "paper_delay_functions",
]

DelayFunction = Callable[[np.ndarray], np.ndarray]


def chain_matrix(dt: float) -> np.ndarray:
    """The paper's A for sampling period ``dt``: I4 + dt * chain (x1' = x2, x3' = x4)."""
    dt = check_real("dt", dt, positive=True)
    A = np.eye(4)
    A[0, 1] = A[2, 3] = dt
    return A


def paper_delay_functions(x: np.ndarray) -> np.ndarray:
    """Eq. 18 (with h_3 -> h_4 fixed): [0, 2 cos x1, 0, 2 (x1^2 + x2^2) sin x2], shape (4,).

    ``x`` is the (delayed) state estimate x̂(k - d̂); these are the
    continuous-time delayed terms of eq. 15, without the factor T.
    """
    x1, x2 = float(x[0]), float(x[1])
    return np.array([0.0, 2.0 * math.cos(x1), 0.0, 2.0 * (x1 * x1 + x2 * x2) * math.sin(x2)])


def bipolar(s: np.ndarray, beta: float) -> np.ndarray:
    """Eq. 19: (1 - exp(-beta s)) / (1 + exp(-beta s)) = tanh(beta s / 2)."""
    return np.tanh(0.5 * beta * s)


def basis_size(n_z: int, *, bias: bool = False, products: bool = True) -> int:
    """l1 for a basis over ``n_z`` = n + m signals: bias + linear + pairwise products."""
    return int(bias) + n_z + (n_z * (n_z - 1) // 2 if products else 0)


def basis(x_hat: np.ndarray, u: np.ndarray, beta: float, *, bias: bool = False, products: bool = True) -> np.ndarray:
    """Phi1(x̂, u): [(1 if bias), sigma(z_j), sigma(z_i) sigma(z_j) (i < j, row-major)] with z = [x̂, u]."""
    s = bipolar(np.concatenate((x_hat, u)), beta)
    parts = [np.ones(1)] if bias else []
    parts.append(s)
    if products:
        i, j = np.triu_indices(s.shape[0], 1)
        parts.append(s[i] * s[j])
    return np.concatenate(parts)


def _default_K() -> np.ndarray:
    return np.array([[0.3, 0.0], [1.0, 0.0], [0.0, 0.3], [0.0, 1.0]])


@dataclass(frozen=True, eq=False)
class HonnObserverParams:
    """Parameters of the HONN observer (eq. 16-19); the defaults are the paper's,
    except the basis (no constant term, so l1 = 15: module docstring, choice 6).

    Every field is validated; a bad value raises ``ValueError`` whose message
    starts with the field name. Arrays are stored as read-only float64 copies
    and must already have the documented shape (nothing is reshaped).

    dt:
        Sampling period T, s (paper: 0.2 and 0.02).
    A:
        (n, n) state matrix; None builds the paper's chain I + T A_c for ``dt``.
    B:
        (n, q) matrix in front of [W1^T Phi1 + h]; paper I4.
    C:
        (p, n) output matrix; paper [[1,1,0,0],[0,0,1,1]].
    D:
        (n, m) input matrix; paper 0 (shape (4, 1)). Its column count fixes m.
    K:
        (n, p) observer gain; paper [[0.3,0],[1,0],[0,0.3],[0,1]].
    F:
        (q, p) design matrix of the weight law; paper ones(4, 2).
    Gamma1:
        Learning gain, a scalar gamma > 0 meaning gamma * I_l1 (paper 0.2), or a
        symmetric positive-definite (l1, l1) matrix.
    sigma1:
        Leakage in [0, 1] (paper 0.6): the weights shrink by (1 - sigma1) per step.
    l1:
        Number of basis functions; None (default) takes the basis length
        implied by n + m, ``basis_bias`` and ``basis_products`` (15 by
        default; the paper's 16 with ``basis_bias=True``), an int is checked
        against it.
    beta:
        Slope of the bipolar activation, eq. 19 (paper 0.01).
    d_hat:
        Delay estimate d̂ in seconds (paper 3.2; true delay 3); a whole
        number >= 0 of periods ``dt``.
    h:
        Known delay functions h: (n,) -> (q,), evaluated at x̂(k - d̂); default
        eq. 18 (:func:`paper_delay_functions`).
    h_times_dt:
        Multiply h by T (default True: the Euler-consistent reading, see the
        module docstring); False uses h as given.
    x0_hat:
        (n,) initial estimate x̂(0), also the pre-history; paper zeros.
    W0:
        (l1, q) initial weights W1(0); None means zeros (PROPOSED).
    basis_bias:
        Include the constant 1 in Phi1 (default False; True gives the paper's
        l1 = 16 with a 16-term basis, which diverges at its gains on Example 1
        at T = 0.2 s: module docstring, choice 6).
    basis_products:
        Include the pairwise products sigma(z_i) sigma(z_j), i < j (default True).
    """

    dt: float = 0.2
    A: np.ndarray | None = None
    B: np.ndarray = field(default_factory=lambda: np.eye(4))
    C: np.ndarray = field(default_factory=lambda: np.array([[1.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 1.0]]))
    D: np.ndarray = field(default_factory=lambda: np.zeros((4, 1)))
    K: np.ndarray = field(default_factory=_default_K)
    F: np.ndarray = field(default_factory=lambda: np.ones((4, 2)))
    Gamma1: float | np.ndarray = 0.2
    sigma1: float = 0.6
    l1: int | None = None
    beta: float = 0.01
    d_hat: float = 3.2
    h: DelayFunction | None = paper_delay_functions
    h_times_dt: bool = True
    x0_hat: np.ndarray = field(default_factory=lambda: np.zeros(4))
    W0: np.ndarray | None = None
    basis_bias: bool = False
    basis_products: bool = True

    def __post_init__(self) -> None:
        put = lambda name, value: object.__setattr__(self, name, value)  # noqa: E731
        dt = check_real("dt", self.dt, positive=True)
        put("dt", dt)
        # A fixes n
        if self.A is None:
            put("A", check_array("A", chain_matrix(dt), (4, 4)))
        else:
            if not isinstance(self.A, np.ndarray) or self.A.ndim != 2 or self.A.shape[0] != self.A.shape[1] \
                    or self.A.shape[0] < 1:
                got: object = self.A.shape if isinstance(self.A, np.ndarray) else type(self.A).__name__
                raise fail("A", f"expected a square numpy array (n, n), got {got}")
            put("A", check_array("A", self.A, self.A.shape))
        assert self.A is not None  # set above
        n = self.A.shape[0]
        for name in ("B", "C", "D"):
            if not isinstance(getattr(self, name), np.ndarray) or getattr(self, name).ndim != 2:
                v = getattr(self, name)
                got = v.shape if isinstance(v, np.ndarray) else type(v).__name__
                raise fail(name, f"expected a 2-D numpy array, got {got}")
        q = self.B.shape[1]
        p = self.C.shape[0]
        m = self.D.shape[1]
        if q < 1:
            raise fail("B", f"expected shape ({n}, q) with q >= 1, got {self.B.shape}")
        if p < 1:
            raise fail("C", f"expected shape (p, {n}) with p >= 1, got {self.C.shape}")
        put("B", check_array("B", self.B, (n, q)))
        put("C", check_array("C", self.C, (p, n)))
        put("D", check_array("D", self.D, (n, m)))
        put("K", check_array("K", self.K, (n, p)))
        put("F", check_array("F", self.F, (q, p)))
        for name in ("h_times_dt", "basis_bias", "basis_products"):
            if not isinstance(getattr(self, name), bool):
                raise fail(name, f"expected a bool, got {type(getattr(self, name)).__name__}")
        expected = basis_size(n + m, bias=self.basis_bias, products=self.basis_products)
        if self.l1 is None:
            object.__setattr__(self, "l1", expected)
        if isinstance(self.l1, bool) or not isinstance(self.l1, (int, np.integer)):
            raise fail("l1", f"expected an integer or None, got {type(self.l1).__name__} {self.l1!r}")
        if int(self.l1) != expected:
            raise fail("l1", f"the basis over n + m = {n + m} signals (bias={self.basis_bias}, "
                              f"products={self.basis_products}) has {expected} functions, got l1 = {self.l1}")
        l1 = int(self.l1)
        put("l1", l1)
        if isinstance(self.Gamma1, np.ndarray):
            G = check_array("Gamma1", self.Gamma1, (l1, l1))
            if not np.allclose(G, G.T, rtol=0.0, atol=1e-12 * max(1.0, float(np.max(np.abs(G))))):
                raise fail("Gamma1", "must be symmetric")
            if np.min(np.linalg.eigvalsh(G)) <= 0.0:
                raise fail("Gamma1", "must be positive definite")
        else:
            g = check_real("Gamma1", self.Gamma1, positive=True)
            G = g * np.eye(l1)
            G.setflags(write=False)
        put("Gamma1", G)
        sigma1 = check_real("sigma1", self.sigma1)
        if not 0.0 <= sigma1 <= 1.0:
            raise fail("sigma1", f"must be in [0, 1], got {sigma1!r}")
        put("sigma1", sigma1)
        put("beta", check_real("beta", self.beta, positive=True))
        d_hat = check_real("d_hat", self.d_hat, nonnegative=True)
        ratio = d_hat / dt
        if abs(ratio - round(ratio)) > 1e-9 * max(1.0, ratio):
            raise fail("d_hat", f"{d_hat!r} s is not a whole number of sampling periods dt = {dt!r} s")
        put("d_hat", d_hat)
        put("x0_hat", check_array("x0_hat", self.x0_hat, (n,)))
        if self.W0 is None:
            W0 = np.zeros((l1, q))
            W0.setflags(write=False)
            put("W0", W0)
        else:
            put("W0", check_array("W0", self.W0, (l1, q)))
        if self.h is not None:
            if not callable(self.h):
                raise fail("h", f"expected a callable (n,) -> (q,) or None, got {type(self.h).__name__}")
            probe = self.h(self.x0_hat.copy())
            if not isinstance(probe, np.ndarray) or probe.shape != (q,) or probe.dtype.kind not in "fiu":
                got = f"{probe.dtype} {probe.shape}" if isinstance(probe, np.ndarray) else type(probe).__name__
                raise fail("h", f"must return a real numpy array of shape ({q},), got {got}")

    # -- derived sizes ---------------------------------------------------------------
    @property
    def n(self) -> int:
        """Number of states."""
        return int(self.A.shape[0])  # type: ignore[union-attr]

    @property
    def p(self) -> int:
        """Number of outputs."""
        return int(self.C.shape[0])

    @property
    def m(self) -> int:
        """Number of inputs."""
        return int(self.D.shape[1])

    @property
    def q(self) -> int:
        """Width of B (rows of W1^T Phi1 and of h)."""
        return int(self.B.shape[1])

    @property
    def delay_samples(self) -> int:
        """d̂ in samples, d_hat / dt (16 for the paper at T = 0.2 s, 160 at 0.02 s)."""
        return int(round(self.d_hat / self.dt))

    def to_dict(self) -> dict[str, Any]:
        """A JSON-friendly summary (h by name)."""
        h = None if self.h is None else getattr(self.h, "__qualname__", repr(self.h))
        return {
            "dt": self.dt, "A": self.A.tolist(), "B": self.B.tolist(),  # type: ignore[union-attr]
            "C": self.C.tolist(), "D": self.D.tolist(), "K": self.K.tolist(), "F": self.F.tolist(),
            "Gamma1": self.Gamma1.tolist(), "sigma1": self.sigma1, "l1": self.l1,  # type: ignore[union-attr]
            "beta": self.beta, "d_hat": self.d_hat, "delay_samples": self.delay_samples, "h": h,
            "h_times_dt": self.h_times_dt, "x0_hat": self.x0_hat.tolist(),
            "W0": self.W0.tolist(), "basis_bias": self.basis_bias,  # type: ignore[union-attr]
            "basis_products": self.basis_products,
        }


class HonnObserver:
    """The HONN observer of eq. 16-17, stepped one sample at a time or over a run.

    State: the sample index k, the current estimate x̂(k), the weights W1(k)
    and the past estimates x̂(k - d̂) .. x̂(k) (x̂(j) = x̂(0) for j < 0).

    ``step(y(k), u(k))`` returns x̂(k+1); ``run(Y, U)`` returns the rows
    x̂(k0), ..., x̂(k0 + T - 1) for the current k0 (0 after construction or
    :meth:`reset`), i.e. row k is the estimate *before* y(k) is used. See the
    module docstring for aligning these with the identifier's predictions.
    """

    def __init__(self, params: HonnObserverParams | None = None) -> None:
        if params is None:
            params = HonnObserverParams()
        if not isinstance(params, HonnObserverParams):
            raise ValueError(f"params: expected HonnObserverParams, got {type(params).__name__}")
        self._p = params
        self._leak = 1.0 - params.sigma1
        self._h_gain = params.dt if params.h_times_dt else 1.0
        self.reset()

    # -- state -----------------------------------------------------------------------
    def reset(self) -> None:
        """Back to k = 0, x̂(0) = x0_hat, W1(0) = W0, constant pre-history x̂(0)."""
        p = self._p
        self._k = 0
        self._x = p.x0_hat.copy()
        self._W = p.W0.copy()  # type: ignore[union-attr]
        self._hist = np.tile(p.x0_hat, (p.delay_samples + 1, 1))  # x̂(j) at row j mod (d̂ + 1)

    @property
    def params(self) -> HonnObserverParams:
        return self._p

    @property
    def k(self) -> int:
        """Index of the current estimate x̂(k)."""
        return self._k

    @property
    def estimate(self) -> np.ndarray:
        """x̂(k), the current estimate (a copy)."""
        return self._x.copy()

    @property
    def weights(self) -> np.ndarray:
        """W1(k), (l1, q) (a copy)."""
        return self._W.copy()

    def delayed_estimate(self) -> np.ndarray:
        """x̂(k - d̂), the argument of h in the next step (x̂(0) while k < d̂), a copy."""
        return self._hist[(self._k + 1) % self._hist.shape[0]].copy()

    def regressor(self, u: np.ndarray) -> np.ndarray:
        """Phi1(x̂(k), u) for the current estimate, (l1,)."""
        u = check_data("u", u, (self._p.m,))
        return self._phi(self._x, u)

    def _phi(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        p = self._p
        return basis(x, u, p.beta, bias=p.basis_bias, products=p.basis_products)

    # -- stepping --------------------------------------------------------------------
    def _advance(self, y: np.ndarray, u: np.ndarray) -> np.ndarray:
        """One step on validated data; returns x̂(k+1) and updates the state."""
        p = self._p
        x = self._x
        y_err = y - p.C @ x  # ỹ(k) = y(k) - C x̂(k)
        phi = self._phi(x, u)  # Phi1(x̂(k), u(k))
        drive = self._W.T @ phi  # W1^T(k) Phi1
        if p.h is not None:
            x_del = self._hist[(self._k + 1) % self._hist.shape[0]]  # x̂(k - d̂)
            hv = p.h(x_del.copy())
            if not isinstance(hv, np.ndarray) or hv.shape != (p.q,):
                got = hv.shape if isinstance(hv, np.ndarray) else type(hv).__name__
                raise ValueError(f"h: must return a numpy array of shape ({p.q},), got {got}")
            drive = drive + self._h_gain * hv
        x_next = p.A @ x + p.B @ drive + p.K @ y_err + p.D @ u
        if not np.all(np.isfinite(x_next)):
            raise FloatingPointError(f"observer estimate x̂({self._k + 1}) is not finite")
        # eq. 17: W1(k+1) = (1 - sigma1) W1(k) + Gamma1 Phi1 ỹ^T F^T
        self._W = self._leak * self._W + np.outer(p.Gamma1 @ phi, p.F @ y_err)
        self._k += 1
        self._hist[self._k % self._hist.shape[0]] = x_next
        self._x = x_next
        return x_next

    def step(self, y: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Use y(k) (p,) and u(k) (m,), float64 and finite; return x̂(k+1) (a new array)."""
        p = self._p
        y = check_data("y", y, (p.p,))
        u = check_data("u", u, (p.m,))
        state = self._save()
        try:
            with np.errstate(over="ignore", invalid="ignore"):  # a non-finite x̂ raises below
                return self._advance(y, u).copy()
        except BaseException:
            self._restore(state)
            raise

    def run(self, Y: np.ndarray, U: np.ndarray) -> np.ndarray:
        """Outputs Y (T, p) and inputs U (T, m), float64 and finite; returns (T, n).

        Row i of the result is x̂(k0 + i), the estimate held *before* y(k0 + i)
        is used (row 0 after construction is x̂(0) = x0_hat). After the call
        the observer holds x̂(k0 + T) (:attr:`estimate`). On any error
        (bad data, non-finite estimate, h failing) the observer is unchanged.
        """
        p = self._p
        if not isinstance(Y, np.ndarray) or Y.ndim != 2:
            got = Y.shape if isinstance(Y, np.ndarray) else type(Y).__name__
            raise ValueError(f"Y: expected a float64 numpy array of shape (T, {p.p}), got {got}")
        T = Y.shape[0]
        Y = check_data("Y", Y, (T, p.p))
        U = check_data("U", U, (T, p.m))
        out = np.empty((T, p.n))
        state = self._save()
        try:
            with np.errstate(over="ignore", invalid="ignore"):  # a non-finite x̂ raises in _advance
                for k in range(T):
                    out[k] = self._x
                    self._advance(Y[k], U[k])
        except BaseException:
            self._restore(state)
            raise
        return out

    def _save(self) -> tuple[int, np.ndarray, np.ndarray, np.ndarray]:
        return self._k, self._x.copy(), self._W.copy(), self._hist.copy()

    def _restore(self, state: tuple[int, np.ndarray, np.ndarray, np.ndarray]) -> None:
        self._k, self._x, self._W, self._hist = state


def common_targets(truth: np.ndarray, observer: np.ndarray,
                   identifier: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Align observer rows (x̂(k)) and identifier rows (x̂(k+1)) on the targets x(1)..x(T-1).

    ``truth``, ``observer`` and ``identifier`` are (T, n) with the conventions
    of :meth:`HonnObserver.run` and ``Identifier.run``. Returns
    ``(truth[1:], observer[1:], identifier[:-1])``: row k of each now refers
    to x(k+1), and both estimates used data up to sample k only. Pass the
    pairs to :mod:`pyrhonn.metrics`.
    """
    for name, a in (("truth", truth), ("observer", observer), ("identifier", identifier)):
        if not isinstance(a, np.ndarray) or a.ndim != 2:
            got = a.shape if isinstance(a, np.ndarray) else type(a).__name__
            raise ValueError(f"{name}: expected a numpy array of shape (T, n), got {got}")
    if observer.shape != truth.shape:
        raise ValueError(f"observer: shape {observer.shape} differs from truth shape {truth.shape}")
    if identifier.shape != truth.shape:
        raise ValueError(f"identifier: shape {identifier.shape} differs from truth shape {truth.shape}")
    if truth.shape[0] < 2:
        raise ValueError(f"truth: needs at least 2 samples, got {truth.shape[0]}")
    return truth[1:], observer[1:], identifier[:-1]


def observe_oscillator(traj: Trajectory, params: HonnObserverParams | None = None, *,
                       measured: bool = False) -> np.ndarray:
    """Run the observer on an Example 1 trajectory; (T, 4) rows x̂(k), k = 0..T-1.

    The outputs are y(k) = C x(k) from the trajectory's true states ``traj.X``
    (``measured=True``: from ``traj.X_meas``, e.g. with noise; it must then be
    finite), the input is ``traj.U``. ``params`` defaults to the paper's
    values at ``traj.dt``; given params must have ``dt == traj.dt``.
    """
    if not isinstance(traj, Trajectory):
        raise ValueError(f"traj: expected a pyrhonn.plants Trajectory, got {type(traj).__name__}")
    if traj.n_states != 4 or traj.n_inputs != 1:
        raise ValueError(f"traj: expected Example 1 (4 states, 1 input), got {traj.n_states} states, "
                         f"{traj.n_inputs} inputs")
    if not isinstance(measured, bool):
        raise ValueError(f"measured: expected a bool, got {type(measured).__name__}")
    if params is None:
        params = HonnObserverParams(dt=traj.dt)
    elif not isinstance(params, HonnObserverParams):
        raise ValueError(f"params: expected HonnObserverParams or None, got {type(params).__name__}")
    elif abs(params.dt - traj.dt) > 1e-12 * traj.dt:
        raise ValueError(f"params.dt: {params.dt!r} differs from the trajectory's dt = {traj.dt!r}")
    if params.n != 4 or params.m != 1:
        raise ValueError(f"params: expected n = 4 states and m = 1 input, got n = {params.n}, m = {params.m}")
    X = traj.X_meas if measured else traj.X
    if measured and not np.all(np.isfinite(X)):
        k, j = (int(i) for i in np.argwhere(~np.isfinite(X))[0])
        raise ValueError(f"traj.X_meas[{k}, {j}]: must be finite to form y = C x")
    Y = X @ params.C.T
    return HonnObserver(params).run(Y, traj.U)
