"""Structure selection: choose each neuron's terms and delays from data.

A user who knows neither the plant's equations nor its delays records the
states and inputs (the CSV of ``pyrhonn identify``), names a candidate
space, and gets an identifier config back. The candidate space is every
product of up to ``degree`` factors among

- ``S(x_j(k-d))``: the activation of state j, d samples ago,
- ``x_j(k-d)``: the raw state,
- ``u_j(k-d)``: an input (d = 0 until the core reads delayed inputs),
- ``1``: the bias,

for the delays d of :attr:`CandidateSpace.delays`. For each neuron i the
terms are chosen by forward orthogonal least squares (FROLS: Billings,
*Nonlinear System Identification: NARMAX Methods in the Time, Frequency,
and Spatio-Temporal Domains*, Wiley 2013, ch. 3) on the one-step targets
x_i(k+1): at every step the candidate with the largest error reduction
ratio

    ERR_c = (p_c'^T y)^2 / (|p_c'|^2 |y|^2),

p_c' the candidate column made orthogonal to the terms already chosen
(modified Gram-Schmidt), joins the model. The path stops where the stopping
rule says (:class:`Criterion`: AIC, BIC or the extended BIC, the default,
on the selection rows, or the one-step error on held-out rows). The activation and its slope beta are
searched over a grid: each neuron keeps the (activation, beta) whose model
scores best.

The work is vectorised: the candidate matrix is built once per (activation,
beta), its columns scaled to unit norm, and each step of every neuron's
path costs one matrix product over it (the projections of the new
orthogonal vectors of all neurons on all candidates). Candidates that have
become linear combinations of the chosen ones (collinear columns, a
constant beside the bias) are never chosen.

Data defects are errors naming the column, option or row (a NaN where a
sample is marked valid, a constant or duplicated column, too few usable
rows for the terms asked for, a candidate space beyond the compiled
capacities); rows whose window holds an invalid sample are left out.
"""
from __future__ import annotations

import enum
import itertools
import math
import time
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
from threadpoolctl import threadpool_limits

from .config import Activation, CovarianceForm, Factor, FactorKind, IdentifierConfig, NeuronConfig, Term
from .configfile import ConfigFile, format_term
from .experiments import window_rows
from .identifier import Identifier, capacities
from .validation import check_int, check_real, fail

__all__ = ["CandidateSpace", "Criterion", "check_capacity", "check_data", "parse_criterion", "NeuronSelection", "Selection", "SelectedTerm", "candidate_terms",
           "input_delays_supported", "select"]

#: The factor kinds a candidate space may use, by their names in the options.
FACTOR_NAMES = {"S": FactorKind.S, "x": FactorKind.X, "u": FactorKind.U, "1": FactorKind.ONE}
#: The largest candidate matrix built (bytes); beyond it the space must shrink.
MAX_MATRIX_BYTES = 4 << 30
#: A candidate whose part orthogonal to the chosen terms is below this
#: fraction of its norm (squared) is taken as their linear combination.
COLLINEAR = 1e-10
#: A path stops once the residual is below this fraction of |y|^2 (an exact
#: fit); AIC and BIC see no residual below it, so that between exact fits
#: (rounding noise) the fewer terms win.
EXACT = 1e-20
#: A path goes on this many steps past its best score before stopping.
PATIENCE = 6


class Criterion(str, enum.Enum):
    """Where a neuron's path stops."""

    AIC = "aic"  #: N ln(sigma^2) + 2 k, on the selection rows
    BIC = "bic"  #: N ln(sigma^2) + k ln N, on the selection rows
    #: N ln(sigma^2) + k (ln N + 2 ln M), the extended BIC of Chen and Chen
    #: (Biometrika 95(3), 2008) with gamma = 1 for M candidates: BIC with the
    #: price of having looked at M candidates for each term, so that among
    #: thousands the best fit to noise is not taken for a term
    EBIC = "ebic"
    HOLDOUT = "holdout"  #: the one-step mean squared error on the held-out rows


def parse_criterion(criterion: Criterion | str) -> Criterion:
    """The :class:`Criterion` a name or member stands for; a ValueError naming ``criterion`` otherwise."""
    try:
        return Criterion(criterion)
    except ValueError:
        raise fail("criterion", f"expected one of {[c.value for c in Criterion]}, got {criterion!r}") from None


def input_delays_supported() -> bool:
    """Whether this pyrhonn's terms take delayed inputs u_j(k-d)."""
    try:
        Factor(FactorKind.U, 0, 1)
    except ValueError:
        return False
    return True


def _input_factor(j: int, d: int) -> Factor:
    return Factor.u(j) if d == 0 else Factor(FactorKind.U, j, d)


