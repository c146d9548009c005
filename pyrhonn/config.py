"""Identifier configuration: validated, immutable dataclasses.

A configuration says, for each neuron i (one per state, eq. 3), which
high-order terms z_i it uses (eq. 4), its activation S (eq. 6 or eq. 19) and
slope beta, and the EKF tuning of eq. 7-8: P_i(0), Q_i, R_i and eta_i.

Every constructor validates its arguments and raises ``ValueError`` whose
message starts with the path of the offending field, e.g.
``neurons[2].terms[1][0].index: state index 5 out of range 0..3``. Nothing is
coerced silently: arrays must already have the documented shape, and numbers
must be real and finite.
"""
from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np

from .validation import check_array, check_int, check_real, fail

__all__ = [
    "Activation",
    "DTYPES",
    "Factor",
    "FactorKind",
    "IdentifierConfig",
    "NeuronConfig",
    "Term",
]

DTYPES = ("float64", "float32")


class FactorKind(enum.IntEnum):
    """What one factor of a high-order term reads (values match the C enum)."""

    S = 0  #: S(x_j(k - d)), the activation of a (delayed) state
    X = 1  #: x_j(k - d), the raw (delayed) state
    U = 2  #: u_j(k - d), an external input, delayed by the input's dead time
    ONE = 3  #: the constant 1 (a bias term)


class Activation(str, enum.Enum):
    """Activation S of a neuron (values match the C enum by position)."""

    LOGISTIC = "logistic"  #: S(s) = 1 / (1 + exp(-beta s)), eq. 6
    BIPOLAR = "bipolar"  #: S(s) = (1 - exp(-beta s)) / (1 + exp(-beta s)), eq. 19

    @property
    def code(self) -> int:
        return 0 if self is Activation.LOGISTIC else 1


class CovarianceForm(str, enum.Enum):
    """How the core stores and updates a neuron's P_i (``rhonn_covariance_form``)."""

    FULL = "full"  #: P_i itself, eq. 7 as written, positive definiteness checked after each update
    UD = "ud"  #: P_i = U D U^T, Bierman's update then Agee-Turner rank-one updates for + Q: definite by construction

    @property
    def code(self) -> int:
        return 0 if self is CovarianceForm.FULL else 1


@dataclass(frozen=True)
class Factor:
    """One factor xi^d of a high-order term (eq. 4).

    Build factors with the class methods: ``Factor.s(j)`` for S(x_j(k)),
    ``Factor.s(j, delay=3)`` for S(x_j(k-3)), ``Factor.x(j)`` for the raw
    state, ``Factor.u(j)`` for an input, ``Factor.u(j, delay=2)`` for
    u_j(k-2) (an input dead time), ``Factor.one()`` for a bias.
    Ranges of ``index`` are checked against the identifier by
    :class:`IdentifierConfig`.
    """

    kind: FactorKind
    index: int = 0
    delay: int = 0
    power: int = 1

    def __post_init__(self) -> None:
        if not isinstance(self.kind, FactorKind):
            raise fail("kind", f"expected a FactorKind, got {self.kind!r}")
        check_int("index", self.index, 0, 254)
        check_int("delay", self.delay, 0, 254)
        check_int("power", self.power, 1, 255)
        if self.kind is FactorKind.ONE and self.delay != 0:
            raise fail("delay", f"a ONE factor has no delay, got {self.delay}")
        if self.kind is FactorKind.ONE and self.index != 0:
            raise fail("index", f"a ONE factor has index 0, got {self.index}")

    @classmethod
    def s(cls, state: int, delay: int = 0, power: int = 1) -> Factor:
        return cls(FactorKind.S, state, delay, power)

    @classmethod
    def x(cls, state: int, delay: int = 0, power: int = 1) -> Factor:
        return cls(FactorKind.X, state, delay, power)

    @classmethod
    def u(cls, input_index: int, power: int = 1, delay: int = 0) -> Factor:
        return cls(FactorKind.U, input_index, delay, power)

    @classmethod
    def one(cls) -> Factor:
        return cls(FactorKind.ONE)

    def __str__(self) -> str:
        if self.kind is FactorKind.ONE:
            return "1"
        name = {FactorKind.S: "S(x{j}{d})", FactorKind.X: "x{j}{d}", FactorKind.U: "u{j}{d}"}[self.kind]
        d = f"(k-{self.delay})" if self.delay else ""
        text = name.format(j=self.index + 1, d=d)
        return text if self.power == 1 else f"{text}^{self.power}"

    def to_dict(self) -> dict[str, Any]:
        return {"kind": self.kind.name, "index": self.index, "delay": self.delay, "power": self.power}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], path: str = "factor") -> Factor:
        if not isinstance(data, Mapping):
            raise fail(path, f"expected a table, got {type(data).__name__}")
        unknown = set(data) - {"kind", "index", "delay", "power"}
        if unknown:
            raise fail(path, f"unknown keys {sorted(unknown)}")
        kind_name = data.get("kind")
        if not isinstance(kind_name, str) or kind_name.upper() not in FactorKind.__members__:
            raise fail(f"{path}.kind", f"expected one of {list(FactorKind.__members__)}, got {kind_name!r}")
        try:
            return cls(FactorKind[kind_name.upper()], data.get("index", 0), data.get("delay", 0), data.get("power", 1))
        except ValueError as exc:
            raise fail(path, str(exc)) from None


Term = tuple[Factor, ...]
"""A high-order term z_ij: the product of its factors (eq. 4)."""


def _real_list(path: str, value: list[Any] | tuple[Any, ...]) -> np.ndarray:
    """A (nested) list of real numbers as a float64 array; None, bools,
    strings and ragged rows are refused, not converted (np.array would turn
    None into NaN and "1" into 1.0)."""
    try:
        a = np.array(value, dtype=object)
    except ValueError:
        raise fail(path, "expected a list of numbers (or of equal-length lists of numbers)") from None
    for idx, v in np.ndenumerate(a):
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            where = path + "".join(f"[{i}]" for i in idx)
            raise fail(where, f"expected a real number, got {type(v).__name__} {v!r}"[:200])
    try:
        return a.astype(np.float64)
    except OverflowError:
        raise fail(path, "out of the float64 range (an integer beyond 1.8e308)") from None


def monomial(term: Term) -> frozenset[tuple[Any, ...]]:
    """The product a term stands for, as {(kind, index, delay): power}: the
    same for S(x1)*S(x2) and S(x2)*S(x1), for S(x1)^2 and S(x1)*S(x1), and
    with ONE factors dropped (a bias alone is the empty product)."""
    powers: dict[tuple[Any, ...], int] = {}
    for fac in term:
        if fac.kind is not FactorKind.ONE:
            key = (fac.kind.value, fac.index, fac.delay)
            powers[key] = powers.get(key, 0) + fac.power
    return frozenset(powers.items())