@dataclass(frozen=True)
class CandidateSpace:
    """The terms the selection may choose from.

    Parameters
    ----------
    max_delay:
        The deepest state tap: delays 0, ``delay_step``, 2 ``delay_step``, ...
        up to ``max_delay`` samples (and 1 when ``delay_step`` > 1).
    delay_step:
        Spacing of the state taps (>= 1): a long delay at a fine sampling
        period is found with a coarse grid first.
    degree:
        Products of up to this many factors (1..4 and the compiled
        RHONN_MAX_FACTORS); a factor used twice is one factor squared.
    factors:
        The factor kinds, a subset of ``("S", "x", "u", "1")``.
    input_max_delay:
        Input taps u_j(k-d) for d = input_min_delay..input_max_delay; above 0
        only where the core reads delayed inputs (:func:`input_delays_supported`).
    input_min_delay:
        The shallowest input tap: an input dead time of d samples makes the
        taps below d carry nothing, so a search past a dead time need not pay
        for them (0 by default).
    extra_delays:
        State taps beyond the grid above (a state delay found by a scan, far
        deeper than the short taps), none by default.
    activations, betas:
        The grid of S searched: every activation with every beta.
    """

    max_delay: int = 0
    delay_step: int = 1
    degree: int = 2
    factors: tuple[str, ...] = ("S", "u", "1")
    input_max_delay: int = 0
    activations: tuple[Activation, ...] = (Activation.BIPOLAR, Activation.LOGISTIC)
    betas: tuple[float, ...] = (1.0,)
    input_min_delay: int = 0
    extra_delays: tuple[int, ...] = ()

    def __post_init__(self) -> None:
        check_int("max_delay", self.max_delay, 0, 254)
        check_int("delay_step", self.delay_step, 1, 254)
        check_int("degree", self.degree, 1, 4)
        check_int("input_max_delay", self.input_max_delay, 0, 254)
        check_int("input_min_delay", self.input_min_delay, 0, self.input_max_delay)
        if not isinstance(self.extra_delays, tuple):
            raise fail("extra_delays", f"expected a tuple of state delays, got {self.extra_delays!r}")
        for e, d in enumerate(self.extra_delays):
            check_int(f"extra_delays[{e}]", d, 1, 254)
        if not isinstance(self.factors, tuple) or not self.factors:
            raise fail("factors", "expected a non-empty tuple of factor kinds")
        for f, name in enumerate(self.factors):
            if name not in FACTOR_NAMES:
                raise fail(f"factors[{f}]", f"expected one of {list(FACTOR_NAMES)}, got {name!r}")
        if len(set(self.factors)) != len(self.factors):
            raise fail("factors", f"a kind is listed twice: {list(self.factors)}")
        if self.factors == ("1",):
            raise fail("factors", "the bias alone selects nothing; add S, x or u")
        if self.input_max_delay and not input_delays_supported():
            raise fail("input_max_delay", "this pyrhonn's terms take inputs at time k only (u_j(k-d) needs "
                                          "a newer core); use 0")
        if not isinstance(self.activations, tuple) or not self.activations:
            raise fail("activations", "expected a non-empty tuple of Activation")
        for a, act in enumerate(self.activations):
            if not isinstance(act, Activation):
                raise fail(f"activations[{a}]", f"expected an Activation, got {act!r}")
        if not isinstance(self.betas, tuple) or not self.betas:
            raise fail("betas", "expected a non-empty tuple of slopes > 0")
        object.__setattr__(self, "betas", tuple(check_real(f"betas[{b}]", v, positive=True)
                                                for b, v in enumerate(self.betas)))

    @property
    def delays(self) -> tuple[int, ...]:
        """The state taps, ascending."""
        taps = set(range(0, self.max_delay + 1, self.delay_step))
        if self.delay_step > 1 and self.max_delay >= 1:
            taps.add(1)
        return tuple(sorted(taps | set(self.extra_delays)))

    @property
    def window(self) -> int:
        """Samples of history a candidate reads (the deepest tap of any kind)."""
        return max(self.delays[-1], self.input_max_delay if "u" in self.factors else 0)


# An atom: (kind, index, delay); a candidate term is a sorted tuple of atoms (repeats are powers).
_Atom = tuple[FactorKind, int, int]


def _atoms(space: CandidateSpace, n: int, m: int) -> list[_Atom]:
    kinds = {FACTOR_NAMES[name] for name in space.factors}
    atoms: list[_Atom] = []
    for kind in (FactorKind.S, FactorKind.X):
        if kind in kinds:
            atoms += [(kind, j, d) for d in space.delays for j in range(n)]
    if FactorKind.U in kinds:
        atoms += [(FactorKind.U, j, d) for d in range(space.input_min_delay, space.input_max_delay + 1)
                  for j in range(m)]
    return atoms


def _term(atoms: Sequence[_Atom]) -> Term:
    """A product of atoms as a term: repeated atoms become one factor with a power."""
    if not atoms:
        return (Factor.one(),)
    counts: dict[_Atom, int] = {}
    for a in atoms:
        counts[a] = counts.get(a, 0) + 1
    out = []
    for (kind, j, d), p in counts.items():
        out.append(Factor(kind, j, d, p) if kind is not FactorKind.U else
                   Factor(FactorKind.U, j, d, p) if d else Factor.u(j, p))
    return tuple(out)


def _products(space: CandidateSpace, n: int, m: int) -> tuple[list[_Atom], np.ndarray, bool]:
    """The atoms, an (M, degree) table of atom indices per candidate product
    (-1 pads a product of fewer factors), and whether the bias is a candidate."""
    atoms = _atoms(space, n, m)
    rows: list[tuple[int, ...]] = []
    for deg in range(1, space.degree + 1):
        for combo in itertools.combinations_with_replacement(range(len(atoms)), deg):
            rows.append(combo + (-1,) * (space.degree - deg))
    table = np.array(rows, dtype=np.int64).reshape(len(rows), space.degree)
    return atoms, table, "1" in space.factors


def candidate_terms(space: CandidateSpace, n_states: int, n_inputs: int) -> tuple[Term, ...]:
    """Every candidate term of ``space`` for a plant of n states and m inputs,
    in the order of the candidate matrix (the bias last)."""
    atoms, table, bias = _products(space, n_states, n_inputs)
    out = [_term([atoms[a] for a in row if a >= 0]) for row in table]
    return tuple(out) + (((Factor.one(),),) if bias else ())


def _activation(act: Activation, beta: float, x: np.ndarray) -> np.ndarray:
    """S of eq. 6 / eq. 19, as the core computes it."""
    if act is Activation.LOGISTIC:
        return 1.0 / (1.0 + np.exp(-beta * x))
    return np.tanh(0.5 * beta * x)


def _atom_matrix(atoms: list[_Atom], X: np.ndarray, U: np.ndarray, rows: np.ndarray, act: Activation,
                 beta: float) -> np.ndarray:
    """(N, len(atoms) + 1): each atom's value at the regressor rows k, then a column of ones."""
    A = np.empty((rows.size, len(atoms) + 1))
    SX = _activation(act, beta, X)
    for c, (kind, j, d) in enumerate(atoms):
        src = SX if kind is FactorKind.S else X if kind is FactorKind.X else U
        A[:, c] = src[rows - d, j]
    A[:, -1] = 1.0
    return A


def _candidate_matrix(A: np.ndarray, table: np.ndarray, bias: bool) -> np.ndarray:
    """(N, M): each candidate product's column (padding -1 reads the ones column)."""
    N, (M, D) = A.shape[0], table.shape
    P = np.empty((N, M + (1 if bias else 0)))
    block = max(1, (1 << 24) // max(N, 1))  # columns per block: ~128 MB of temporaries at most
    for start in range(0, M, block):
        idx = table[start:start + block]
        out = P[:, start:start + idx.shape[0]]
        np.take(A, idx[:, 0], axis=1, out=out)
        for d in range(1, D):
            out *= A[:, idx[:, d]]
    if bias:
        P[:, -1] = 1.0
    return P


@dataclass
class _Path:
    """One neuron's forward selection path on one candidate matrix."""

    chosen: list[int] = field(default_factory=list)
    err: list[float] = field(default_factory=list)
    R: list[np.ndarray] = field(default_factory=list)  # column k: Q^T p_chosen[k] (length k+1)
    g: list[float] = field(default_factory=list)  # q_k^T y
    score: list[float] = field(default_factory=list)
    Q: list[np.ndarray] = field(default_factory=list)
    done: bool = False

    def best(self) -> int:
        """The number of terms of the best-scoring prefix (>= 1)."""
        return int(np.argmin(self.score)) + 1

    def weights(self, k: int) -> np.ndarray:
        """Least-squares weights of the first k chosen (unit-norm) columns."""
        Rk = np.zeros((k, k))
        for c in range(k):
            Rk[: c + 1, c] = self.R[c]
        return _back_substitute(Rk, np.array(self.g[:k]))


def _back_substitute(R: np.ndarray, g: np.ndarray) -> np.ndarray:
    k = g.size
    theta = np.zeros(k)
    for r in range(k - 1, -1, -1):
        theta[r] = (g[r] - R[r, r + 1:] @ theta[r + 1:]) / R[r, r]
    return theta


def _frols(P: np.ndarray, Y: np.ndarray, max_terms: int, criterion: Criterion,
           P_val: np.ndarray | None, Y_val: np.ndarray | None) -> list[_Path]:
    """Forward orthogonal least squares for every column of Y on the unit-norm
    candidate columns of P, all targets advanced together (one matrix
    product over P per step)."""
    N, M = P.shape
    n = Y.shape[1]
    yy = np.einsum("ij,ij->j", Y, Y)
    proj = (P.T @ Y).T.copy()  # (n, M): p_c'^T y_i
    resid = np.ones((n, M))  # |p_c'|^2 (columns have unit norm)
    usable = np.ones((n, M), dtype=bool)
    r = Y.copy()  # residuals
    paths = [_Path() for _ in range(n)]
    for _ in range(max_terms):
        live = [i for i in range(n) if not paths[i].done]
        if not live:
            break
        Qnew = np.empty((N, len(live)))
        for col, i in enumerate(live):
            path = paths[i]
            ok = usable[i] & (resid[i] > COLLINEAR)
            err = np.where(ok, proj[i] ** 2 / np.where(ok, resid[i], 1.0), -1.0) / max(yy[i], 1e-300)
            c = int(np.argmax(err))
            if err[c] < 0:  # every candidate is chosen or a combination of the chosen
                path.done = True
                Qnew[:, col] = 0.0
                continue
            p = P[:, c]
            q = p.copy()
            coef = np.zeros(len(path.Q) + 1)
            for _pass in range(2):  # modified Gram-Schmidt, twice (reorthogonalisation)
                for t, qt in enumerate(path.Q):
                    a = qt @ q
                    coef[t] += a
                    q -= a * qt
            norm = float(np.linalg.norm(q))
            q /= norm
            coef[-1] = norm
            g = float(q @ Y[:, i])
            r[:, i] -= g * q
            path.chosen.append(c)
            path.err.append(float(err[c]))
            path.R.append(coef)
            path.g.append(g)
            path.Q.append(q)
            usable[i, c] = False
            k = len(path.chosen)
            if criterion is Criterion.HOLDOUT:
                assert P_val is not None and Y_val is not None
                e = Y_val[:, i] - P_val[:, path.chosen] @ path.weights(k)
                path.score.append(_score(criterion, float(e @ e), float(Y_val[:, i] @ Y_val[:, i]), e.size, k, M))
            else:
                path.score.append(_score(criterion, float(r[:, i] @ r[:, i]), float(yy[i]), N, k, M))
            if float(r[:, i] @ r[:, i]) <= EXACT * yy[i] or k - path.best() >= PATIENCE:
                path.done = True
            Qnew[:, col] = q
        A = Qnew.T @ P  # (live, M): the new orthogonal vectors against every candidate
        for col, i in enumerate(live):
            if paths[i].Q and paths[i].Q[-1] is not None and np.any(Qnew[:, col]):
                resid[i] -= A[col] ** 2
                proj[i] -= A[col] * paths[i].g[-1]
    return paths


def _score(criterion: Criterion, rss: float, yy: float, N: int, k: int, M: int) -> float:
    """The score of a k-term fit with residual sum of squares ``rss`` (lower is better)."""
    if criterion is Criterion.HOLDOUT:
        return max(rss, EXACT * yy) / N
    s2 = max(rss, EXACT * yy, 1e-300) / N
    penalty = {Criterion.AIC: 2.0, Criterion.BIC: math.log(N)}.get(criterion, math.log(N) + 2 * math.log(M))
    return N * math.log(s2) + penalty * k


def _fit(P: np.ndarray, y: np.ndarray, chosen: list[int], criterion: Criterion, M: int,
         P_val: np.ndarray | None, y_val: np.ndarray | None) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """The least-squares fit of the chosen columns in their order: ``(score,
    ERR per term, g = Q^T y, R)`` with P[:, chosen] = Q R."""
    Q, R = np.linalg.qr(P[:, chosen])
    g = Q.T @ y
    yy = float(y @ y)
    err = g ** 2 / max(yy, 1e-300)
    if criterion is Criterion.HOLDOUT:
        assert P_val is not None and y_val is not None
        e = y_val - P_val[:, chosen] @ _back_substitute(R, g)
        return _score(criterion, float(e @ e), float(y_val @ y_val), e.size, len(chosen), M), err, g, R
    r = y - Q @ g
    return _score(criterion, float(r @ r), yy, y.size, len(chosen), M), err, g, R


def _prune(P: np.ndarray, y: np.ndarray, chosen: list[int], criterion: Criterion, M: int,
           P_val: np.ndarray | None, y_val: np.ndarray | None) -> list[int]:
    """Backward elimination after the forward path: drop, one at a time, the
    term whose removal scores best while that is no worse than keeping it (a
    term the greedy path took early and later ones made redundant)."""
    chosen = list(chosen)
    current = _fit(P, y, chosen, criterion, M, P_val, y_val)[0]
    yy = float(y @ y)
    while len(chosen) > 1:
        # One QR of the chosen columns serves every removal: with P_S = Q R and g = Q^T y, the fit
        # without column t leaves |y - Q g|^2 + min_w |g - R_{-t} w|^2, a k x (k-1) problem.
        Q, R = np.linalg.qr(P[:, chosen])
        g = Q.T @ y
        r = y - Q @ g
        rss = float(r @ r)
        trials = []
        for t in range(len(chosen)):
            Rt = np.delete(R, t, axis=1)
            w, *_ = np.linalg.lstsq(Rt, g, rcond=None)
            d = g - Rt @ w
            rest = chosen[:t] + chosen[t + 1:]
            if criterion is Criterion.HOLDOUT:
                assert P_val is not None and y_val is not None
                e = y_val - P_val[:, rest] @ w
                trials.append((_score(criterion, float(e @ e), float(y_val @ y_val), e.size, len(rest), M), t))
            else:
                trials.append((_score(criterion, rss + float(d @ d), yy, y.size, len(rest), M), t))
        score, t = min(trials)
        if score > current:
            break
        current = score
        del chosen[t]
    return chosen


@dataclass(frozen=True)
class SelectedTerm:
    """One chosen term, its error reduction ratio and least-squares weight."""

    term: Term
    err: float
    weight: float

    @property
    def text(self) -> str:
        return format_term(self.term)


@dataclass(frozen=True)
class NeuronSelection:
    """Neuron i's model: its terms in the order chosen, with S and the score."""

    state: int
    activation: Activation
    beta: float
    terms: tuple[SelectedTerm, ...]
    score: float
    residual_variance: float
    candidates_tried: int
    #: (Z^T Z)^-1 of the chosen terms' columns (in term order), the least-squares covariance of the
    #: weights per unit residual variance; None where not computed
    covariance: np.ndarray | None = field(default=None, compare=False, repr=False)

    @property
    def err_total(self) -> float:
        return float(sum(t.err for t in self.terms))

    @property
    def delays(self) -> tuple[tuple[int, int], ...]:
        """(state index, delay) of every delayed state factor in the terms, sorted."""
        return tuple(sorted({(f.index, f.delay) for t in self.terms for f in t.term
                             if f.kind in (FactorKind.S, FactorKind.X) and f.delay > 0}))


#: Per dtype, the fit's covariance P0 keeps its eigenvalues above this fraction of the largest (a
#: condition number the core factorises at that precision with room to spare). In float32 these are
#: tried in turn, the first the core accepts kept (see :meth:`Selection.config`).
P0_CONDITION = {"float64": 1e-12, "float32": 1e-6}
P0_CONDITION_FLOAT32 = (1e-12, 1e-10, 1e-8, 1e-6)

#: The covariance form of a fit P0, per dtype: float32 keeps P0 as its U D U^T factors, whose
#: updates cannot lose definiteness to rounding, so the well-determined weight combinations keep
#: their small variances (measured on the cascaded tanks: see :meth:`Selection.config`).
P0_FORM = {"float64": CovarianceForm.FULL, "float32": CovarianceForm.UD}


def _conditioned(P: np.ndarray, floor: float) -> tuple[np.ndarray, float]:
    """``P`` symmetric with the eigenvalues of its correlation matrix floored at ``floor`` times the
    largest, and a lower bound of the result's smallest eigenvalue.

    With D = diag(P)^(1/2) and C = D^-1 P D^-1 (unit diagonal), C's eigenvalues are floored and
    P = D C D rebuilt: the floor is relative to each weight's own variance, so a regressor of small
    magnitude (a cube of a state of order 1e-3, whose weight's variance is huge) does not lift the
    variances of the weights the data determined best. Positive definiteness and the core's
    factorisation depend on C's conditioning, not on the diagonal's spread (Cholesky is invariant to
    diagonal scaling). The bound is lambda_min(C) min_i D_ii^2 (x^T D C D x >= lambda_min(C) |D x|^2),
    which rounding in D C D cannot make negative as an eigenvalue routine can."""
    S = 0.5 * (P + P.T)
    d = np.sqrt(np.abs(np.diag(S)))
    if S.size == 0 or not np.all(np.isfinite(S)) or not np.all(d > 0.0):
        scale = float(np.max(np.abs(np.diag(P)))) if P.size and np.all(np.isfinite(np.diag(P))) else 0.0
        scale = scale if scale > 0.0 else 1e-12
        return np.eye(P.shape[0]) * scale, scale
    C = S / np.outer(d, d)
    lam, V = np.linalg.eigh(0.5 * (C + C.T))
    lam = np.maximum(lam, floor * float(lam[-1]))
    out = ((V * lam) @ V.T) * np.outer(d, d)
    symmetric: np.ndarray = 0.5 * (out + out.T)
    return symmetric, float(lam[0]) * float(np.min(d)) ** 2


@dataclass(frozen=True)
class Selection:
    """The result of :func:`select`: a model per neuron and how it was found."""

    neurons: tuple[NeuronSelection, ...]
    space: CandidateSpace
    criterion: Criterion
    n_states: int
    n_inputs: int
    n_candidates: int
    rows: int
    rows_held_out: int
    rows_dropped: int
    seconds: float

    def state_delays(self) -> tuple[int | None, ...]:
        """The estimated delay of each state: among the delayed taps of x_j in
        every neuron's terms, the one whose terms carry the most ERR (None if
        x_j appears in no delayed term)."""
        weight: dict[tuple[int, int], float] = {}
        for nr in self.neurons:
            for st in nr.terms:
                for f in st.term:
                    if f.kind in (FactorKind.S, FactorKind.X) and f.delay > 0:
                        weight[(f.index, f.delay)] = weight.get((f.index, f.delay), 0.0) + st.err
        out: list[int | None] = []
        for j in range(self.n_states):
            taps = {d: w for (s, d), w in weight.items() if s == j}
            out.append(max(taps, key=lambda d: (taps[d], -d)) if taps else None)
        return tuple(out)

    def config(self, *, p0: float | None = None, q: float | None = None, r: float | None = None,
               dtype: str = "float64", p0_form: str = "fit") -> IdentifierConfig:
        """An identifier with the selected terms, started from their
        least-squares weights (w0). Tuning per neuron unless given: R the
        residual variance sigma^2 of its fit (at least 1e-12); P0 the
        least-squares covariance of the weights,

            P0 = sigma^2 (Z^T Z)^-1,

        Z the rows' regressors (``p0_form="fit"``, the default; its
        eigenvalues floored at :data:`P0_CONDITION` of ``dtype`` times the
        largest, so that the core factorises it), or ``p0_form="scalar"``,
        P0 = R / rows times the identity. Q is the same in every direction,
        the smallest eigenvalue of P0 over the rows (R / rows^2 for the
        scalar form), so that the filter follows slow changes without
        inflating the uncertainty of any direction beyond its size.

        The floor is applied to P0's correlation matrix (each weight's
        variance scaled to 1), not to P0 itself: terms of very different
        magnitudes (a state of order 1e-3 and its cube) give weight variances
        many decades apart, and a floor relative to the largest would lift
        the smallest, those of the weights the data determined best, by
        decades (measured on the Bouc-Wen record of the real-data benchmark:
        learning online then predicted one step ahead far worse than the
        frozen weights; with the floor on the correlations, as well).

        With P0 the fit's own covariance and that small a Q, learning online
        continues the least-squares fit (it is recursive least squares from
        the batch solution): the weights move only where the fit left them
        uncertain, and the well-determined combinations (a pole near 1 of a
        slow plant) stay where the data put them. A P0 of the diagonal
        alone, or a Q of its diagonal, lets a few steps of learning move
        those combinations far beyond their uncertainty, and a model that
        simulated well stops doing so (measured on the cascaded tanks: a
        free run of 0.65 V became 2.5-7.8 V after 20 learning steps; 0.67-0.70
        V with this P0 and Q).

        Each neuron waits for its history (``wait_for_history``): online, it
        learns only from samples whose regressor reads measured values at
        every tap, as the least-squares fit used only such rows.

        In float32 the fit P0 is stored as its U D U^T factors
        (:data:`P0_FORM`) and floored at the first of
        :data:`P0_CONDITION_FLOAT32` the float32 core accepts (float64's
        1e-12 when it factorises it): a floor at float32's own resolution
        (1e-6 of the largest eigenvalue) lifts the smallest variances, of
        the combinations the data determined best, by orders of magnitude,
        and measured on the cascaded tanks 10 learning steps then took the
        free run from 0.42 V to 1.09 V and 100 steps out of range; with the
        factors and float64's floor: 0.42 V after 10 steps, 0.43 V after
        100, 0.50 V after the whole record, as float64.

        Each neuron skips a refused update (``skip_refused``) instead of
        stopping the step: online, one neuron's refusal leaves the others
        learning (measured on the three benchmark records in float64 no
        update is refused, so nothing changes there)."""
        if p0_form not in ("fit", "scalar"):
            raise fail("p0_form", f"expected 'fit' or 'scalar', got {p0_form!r}")
        floors = P0_CONDITION_FLOAT32 if dtype == "float32" else (P0_CONDITION.get(dtype, P0_CONDITION["float32"]),)
        if p0 is not None or p0_form != "fit" or len(floors) == 1:
            return self._config(p0, q, r, dtype, p0_form, floors[0])
        for floor in floors:  # the first floor whose P0 the float32 core factorises
            config = self._config(p0, q, r, dtype, p0_form, floor)
            try:
                Identifier(config)
            except ValueError:
                continue
            return config
        return config

    def _config(self, p0: float | None, q: float | None, r: float | None, dtype: str, p0_form: str,
                floor: float) -> IdentifierConfig:
        """:meth:`config` with the fit P0's eigenvalues floored at ``floor`` of the largest."""
        neurons = []
        for nr in self.neurons:
            terms = tuple(t.term for t in nr.terms)
            rr = max(nr.residual_variance, 1e-12) if r is None else r
            pp: float | np.ndarray
            form = CovarianceForm.FULL
            if p0 is not None:
                pp = p0
            elif p0_form == "fit" and nr.covariance is not None:
                pp, smallest = _conditioned(rr * nr.covariance, floor)
                form = P0_FORM.get(dtype, CovarianceForm.FULL)
            else:
                pp = smallest = rr / max(self.rows, 1)
            if q is not None:
                qq: float = q
            elif isinstance(pp, np.ndarray):  # the eigenvalue routine where it resolves it, else the bound
                qq = max(float(np.linalg.eigvalsh(pp)[0]), smallest) / max(self.rows, 1)
            else:
                qq = smallest / max(self.rows, 1)
            neurons.append(NeuronConfig(terms=terms, activation=nr.activation, beta=nr.beta, p0=pp, q=qq, r=rr,
                                        w0=np.array([t.weight for t in nr.terms]), covariance=form,
                                        wait_for_history=True, skip_refused=True))
        return IdentifierConfig(n_states=self.n_states, n_inputs=self.n_inputs, neurons=tuple(neurons), dtype=dtype)

    def config_file(self, state_names: tuple[str, ...] | None = None, input_names: tuple[str, ...] | None = None,
                    **tuning: float | str | None) -> ConfigFile:
        """:meth:`config` with names, a description of the search and, per
        neuron, its terms with their ERR as the ``why``."""
        sp = self.space
        description = (
            f"Terms selected from data by forward orthogonal least squares (pyrhonn select): "
            f"{self.n_candidates} candidates (products of up to {sp.degree} of {', '.join(sp.factors)}; "
            f"state delays {_ranges(sp.delays)}), criterion {self.criterion.value}, {self.rows} rows"
            + (f" + {self.rows_held_out} held out" if self.rows_held_out else "") + ".")
        why = tuple(f"{nr.activation.value}, beta {nr.beta:g}; ERR " + ", ".join(
            f"{t.text} {t.err:.3g}" for t in nr.terms) + f"; total {nr.err_total:.6f}" for nr in self.neurons)
        return ConfigFile.from_config(self.config(**tuning), state_names=state_names,  # type: ignore[arg-type]
                                      input_names=input_names, description=description, why=why)

    def report(self, state_names: Sequence[str] | None = None) -> str:
        """A readable report: per neuron its terms in order with ERR, then the delays."""
        names = list(state_names) if state_names else [f"x{j + 1}" for j in range(self.n_states)]
        lines = [f"{self.n_candidates} candidates per (activation, beta), {len(self.space.activations)} "
                 f"activations x {len(self.space.betas)} betas; {self.rows} rows for selection"
                 + (f", {self.rows_held_out} held out" if self.rows_held_out else "")
                 + (f", {self.rows_dropped} left out (invalid samples)" if self.rows_dropped else "")
                 + f"; criterion {self.criterion.value}; {self.seconds:.2f} s"]
        for nr in self.neurons:
            lines.append(f"neuron {nr.state + 1} ({names[nr.state]}(k+1)): {len(nr.terms)} terms, "
                         f"{nr.activation.value} beta {nr.beta:g}, ERR total {nr.err_total:.6f}, "
                         f"residual variance {nr.residual_variance:.3g}")
            for rank, t in enumerate(nr.terms, 1):
                lines.append(f"  {rank:2d}. {t.text:32s} ERR {t.err:.6f}  w {t.weight:+.6g}")
            taps = ", ".join(f"x{j + 1}(k-{d})" for j, d in nr.delays) or "none"
            lines.append(f"  delayed taps: {taps}")
        est = self.state_delays()
        lines.append("estimated delay per state: " + ", ".join(
            f"{names[j]} {'-' if d is None else d}" for j, d in enumerate(est)))
        return "\n".join(lines)


def _ranges(values: Sequence[int]) -> str:
    vs = list(values)
    if len(vs) > 2 and all(b - a == vs[1] - vs[0] for a, b in zip(vs, vs[1:])):
        return f"{vs[0]}..{vs[-1]}" + (f" step {vs[1] - vs[0]}" if vs[1] - vs[0] != 1 else "")
    return ", ".join(str(v) for v in vs)


def check_capacity(space: CandidateSpace, n: int, m: int, max_terms: int) -> None:
    caps = capacities()

    def over(option: str, value: int, cap: str) -> None:
        if value > caps[cap]:
            raise fail(option, f"{value} exceeds the compiled capacity {cap} = {caps[cap]} "
                               "(pyrhonn info; the README says how to build with larger capacities)")

    over("n_states", n, "RHONN_MAX_STATES")
    over("n_inputs", m, "RHONN_MAX_INPUTS")
    over("max_terms", max_terms, "RHONN_MAX_TERMS")
    over("degree", space.degree, "RHONN_MAX_FACTORS")
    over("degree", space.degree, "RHONN_MAX_POWER")
    over("max_delay", space.delays[-1], "RHONN_MAX_DELAY")
    over("input_max_delay", space.input_max_delay, "RHONN_MAX_DELAY")


def _check_data(X: np.ndarray, U: np.ndarray, valid: np.ndarray, state_names: Sequence[str],
                input_names: Sequence[str]) -> None:
    """Every state and input column varies and no two are the same up to scale and offset."""
    cols = [(X[valid[:, j], j], f"state column {state_names[j]!r}") for j in range(X.shape[1])]
    cols += [(U[:, j], f"input column {input_names[j]!r}") for j in range(U.shape[1])]
    for values, what in cols:
        if values.size and np.ptp(values) <= 1e-12 * max(1.0, float(np.max(np.abs(values)))):
            raise ValueError(f"{what}: constant ({float(values[0]):g} on every valid line): it carries no "
                             "information; leave it out")
    both = valid.all(axis=1)
    Z = np.hstack([X[both], U[both]])
    if Z.shape[0] > 2:
        Zc = Z - Z.mean(axis=0)
        Zc /= np.linalg.norm(Zc, axis=0)
        corr = Zc.T @ Zc
        names = [f"state column {s!r}" for s in state_names] + [f"input column {s!r}" for s in input_names]
        for a, b in zip(*np.triu_indices(Z.shape[1], 1)):
            if abs(corr[a, b]) > 1.0 - 1e-12:
                raise ValueError(f"{names[b]}: the same as {names[a]} up to scale and offset (correlation "
                                 f"{corr[a, b]:.12f}): collinear columns cannot be told apart; leave one out")


def check_data(X: np.ndarray, U: np.ndarray, valid: np.ndarray, state_names: Sequence[str],
               input_names: Sequence[str], first_line: np.ndarray | None = None) -> None:
    """The checks :func:`select` makes of a recording before any work: every
    valid state and every input finite (the error names the line, from
    ``first_line``, or the row), no column constant, no two alike."""
    snames, inames = state_names, input_names

    def where(k: int) -> str:
        return f"line {int(first_line[k])}" if first_line is not None else f"row {k}"

    bad = np.argwhere(~np.isfinite(X) & valid)
    if bad.size:
        k, j = (int(v) for v in bad[0])
        raise ValueError(f"X: {where(k)}, {snames[j]}: not finite ({X[k, j]!r}) but marked valid")
    bad = np.argwhere(~np.isfinite(U))
    if bad.size:
        k, j = (int(v) for v in bad[0])
        raise ValueError(f"U: {where(k)}, {inames[j]}: not finite ({U[k, j]!r}); inputs must be given on every line")
    _check_data(X, U, valid, snames, inames)


def _select_paths(space: CandidateSpace, crit: Criterion, X: np.ndarray, U: np.ndarray, Y: np.ndarray,
                  Y_val: np.ndarray | None, atoms: list[_Atom], table: np.ndarray, bias: bool, est_rows: np.ndarray,
                  val_rows: np.ndarray, n_val: int, max_terms: int, M: int, terms: tuple[Term, ...],
                  n: int) -> list[NeuronSelection | None]:
    """Every neuron's best model over the grid of (activation, beta): the core of :func:`select`."""
    best: list[NeuronSelection | None] = [None] * n
    for act in space.activations:
        betas = space.betas if "S" in space.factors else space.betas[:1]
        for beta in betas:
            A = _atom_matrix(atoms, X, U, est_rows, act, beta)
            P = _candidate_matrix(A, table, bias)
            norms = np.linalg.norm(P, axis=0)
            dead = norms <= 1e-300
            scale = np.where(dead, 1.0, norms)
            P /= scale
            P_val = None
            if n_val:
                P_val = _candidate_matrix(_atom_matrix(atoms, X, U, val_rows, act, beta), table, bias) / scale
            paths = _frols(P, Y, max_terms, crit, P_val, Y_val)
            for i, path in enumerate(paths):
                if not path.chosen:
                    continue
                chosen = _prune(P, Y[:, i], path.chosen[: path.best()], crit, M,
                                P_val, None if Y_val is None else Y_val[:, i])
                score, err, g, R = _fit(P, Y[:, i], chosen, crit, M, P_val,
                                        None if Y_val is None else Y_val[:, i])
                w = _back_substitute(R, g) / scale[chosen]
                resid = Y[:, i] - (P[:, chosen] * scale[chosen]) @ w
                Rinv = np.linalg.solve(R, np.eye(R.shape[0])) / scale[chosen][:, None]  # Z = P_c diag(scale)
                cand = NeuronSelection(
                    state=i, activation=act, beta=beta,
                    terms=tuple(SelectedTerm(terms[c], float(e), float(wt)) for c, e, wt in zip(chosen, err, w)),
                    score=score, residual_variance=float(resid @ resid) / resid.size, candidates_tried=M,
                    covariance=Rinv @ Rinv.T)
                if best[i] is None or cand.score < best[i].score:  # type: ignore[union-attr]
                    best[i] = cand
            del P, P_val
    return best


def select(
    X: np.ndarray,
    U: np.ndarray | None = None,
    valid: np.ndarray | None = None,
    *,
    space: CandidateSpace | None = None,
    criterion: Criterion | str = Criterion.EBIC,
    max_terms: int = 16,
    holdout: float = 0.2,
    state_names: Sequence[str] | None = None,
    input_names: Sequence[str] | None = None,
    first_line: np.ndarray | None = None,
    starts: Sequence[int] = (),
) -> Selection:
    """Select every neuron's terms from a recorded trajectory.

    ``X`` (T, n) and ``U`` (T, m) float64 in time order; ``valid`` (T, n)
    bool marks measured samples (a NaN is allowed only where it is False).
    Regressor rows k read samples k - window .. k + 1; a row whose window
    holds an invalid sample is left out. With ``criterion="holdout"`` the
    last ``holdout`` fraction of the rows scores each path and the rest
    selects; AIC, BIC and EBIC select and score on all rows. ``state_names`` /
    ``input_names`` name columns in errors; ``first_line`` (T,), the file
    line of each sample, names lines. ``starts``: the samples where a new
    experiment begins when several recordings are merged into one X (as
    MATLAB's ``merge`` of ``iddata``): no regressor row reads across one, so
    each experiment is its own trajectory.
    """
    t0 = time.perf_counter()
    space = CandidateSpace() if space is None else space
    if not isinstance(space, CandidateSpace):
        raise fail("space", f"expected a CandidateSpace, got {type(space).__name__}")
    crit = parse_criterion(criterion)
    if not isinstance(X, np.ndarray) or X.ndim != 2 or X.dtype != np.float64:
        raise fail("X", "expected a (T, n) float64 numpy array")
    T, n = X.shape
    if U is None:
        U = np.zeros((T, 0))
    if not isinstance(U, np.ndarray) or U.dtype != np.float64 or U.shape[:1] != (T,) or U.ndim != 2:
        raise fail("U", f"expected a ({T}, m) float64 numpy array")
    m = U.shape[1]
    if valid is None:
        valid = np.ones((T, n), dtype=bool)
    if not isinstance(valid, np.ndarray) or valid.dtype != np.bool_ or valid.shape != (T, n):
        raise fail("valid", f"expected a ({T}, {n}) bool numpy array")
    max_terms = check_int("max_terms", max_terms, 1, 255)
    snames = tuple(state_names) if state_names else tuple(f"x{j + 1}" for j in range(n))
    inames = tuple(input_names) if input_names else tuple(f"u{j + 1}" for j in range(m))

    check_data(X, U, valid, snames, inames, first_line)
    if "u" in space.factors and m == 0:
        raise fail("factors", "'u' asks for input factors but the data has no inputs")
    check_capacity(space, n, m, max_terms)

    W = space.window
    starts = [check_int(f"starts[{e}]", b, 1, T - 1) for e, b in enumerate(starts)]
    rows = window_rows(valid, W, starts=starts)
    dropped = int(max(T - 1 - W, 0) - rows.size)
    n_val = int(round(holdout * rows.size)) if crit is Criterion.HOLDOUT else 0
    if crit is Criterion.HOLDOUT and not 0.0 < holdout < 1.0:
        raise fail("holdout", f"expected a fraction in (0, 1), got {holdout!r}")
    est_rows, val_rows = rows[: rows.size - n_val], rows[rows.size - n_val:]
    need = max(4 * max_terms, 20)
    if est_rows.size < need:
        raise ValueError(
            f"data: {est_rows.size} usable rows for selection ({T} samples, less the {W} of the deepest delay, "
            f"the last, {dropped} with invalid samples" + (f", {n_val} held out" if n_val else "")
            + f") but max_terms = {max_terms} needs at least {need}: record longer, or lower "
              "max_terms or max_delay")
    if crit is Criterion.HOLDOUT and val_rows.size < 10:
        raise fail("holdout", f"{val_rows.size} held-out rows; at least 10 are needed")
    atoms, table, bias = _products(space, n, m)
    M = table.shape[0] + int(bias)
    if est_rows.size * M * 8 > MAX_MATRIX_BYTES:
        raise ValueError(f"degree: {M} candidates x {est_rows.size} rows would take "
                         f"{est_rows.size * M * 8 / 2**30:.1f} GiB (at most {MAX_MATRIX_BYTES / 2**30:.0f}): lower "
                         "degree or max_delay, raise delay_step, or drop a factor kind")
    Y = X[est_rows + 1]
    Y_val = X[val_rows + 1] if n_val else None
    terms = candidate_terms(space, n, m)
    with threadpool_limits(limits=1, user_api="blas"):  # many small QRs: threads only wait (see search)
        best = _select_paths(space, crit, X, U, Y, Y_val, atoms, table, bias, est_rows, val_rows, n_val, max_terms,
                             M, terms, n)
    for i, nr in enumerate(best):
        if nr is None:
            raise ValueError(f"{snames[i]}: no candidate explains any of x{i + 1}(k+1) (every column is zero)")
    return Selection(neurons=tuple(best), space=space, criterion=crit, n_states=n,  # type: ignore[arg-type]
                     n_inputs=m, n_candidates=M, rows=int(est_rows.size), rows_held_out=n_val,
                     rows_dropped=dropped, seconds=time.perf_counter() - t0)