@dataclass(frozen=True, eq=False)
class NeuronConfig:
    """One neuron: its terms and the EKF tuning of eq. 7-8.

    Parameters
    ----------
    terms:
        The L_i high-order terms, each a non-empty tuple of :class:`Factor`.
    activation, beta:
        S of eq. 6 (logistic) or eq. 19 (bipolar) and its slope beta > 0.
    p0:
        P_i(0): a scalar (times the identity, as the paper's eq. 20), a
        vector of L_i diagonal entries, or a full symmetric L_i x L_i matrix.
    q:
        Q_i: a scalar (times the identity) or the L_i diagonal entries, >= 0.
    r:
        R_i > 0, the scalar measurement-noise variance of eq. 8.
    eta:
        eta_i > 0, the learning rate of eq. 7.
    w0:
        w_i(0), L_i entries; zeros when None.
    covariance:
        How P_i is stored and updated: :attr:`CovarianceForm.FULL` (eq. 7 as
        written) or :attr:`CovarianceForm.UD` (the same filter on the factors
        P_i = U D U^T, which cannot lose positive definiteness to rounding;
        about (2/3) L_i^3 more multiply-adds per step). Either way a step whose
        P_i(k+1) is not positive definite at the working precision is refused.
    forgetting:
        lambda in (0, 1]: 1 (the default) is eq. 7; below 1, old information
        fades geometrically, up to a ceiling c_i on the trace (``p_trace_max``
        when set, else trace P_i(0)). With P+ = P_i - K_i z^T P_i::

            P_i <- P+ / lambda + Q_i    when trace(P+) / lambda <= c_i
            P_i <- P+ + Q_i             otherwise (eq. 7)

        so a quiet stretch, where z visits few directions, grows P_i only
        until it is as uncertain as it started, not without bound.
    p_trace_max:
        None (the default) or a ceiling on trace P_i, at least trace P_i(0): a
        P_i(k+1) above it is scaled down to it, so a long stretch without
        excitation (where Q_i piles up) cannot build an unbounded gain.
    reset_after:
        0 (the default) or N >= 1: the N-th refused learning update in a row
        resets P_i to P_i(0) instead (weights kept) and the step goes on.
    gate:
        0 (the default: off) or a threshold >= 0 on the normalised innovation
        squared: an update with ``e_i^2 / s_i > gate``, where
        ``e_i = x_i(k) - xhat_i(k)`` (eq. 9) and ``s_i = R_i + z^T P_i z``
        (eq. 8), is skipped (w_i and P_i unchanged, the step goes on) and
        counted in :attr:`~pyrhonn.identifier.NeuronHealth.gated`. e^2/s is
        chi-square with 1 degree of freedom for a consistent filter: 9 skips
        0.27 % of good samples, so an outlier is not learned.
    skip_refused:
        False (the default): a refused learning update of this neuron (its
        P_i(k+1) not positive definite or not finite, its weights not
        finite) refuses the whole step, which changes nothing and raises.
        True: only this neuron's update is skipped (w_i and P_i kept, the
        refusal counted in :attr:`~pyrhonn.identifier.NeuronHealth.rejected`),
        the other neurons learn and the step goes on; with ``reset_after``
        the N-th refusal in a row still resets P_i, inside
        :meth:`~pyrhonn.identifier.Identifier.run` as well. For records that
        must not stop the identifier.
    wait_for_history:
        False (the default): the neuron learns from the second sample after
        construction, reset or restart on, its delayed taps reading the
        constant history before the first sample (the paper's initial
        function). True: it learns only once every tap of its regressor
        (any factor's delay, states and inputs) reads a measured sample,
        from sample D_i + 1 on (D_i its deepest delay), and after a dropout
        of its own state once it has been measured D_i + 1 samples in a row.
        A model fitted offline on measured histories is then not taught the
        padded start of a record.
    """

    terms: tuple[Term, ...]
    activation: Activation = Activation.LOGISTIC
    beta: float = 1.0
    p0: float | np.ndarray = 1.0
    q: float | np.ndarray = 0.0
    r: float = 1.0
    eta: float = 1.0
    w0: np.ndarray | None = None
    covariance: CovarianceForm = CovarianceForm.FULL
    forgetting: float = 1.0
    p_trace_max: float | None = None
    reset_after: int = 0
    gate: float = 0.0
    skip_refused: bool = False
    wait_for_history: bool = False

    def __post_init__(self) -> None:
        if not isinstance(self.terms, tuple) or not self.terms:
            raise fail("terms", "expected a non-empty tuple of terms")
        for t, term in enumerate(self.terms):
            if not isinstance(term, tuple) or not term:
                raise fail(f"terms[{t}]", "expected a non-empty tuple of Factor")
            for f, fac in enumerate(term):
                if not isinstance(fac, Factor):
                    raise fail(f"terms[{t}][{f}]", f"expected a Factor, got {type(fac).__name__}")
        seen: dict[frozenset[tuple[Any, ...]], int] = {}
        for t, term in enumerate(self.terms):
            first = seen.setdefault(monomial(term), t)
            if first != t:  # the same z_ij twice: two weights on one regressor, a typo more than a choice
                raise fail(f"terms[{t}]", f"the same product as terms[{first}] (factor order, ONE factors and "
                                          "split powers do not make a different term)")
        if not isinstance(self.activation, Activation):
            raise fail("activation", f"expected an Activation, got {self.activation!r}")
        check_real("beta", self.beta, positive=True)
        check_real("r", self.r, positive=True)
        check_real("eta", self.eta, positive=True)
        L = len(self.terms)
        if isinstance(self.p0, np.ndarray):
            if self.p0.ndim == 1:
                d = check_array("p0", self.p0, (L,))
                if not np.all(d > 0):
                    raise fail(f"p0[{int(np.argmin(d > 0))}]", "diagonal entries must be > 0")
                object.__setattr__(self, "p0", d)
            else:
                full = check_array("p0", self.p0, (L, L))
                if not np.array_equal(full, full.T):
                    raise fail("p0", "matrix must be symmetric")
                diag = np.diag(full)
                if not np.all(diag > 0):
                    raise fail(f"p0[{int(np.argmin(diag > 0))}][{int(np.argmin(diag > 0))}]",
                                "diagonal entries must be > 0")
                try:  # P_i(0) is a covariance (eq. 10): positive definite, not only symmetric
                    np.linalg.cholesky(full)
                except np.linalg.LinAlgError:
                    raise fail("p0", "matrix must be positive definite (smallest eigenvalue "
                                     f"{float(np.linalg.eigvalsh(full)[0]):.3g})") from None
                object.__setattr__(self, "p0", full)
        else:
            object.__setattr__(self, "p0", check_real("p0", self.p0, positive=True))
        if isinstance(self.q, np.ndarray):
            qd = check_array("q", self.q, (L,))
            if not np.all(qd >= 0):
                raise fail(f"q[{int(np.argmin(qd >= 0))}]", "entries must be >= 0")
            object.__setattr__(self, "q", qd)
        else:
            object.__setattr__(self, "q", check_real("q", self.q, nonnegative=True))
        if self.w0 is not None:
            object.__setattr__(self, "w0", check_array("w0", self.w0, (L,)))
        for name in ("beta", "r", "eta"):
            object.__setattr__(self, name, float(getattr(self, name)))
        if not isinstance(self.covariance, CovarianceForm):
            raise fail("covariance", f"expected a CovarianceForm, got {self.covariance!r}")
        lam = check_real("forgetting", self.forgetting, positive=True)
        if lam > 1.0:
            raise fail("forgetting", f"lambda must be in (0, 1] (1 = no forgetting), got {lam!r}")
        object.__setattr__(self, "forgetting", lam)
        if self.p_trace_max is not None:
            ceiling = check_real("p_trace_max", self.p_trace_max, positive=True)
            trace0 = float(np.trace(self.p0_matrix()))
            if ceiling < trace0:
                raise fail("p_trace_max", f"{ceiling!r} is below trace P0 = {trace0:.6g}: the bound would "
                                          "shrink the starting covariance")
            object.__setattr__(self, "p_trace_max", ceiling)
        object.__setattr__(self, "reset_after", check_int("reset_after", self.reset_after, 0, 65535))
        object.__setattr__(self, "gate", check_real("gate", self.gate, nonnegative=True))
        if not isinstance(self.skip_refused, (bool, np.bool_)):
            raise fail("skip_refused", f"expected True or False, got {self.skip_refused!r}")
        object.__setattr__(self, "skip_refused", bool(self.skip_refused))
        if not isinstance(self.wait_for_history, (bool, np.bool_)):
            raise fail("wait_for_history", f"expected True or False, got {self.wait_for_history!r}")
        object.__setattr__(self, "wait_for_history", bool(self.wait_for_history))

    def __eq__(self, other: object) -> bool:
        return isinstance(other, NeuronConfig) and self.to_dict() == other.to_dict()

    __hash__ = None  # type: ignore[assignment]

    @property
    def n_terms(self) -> int:
        return len(self.terms)

    def p0_matrix(self) -> np.ndarray:
        """P_i(0) as a full L_i x L_i float64 matrix."""
        L = self.n_terms
        if isinstance(self.p0, np.ndarray):
            return np.diag(self.p0) if self.p0.ndim == 1 else self.p0.copy()
        return float(self.p0) * np.eye(L)

    def q_diagonal(self) -> np.ndarray:
        """diag(Q_i) as a float64 vector of L_i entries."""
        if isinstance(self.q, np.ndarray):
            return self.q.copy()
        return np.full(self.n_terms, float(self.q))

    def w0_vector(self) -> np.ndarray:
        """w_i(0) as a float64 vector of L_i entries."""
        return np.zeros(self.n_terms) if self.w0 is None else self.w0.copy()

    def describe(self) -> list[str]:
        """The terms as readable products, e.g. ``S(x1)*u1^2``."""
        return ["*".join(str(f) for f in term) for term in self.terms]

    def to_dict(self) -> dict[str, Any]:
        def arr(v: float | np.ndarray) -> Any:
            return v.tolist() if isinstance(v, np.ndarray) else v

        return {
            "terms": [[f.to_dict() for f in term] for term in self.terms],
            "activation": self.activation.value,
            "beta": self.beta,
            "p0": arr(self.p0),
            "q": arr(self.q),
            "r": self.r,
            "eta": self.eta,
            "w0": None if self.w0 is None else self.w0.tolist(),
            "covariance": self.covariance.value,
            "forgetting": self.forgetting,
            "p_trace_max": self.p_trace_max,
            "reset_after": self.reset_after,
            "gate": self.gate,
            "skip_refused": self.skip_refused,
            "wait_for_history": self.wait_for_history,
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], path: str = "neuron") -> NeuronConfig:
        if not isinstance(data, Mapping):
            raise fail(path, f"expected a table, got {type(data).__name__}")
        known = {"terms", "activation", "beta", "p0", "q", "r", "eta", "w0", "covariance", "forgetting",
                 "p_trace_max", "reset_after", "gate", "skip_refused", "wait_for_history"}
        unknown = set(data) - known
        if unknown:
            raise fail(path, f"unknown keys {sorted(unknown)}")
        raw_terms = data.get("terms")
        if not isinstance(raw_terms, Sequence) or isinstance(raw_terms, str):
            raise fail(f"{path}.terms", "expected a list of terms")
        terms = []
        for t, raw in enumerate(raw_terms):
            if not isinstance(raw, Sequence) or isinstance(raw, str):
                raise fail(f"{path}.terms[{t}]", "expected a list of factors")
            terms.append(tuple(Factor.from_dict(f, f"{path}.terms[{t}][{i}]") for i, f in enumerate(raw)))
        act = data.get("activation", Activation.LOGISTIC.value)
        try:
            activation = Activation(act)
        except ValueError:
            raise fail(f"{path}.activation", f"expected one of {[a.value for a in Activation]}, got {act!r}") from None

        def num_or_array(key: str, default: Any) -> Any:
            v = data.get(key, default)
            return _real_list(f"{path}.{key}", v) if isinstance(v, (list, tuple)) else v

        p0, q, w0 = num_or_array("p0", 1.0), num_or_array("q", 0.0), num_or_array("w0", None)
        form = data.get("covariance", CovarianceForm.FULL.value)
        try:
            covariance = CovarianceForm(form)
        except ValueError:
            raise fail(f"{path}.covariance", f"expected one of {[c.value for c in CovarianceForm]}, "
                                             f"got {form!r}") from None
        try:
            return cls(terms=tuple(terms), activation=activation, beta=data.get("beta", 1.0), p0=p0, q=q,
                       r=data.get("r", 1.0), eta=data.get("eta", 1.0), w0=w0, covariance=covariance,
                       forgetting=data.get("forgetting", 1.0), p_trace_max=data.get("p_trace_max"),
                       reset_after=data.get("reset_after", 0), gate=data.get("gate", 0.0),
                       skip_refused=data.get("skip_refused", False),
                       wait_for_history=data.get("wait_for_history", False))
        except ValueError as exc:  # "p0[1]: ..." from the checks: the field, under this neuron's path
            raise ValueError(f"{path}.{exc}") from None


@dataclass(frozen=True, eq=False)
class IdentifierConfig:
    """A whole identifier: n neurons for n states, m inputs, one dtype.

    ``x0`` is xhat(0), which stands in for a state whose measurement is
    invalid on the very first step (zeros when None). ``dtype`` selects the
    float64 or float32 build of the C core.
    """

    n_states: int
    n_inputs: int
    neurons: tuple[NeuronConfig, ...]
    dtype: str = "float64"
    x0: np.ndarray | None = None

    def __post_init__(self) -> None:
        n = check_int("n_states", self.n_states, 1, 255)
        m = check_int("n_inputs", self.n_inputs, 0, 255)
        if not isinstance(self.dtype, str) or self.dtype not in DTYPES:  # np.dtype("float32") == "float32"
            raise fail("dtype", f"expected one of {DTYPES} as a str, got {type(self.dtype).__name__} {self.dtype!r}")
        if not isinstance(self.neurons, tuple):
            raise fail("neurons", f"expected a tuple of NeuronConfig, got {type(self.neurons).__name__}")
        if len(self.neurons) != n:
            raise fail("neurons", f"expected one neuron per state ({n}), got {len(self.neurons)}")
        for i, neuron in enumerate(self.neurons):
            if not isinstance(neuron, NeuronConfig):
                raise fail(f"neurons[{i}]", f"expected a NeuronConfig, got {type(neuron).__name__}")
            for t, term in enumerate(neuron.terms):
                for f, fac in enumerate(term):
                    where = f"neurons[{i}].terms[{t}][{f}].index"
                    if fac.kind in (FactorKind.S, FactorKind.X) and fac.index >= n:
                        raise fail(where, f"state index {fac.index} out of range 0..{n - 1}")
                    if fac.kind is FactorKind.U and fac.index >= m:
                        raise fail(where, f"input index {fac.index} out of range 0..{m - 1}"
                                    if m else f"input index {fac.index} but the identifier has no inputs")
        if self.x0 is not None:
            object.__setattr__(self, "x0", check_array("x0", self.x0, (n,)))
        object.__setattr__(self, "n_states", n)
        object.__setattr__(self, "n_inputs", m)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, IdentifierConfig) and self.to_dict() == other.to_dict()

    __hash__ = None  # type: ignore[assignment]

    @property
    def max_delay(self) -> int:
        return max((f.delay for nr in self.neurons for t in nr.terms for f in t), default=0)

    def x0_vector(self) -> np.ndarray:
        return np.zeros(self.n_states) if self.x0 is None else self.x0.copy()

    def replace(self, **changes: Any) -> IdentifierConfig:
        """A copy with some fields changed (validated again)."""
        data = {k: getattr(self, k) for k in ("n_states", "n_inputs", "neurons", "dtype", "x0")}
        data.update(changes)
        return IdentifierConfig(**data)

    @classmethod
    def uniform(
        cls,
        terms: Sequence[Term] | Sequence[Sequence[Term]],
        *,
        n_states: int,
        n_inputs: int,
        dtype: str = "float64",
        **neuron_kwargs: Any,
    ) -> IdentifierConfig:
        """Every neuron with the same tuning. ``terms`` is either one term
        list shared by all neurons or a list of n_states term lists."""
        check_int("n_states", n_states, 1, 255)
        if terms and isinstance(terms[0], tuple) and terms[0] and isinstance(terms[0][0], Factor):
            per = [tuple(terms)] * n_states
        else:
            per = [tuple(ts) for ts in terms]  # type: ignore[arg-type]
        neurons = tuple(NeuronConfig(terms=t, **neuron_kwargs) for t in per)  # type: ignore[arg-type]
        return cls(n_states=n_states, n_inputs=n_inputs, neurons=neurons, dtype=dtype)

    def to_dict(self) -> dict[str, Any]:
        return {
            "n_states": self.n_states,
            "n_inputs": self.n_inputs,
            "dtype": self.dtype,
            "x0": None if self.x0 is None else self.x0.tolist(),
            "neurons": [nr.to_dict() for nr in self.neurons],
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> IdentifierConfig:
        if not isinstance(data, Mapping):
            raise fail("config", f"expected a table, got {type(data).__name__}")
        unknown = set(data) - {"n_states", "n_inputs", "dtype", "x0", "neurons"}
        if unknown:
            raise fail("config", f"unknown keys {sorted(unknown)}")
        for key in ("n_states", "n_inputs", "neurons"):
            if key not in data:
                raise fail(key, "missing")
        raw = data["neurons"]
        if not isinstance(raw, Sequence) or isinstance(raw, str):
            raise fail("neurons", "expected a list of neuron tables")
        neurons = tuple(NeuronConfig.from_dict(nr, f"neurons[{i}]") for i, nr in enumerate(raw))
        x0 = data.get("x0")
        if x0 is not None:
            if not isinstance(x0, (list, tuple)):
                raise fail("x0", "expected a list of numbers")
            x0 = _real_list("x0", x0)
        return cls(n_states=data["n_states"], n_inputs=data["n_inputs"], neurons=neurons,
                   dtype=data.get("dtype", "float64"), x0=x0)
