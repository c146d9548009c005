"""The RHONN identifier, running the C core through cffi.

Math (Alanis et al., eq. 3-9), for neuron i = 1..n with L_i weights:

.. math::

    \\hat x_i(k+1) = w_i^\\top z_i(x(k), x(k-1), \\dots, u(k))          \\quad (3)

    z_{ij} = \\prod_{f \\in I_j} \\xi_f^{d_f}, \\quad
    \\xi = [S(x_1) \\dots S(x_n), u_1 \\dots u_m]                       \\quad (4, 5)

    e_i(k) = x_i(k) - \\hat x_i(k)                                      \\quad (9)

    M_i = (R_i + H_i^\\top P_i H_i)^{-1}, \\quad K_i = P_i H_i M_i      \\quad (8, 7)

    w_i \\leftarrow w_i + \\eta_i K_i e_i, \\quad
    P_i \\leftarrow P_i - K_i H_i^\\top P_i + Q_i                      \\quad (7)

with H_i = z_i (eq. 11; the network is linear in its weights). One
:meth:`Identifier.step` learns from e(k) with the regressor z(k-1) that
produced x̂(k), then forms z(k) and returns x̂(k+1); see ``csrc/include/rhonn.h``
for the exact ordering, the dropout rule and the initial history.
"""
from __future__ import annotations

import functools
import threading
import weakref
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import Any, Callable, TypeVar

import numpy as np

from . import _rhonn_f32, _rhonn_f64, _rhonn_small_f32, _rhonn_small_f64
from .config import IdentifierConfig
from .covariance import clearly_indefinite
from .covariance import unpacked as _unpacked

__all__ = ["Identifier", "IdentifierError", "NeuronHealth", "capacities"]

_ndarray = np.ndarray
_BOOL = np.dtype(np.bool_)

_BACKENDS: dict[str, ModuleType] = {"float64": _rhonn_f64, "float32": _rhonn_f32}
#: Every build of each precision, smallest ``rhonn_t`` first: the small-capacity
#: pair (``pyrhonn._build.SMALL_CAPACITIES``) and the large one of _BACKENDS.
#: An identifier runs on the first that holds its config; all give the same
#: results bit for bit (same sources, same flags; only the array capacities,
#: and with them the strides, differ).
_BUILDS: dict[str, tuple[ModuleType, ...]] = {
    dtype: tuple(sorted({small, large}, key=lambda mod: int(mod.ffi.sizeof("rhonn_t"))))
    for dtype, small, large in (("float64", _rhonn_small_f64, _rhonn_f64), ("float32", _rhonn_small_f32, _rhonn_f32))
}
_CAPACITY_NAMES = ("RHONN_MAX_STATES", "RHONN_MAX_INPUTS", "RHONN_MAX_TERMS", "RHONN_MAX_FACTORS",
                   "RHONN_MAX_DELAY", "RHONN_MAX_POWER")

_FIELD_NAMES = {
    1: "n_states", 2: "n_inputs", 3: "x0", 4: "terms", 5: "activation", 6: "beta", 7: "eta",
    8: "r", 9: "q", 10: "w0", 11: "p0", 12: "terms[{t}] factors", 13: "terms[{t}][{f}].kind",
    14: "terms[{t}][{f}].index", 15: "terms[{t}][{f}].delay", 16: "terms[{t}][{f}].power",
    17: "covariance", 18: "forgetting", 19: "p_trace_max", 20: "reset_after", 21: "gate", 22: "skip_refused", 23: "wait_for_history",
}


@dataclass(frozen=True)
class NeuronHealth:
    """One neuron's filter health (``rhonn_health`` in ``rhonn.h``)."""

    innovation: float   # e_i of the last learning update, committed or gated (eq. 9)
    nis: float          # e_i^2 / s_i of that update: about 1 on average when P_i is consistent
    trace_p: float      # trace of the committed P_i
    updates: int        # learning updates committed
    rejected: int       # learning updates refused (the step raised)
    resets: int         # automatic covariance resets (reset_after)
    bounded: int        # updates whose P_i was scaled down to p_trace_max
    fail_run: int       # refused updates in a row, up to now
    gated: int = 0      # updates skipped by the innovation gate (e_i^2 / s_i > gate)


class IdentifierError(ValueError):
    """The C core refused a step: ``status`` is the rhonn_status name.

    A ``ValueError`` so that every rejected input is caught the same way;
    the identifier's state is unchanged when this is raised. A failure that
    comes from the stored state (a learning update that overflows for the
    stored regressor and covariance) therefore repeats on the next steps:
    recover with ``reset()``, ``learning = False`` or the setters.
    """

    def __init__(self, status: str, message: str, sample: int | None = None) -> None:
        super().__init__(message)
        self.status = status
        self.sample = sample  #: the failing row of a run() (None for step() and the setters)


def capacities(dtype: str = "float64") -> dict[str, int]:
    """The compile-time capacities the extension was built with: those of
    the large build, the most an identifier of this dtype can hold."""
    return build_capacities(_backend(dtype))


def build_capacities(build: ModuleType) -> dict[str, int]:
    """The compile-time capacities of one build (an extension module)."""
    return {name: int(getattr(build.lib, name)) for name in _CAPACITY_NAMES}


def _build_for(config: IdentifierConfig) -> ModuleType:
    """The smallest build of ``config.dtype`` that holds ``config``; ValueError
    naming the field that exceeds even the largest one's capacity."""
    builds = _BUILDS[config.dtype]
    for build in builds[:-1]:
        try:
            _check_capacity(config, build_capacities(build))
        except ValueError:
            continue
        return build
    _check_capacity(config, build_capacities(builds[-1]))
    return builds[-1]


_work = threading.local()  # one scratch per thread and build of the core (it holds nothing between calls)


#: Rows of the blocks step() returns its predictions in (Identifier._fast_step).
_STEP_ROWS = 64

_LANE_ALIGNMENT = 64  # an AVX-512 vector of the lanes: one cache line


def _workspace(build: ModuleType) -> Any:
    """This thread's ``rhonn_population_work`` for one build of the core (an
    extension module): the lanes of ``rhonn_run_population`` and of
    ``rhonn_run_wide``, which hold nothing between calls. Aligned to a cache
    line, so that no vector of 8 lanes straddles two (malloc gives 16 bytes;
    measured: a misaligned workspace costs the vector kernels 10-15 %)."""
    cache = getattr(_work, "by_build", None)
    if cache is None:
        cache = _work.by_build = {}
    if build.__name__ not in cache:
        cache[build.__name__] = _aligned_workspace(build)
    return cache[build.__name__][1]


def _aligned_workspace(build: ModuleType) -> tuple[Any, Any]:
    """A new ``rhonn_population_work`` of one build on a cache line: (the
    allocation, which keeps it alive; the pointer to the workspace)."""
    ffi = build.ffi
    raw = ffi.new("char[]", ffi.sizeof("rhonn_population_work") + _LANE_ALIGNMENT)
    skip = -int(ffi.cast("uintptr_t", raw)) % _LANE_ALIGNMENT
    return raw, ffi.cast("rhonn_population_work *", raw + skip)


@functools.cache
def _raw_allocator(build: ModuleType) -> Callable[..., Any]:
    """``ffi.new`` of one build without the zeroing, for buffers written whole at once."""
    return build.ffi.new_allocator(should_clear_after_alloc=False)  # type: ignore[no-any-return]


def _backend(dtype: str) -> ModuleType:
    try:
        return _BACKENDS[dtype]
    except KeyError:
        raise ValueError(f"dtype: expected one of {sorted(_BACKENDS)}, got {dtype!r}") from None


def _check_capacity(config: IdentifierConfig, caps: dict[str, int]) -> None:
    def over(path: str, value: int, cap: str) -> None:
        if value > caps[cap]:
            raise ValueError(f"{path}: {value} exceeds the compiled capacity {cap} = {caps[cap]}")

    over("n_states", config.n_states, "RHONN_MAX_STATES")
    over("n_inputs", config.n_inputs, "RHONN_MAX_INPUTS")
    for i, neuron in enumerate(config.neurons):
        over(f"neurons[{i}].terms", neuron.n_terms, "RHONN_MAX_TERMS")
        for t, term in enumerate(neuron.terms):
            over(f"neurons[{i}].terms[{t}] (factors)", len(term), "RHONN_MAX_FACTORS")
            for f, fac in enumerate(term):
                over(f"neurons[{i}].terms[{t}][{f}].delay", fac.delay, "RHONN_MAX_DELAY")
                over(f"neurons[{i}].terms[{t}][{f}].power", fac.power, "RHONN_MAX_POWER")


def _packed(P: np.ndarray) -> np.ndarray:
    """Upper triangle of a symmetric matrix, row by row (the core's layout)."""
    return P[np.triu_indices(P.shape[0])]


def _float32_note(config: IdentifierConfig, field: int, neuron: int) -> str:
    """Why a float32 core refused a real-valued field that float64 accepts: the
    first value of that field that is beyond float32's range or rounds to 0."""
    if config.dtype != "float32" or field not in (3, 6, 7, 8, 9, 10, 11, 18, 19, 21):
        return ""
    if field == 3:
        values = config.x0_vector()
    else:
        nr = config.neurons[neuron]
        values = {6: np.array([nr.beta]), 7: np.array([nr.eta]), 8: np.array([nr.r]), 9: nr.q_diagonal(),
                  10: nr.w0_vector(), 11: _packed(nr.p0_matrix()), 18: np.array([nr.forgetting]),
                  19: np.array([nr.p_trace_max or 0.0]), 21: np.array([nr.gate])}[field]
    f32 = np.finfo(np.float32)
    with np.errstate(over="ignore", under="ignore"):
        for v in np.asarray(values, dtype=np.float64):
            if abs(v) > float(f32.max):
                return f" ({v:.3g} is beyond float32's range, +-{float(f32.max):.3g})"
            if v != 0.0 and abs(v) < float(f32.tiny):
                return f" ({v:.3g} is below float32's smallest normal number, {float(f32.tiny):.3g})"
    if field == 11:
        return " (not positive definite at float32 precision)"
    if field == 19:
        return " (below trace P0 once both are rounded to float32)"
    return ""


_F = TypeVar("_F", bound=Callable[..., Any])


def _serialised(method: _F) -> _F:
    """Run ``method`` holding the identifier's lock: the C core's state is
    one struct, and two threads stepping it at once would interleave halves
    of two updates (cffi releases the GIL during the C call). The learning
    state :meth:`Identifier.step` lent to the vector lanes is given back
    first, so the method finds all of it in the struct."""
    @functools.wraps(method)
    def locked(self: Identifier, *args: Any, **kwargs: Any) -> Any:
        with self._lock:
            self._settle()
            return method(self, *args, **kwargs)
    return locked  # type: ignore[return-value]


def _nothing_lent() -> None:
    """:attr:`Identifier._settle` of an identifier whose steps do not use the lanes."""


class Identifier:
    """A RHONN identifier trained online by a per-neuron EKF, in C.

    Parameters
    ----------
    config:
        A validated :class:`~pyrhonn.config.IdentifierConfig`; its ``dtype``
        selects the float64 or float32 build of the core. A config larger than
        the compiled capacities raises ``ValueError`` naming the field.

    Arrays in and out have exactly the identifier's dtype; nothing is
    converted silently. Wrong shapes, dtypes or non-finite measurements raise
    ``ValueError`` naming the argument, and leave the identifier unchanged.

    Threads: one identifier may be used from several threads; its calls are
    serialised by a lock (a second thread's ``step`` or ``run`` waits for the
    first to finish). Separate identifiers share nothing and run in parallel:
    the C call releases the GIL.
    """

    def __init__(self, config: IdentifierConfig) -> None:
        if not isinstance(config, IdentifierConfig):
            raise ValueError(f"config: expected an IdentifierConfig, got {type(config).__name__}")
        _backend(config.dtype)  # ValueError naming an unknown dtype
        backend = self._build = _build_for(config)
        self._ffi = backend.ffi
        self._lib = backend.lib
        self._config = config
        self._dtype = np.dtype(config.dtype)
        self._n = config.n_states
        self._m = config.n_inputs
        self._xshape = (self._n,)
        self._ushape = (self._m,)
        self._real_array = "double[]" if config.dtype == "float64" else "float[]"
        self._lock = threading.RLock()
        self._net = self._ffi.new("rhonn_t *")
        self._cfg = self._c_config(config)
        where = self._ffi.new("rhonn_config_error *")
        status = self._lib.rhonn_init(self._net, self._cfg, where)
        if status != self._lib.RHONN_OK:
            raise ValueError(self._config_error_message(where) + _float32_note(config, int(where.field),
                                                                                int(where.neuron)))
        at = self._ffi.offsetof("rhonn_t", "n_groups")
        self._mutable = (at, self._ffi.sizeof("rhonn_t") - at)
        # run() puts the neurons side by side in the vector lanes where the
        # core expects that to be faster on this CPU (the same bits either way)
        self._wide = bool(self._lib.rhonn_wide_pays(self._net))
        self._out = np.empty(self._n, dtype=self._dtype)
        self._out_ptr = self._ffi.from_buffer(self._real_array, self._out)
        self._null = self._ffi.NULL
        self._no_inputs = self._ffi.from_buffer(self._real_array, np.zeros(1, dtype=self._dtype))
        # Gives back what step() lent to the lanes (see _fast_step); called
        # under the lock before anything else reads or writes the C state.
        self._settle: Callable[[], None] = _nothing_lent
        if type(self).step is Identifier.step:  # a subclass's own step() is left to it
            self.step = self._fast_step()  # type: ignore[method-assign]

    # -- construction helpers -------------------------------------------------

    def _c_config(self, config: IdentifierConfig) -> Any:
        cfg = self._ffi.new("rhonn_config *")
        cfg.n_states = config.n_states
        cfg.n_inputs = config.n_inputs
        for j, v in enumerate(config.x0_vector()):
            cfg.x0[j] = float(v)
        for i, neuron in enumerate(config.neurons):
            nc = cfg.neurons[i]
            nc.n_terms = neuron.n_terms
            nc.activation = neuron.activation.code
            nc.beta = neuron.beta
            nc.eta = neuron.eta
            nc.r = neuron.r
            for t, v in enumerate(neuron.q_diagonal()):
                nc.q[t] = float(v)
            for t, v in enumerate(neuron.w0_vector()):
                nc.w0[t] = float(v)
            for t, v in enumerate(_packed(neuron.p0_matrix())):
                nc.p0[t] = float(v)
            nc.covariance = neuron.covariance.code
            nc.forgetting = neuron.forgetting
            nc.p_trace_max = 0.0 if neuron.p_trace_max is None else neuron.p_trace_max
            nc.reset_after = neuron.reset_after
            nc.gate = neuron.gate
            nc.skip_refused = int(neuron.skip_refused)
            nc.wait_for_history = int(neuron.wait_for_history)
            for t, term in enumerate(neuron.terms):
                nc.terms[t].n_factors = len(term)
                for f, fac in enumerate(term):
                    cf = nc.terms[t].factors[f]
                    cf.kind = int(fac.kind)
                    cf.index = fac.index
                    cf.delay = fac.delay
                    cf.power = fac.power
        return cfg

    def _config_error_message(self, where: Any) -> str:
        template = _FIELD_NAMES.get(int(where.field), "config")
        name = template.format(t=int(where.term), f=int(where.factor))
        if int(where.field) in (1, 2):
            return f"{name}: rejected by the C core"
        if int(where.field) == 3:
            return f"x0[{int(where.factor)}]: rejected by the C core"
        return f"neurons[{int(where.neuron)}].{name}: rejected by the C core"

    # -- properties -------------------------------------------------------------

    @property
    def config(self) -> IdentifierConfig:
        return self._config

    @property
    def dtype(self) -> np.dtype:
        return self._dtype

    @property
    def n_states(self) -> int:
        return self._n

    @property
    def n_inputs(self) -> int:
        return self._m

    @property
    def steps(self) -> int:
        """Steps since construction or :meth:`reset` (wraps at 2**32)."""
        with self._lock:  # a field steps in the lanes keep up to date: no need to bring them back
            return int(self._net.steps)

    @property
    def learning(self) -> bool:
        """Whether steps update the weights (predictions continue either way)."""
        with self._lock:  # as steps
            return bool(self._net.learning)

    @learning.setter
    @_serialised
    def learning(self, on: bool) -> None:
        if not isinstance(on, (bool, np.bool_)):
            raise ValueError(f"learning: expected a bool, got {type(on).__name__}")
        self._check(self._lib.rhonn_set_learning(self._net, 1 if on else 0), "learning")

    @property
    @_serialised
    def prediction(self) -> np.ndarray:
        """x̂(k): the last prediction (config x0 before the first step)."""
        out = np.empty(self._n, dtype=self._dtype)
        self._check(self._lib.rhonn_get_prediction(self._net, self._ffi.from_buffer(self._real_array, out),
                                                   self._n), "prediction")
        return out

    @property
    def weights(self) -> list[np.ndarray]:
        """w_i for every neuron (copies), shapes (L_i,)."""
        return [self.get_weights(i) for i in range(self._n)]

    @property
    def covariances(self) -> list[np.ndarray]:
        """P_i for every neuron as full symmetric (L_i, L_i) matrices (copies)."""
        return [self.get_covariance(i) for i in range(self._n)]

    @property
    @_serialised
    def regressors(self) -> list[np.ndarray]:
        """z_i(k-1), the regressors that produced x̂(k) (copies)."""
        zb = int(self._net.zbank)
        return [np.array([self._net.z[zb][i][t] for t in range(nr.n_terms)], dtype=self._dtype)
                for i, nr in enumerate(self._config.neurons)]

    def _neuron_index(self, neuron: int) -> int:
        if isinstance(neuron, bool) or not isinstance(neuron, (int, np.integer)) or not 0 <= neuron < self._n:
            raise ValueError(f"neuron: expected an index in 0..{self._n - 1}, got {neuron!r}")
        return int(neuron)

    @_serialised
    def get_weights(self, neuron: int) -> np.ndarray:
        i = self._neuron_index(neuron)
        L = self._config.neurons[i].n_terms
        out = np.empty(L, dtype=self._dtype)
        self._check(self._lib.rhonn_get_weights(self._net, i, self._ffi.from_buffer(self._real_array, out), L),
                    "weights")
        return out

    @_serialised
    def set_weights(self, neuron: int, w: np.ndarray) -> None:
        """Replace w_i; ``w`` must have shape (L_i,) and the identifier's dtype."""
        i = self._neuron_index(neuron)
        L = self._config.neurons[i].n_terms
        self._require(w, "w", (L,))
        if not np.all(np.isfinite(w)):
            raise ValueError(f"w[{int(np.argmin(np.isfinite(w)))}]: not finite")
        w = np.ascontiguousarray(w)  # a strided view (w[::2]) is taken as step() takes x: same values, same dtype
        self._check(self._lib.rhonn_set_weights(self._net, i, self._ffi.from_buffer(self._real_array, w), L), "w")

    @_serialised
    def get_covariance(self, neuron: int) -> np.ndarray:
        i = self._neuron_index(neuron)
        L = self._config.neurons[i].n_terms
        packed = np.empty(L * (L + 1) // 2, dtype=self._dtype)
        self._check(self._lib.rhonn_get_covariance(self._net, i, self._ffi.from_buffer(self._real_array, packed),
                                                   packed.size), "covariance")
        return _unpacked(packed, L)

    @_serialised
    def set_covariance(self, neuron: int, P: np.ndarray) -> None:
        """Replace P_i with a symmetric (L_i, L_i) matrix that is positive
        definite at the identifier's precision (its U D U^T factorisation has
        positive pivots)."""
        i = self._neuron_index(neuron)
        L = self._config.neurons[i].n_terms
        self._require(P, "P", (L, L))
        if not np.all(np.isfinite(P)):
            r, c = (int(v) for v in np.argwhere(~np.isfinite(P))[0])
            raise ValueError(f"P[{r}, {c}]: not finite")
        if not np.array_equal(P, P.T):
            raise ValueError("P: not symmetric")
        if not np.all(np.diag(P) > 0):
            raise ValueError(f"P[{int(np.argmin(np.diag(P) > 0))}, {int(np.argmin(np.diag(P) > 0))}]: "
                             "diagonal entries must be > 0")
        lowest = clearly_indefinite(P)
        if lowest is not None:
            raise ValueError(f"P: not positive semi-definite (smallest eigenvalue {lowest:.3g})")
        packed = np.ascontiguousarray(_packed(P))
        status = self._lib.rhonn_set_covariance(self._net, i, self._ffi.from_buffer(self._real_array, packed),
                                                packed.size)
        if status == self._lib.RHONN_E_VALUE:
            lowest = float(np.linalg.eigvalsh(P.astype(np.float64))[0])
            raise IdentifierError(self._status_name(status),
                                  f"P: not positive definite at {self._dtype} precision (smallest eigenvalue "
                                  f"{lowest:.3g}; the core keeps every P_i positive definite)")
        self._check(status, "P")

    # -- running ------------------------------------------------------------------

    def _require(self, a: object, name: str, shape: tuple[int, ...]) -> None:
        if not isinstance(a, np.ndarray):
            raise ValueError(f"{name}: expected a numpy array, got {type(a).__name__}")
        if a.dtype != self._dtype:
            raise ValueError(f"{name}: expected dtype {self._dtype}, got {a.dtype}")
        if a.shape != shape:
            raise ValueError(f"{name}: expected shape {shape}, got {a.shape}")

    def _require_valid(self, valid: object, shape: tuple[int, ...]) -> None:
        if not isinstance(valid, np.ndarray):
            raise ValueError(f"valid: expected a numpy bool array, got {type(valid).__name__}")
        if valid.dtype != np.bool_:
            raise ValueError(f"valid: expected dtype bool, got {valid.dtype}")
        if valid.shape != shape:
            raise ValueError(f"valid: expected shape {shape}, got {valid.shape}")

    def step(self, x: np.ndarray, u: np.ndarray | None = None, valid: np.ndarray | None = None) -> np.ndarray:
        """One sample: learn from x(k), then return x̂(k+1) (a new array).

        ``x`` has shape (n,), ``u`` shape (m,) (None when m = 0), ``valid`` is
        None (all measured) or a bool array of shape (n,); an entry of x whose
        flag is False is ignored (it may be NaN) and replaced by x̂_j(k).

        ``ident.step`` is the identifier's own fast version of this method
        (:meth:`_fast_step`); it accepts, refuses and returns exactly the same.
        Its arrays are rows of a small block (their ``base``) that the next
        steps' predictions fill, one row each, never shared and never written
        again: a kept prediction keeps its block (a few kB at most) alive.
        Where :meth:`run` puts the neurons side by side in the vector lanes,
        so does it, keeping them there from one step to the next (the same
        bits as stepping neuron by neuron); any other method first brings
        them back, a few hundred ns, so a loop that reads something after
        every step is faster reading it every few steps.
        """
        return self._step_checked(x, u, valid)

    def _fast_step(self) -> Callable[..., np.ndarray]:
        """The identifier's own :meth:`step`, bound once (it shadows the
        method on the instance).

        Arguments that are already exactly right -- numpy arrays of the
        identifier's dtype (the very dtype object numpy uses for it) and
        shape, ``valid`` None or bool -- are passed as their bytes
        (``tobytes``, a C-order copy of exactly the checked size) to one C
        call (``pyrhonn_step_from``, host glue of :mod:`pyrhonn._build`
        around ``rhonn_step``), which copies them into preallocated buffers
        and steps; everything the call needs is held in the closure: no
        attribute lookups, no ``from_buffer``. Anything else, right or wrong,
        goes to :meth:`_step_checked`, which accepts, copies and refuses
        exactly as before. The copies happen under the identifier's lock,
        since the buffers are shared by every thread using it. The closure
        holds the identifier only weakly: no reference cycle keeps a dropped
        identifier's (large) C state alive until the garbage collector runs.

        Where ``run`` puts the neurons side by side in the vector lanes
        (``_wide``, decided by the core for this CPU; read at the first
        step), so does ``step``, which would otherwise pay for loading the
        lanes and storing them back at every call: the first step lends the
        neurons' weights, covariances and regressor to the identifier's own
        workspace (``rhonn_wide_begin``; allocated then: 230 kB in float64
        on the small build, 5.1 MB on the large one) and the later ones step
        there (``rhonn_wide_step``, the same bits as ``rhonn_step``). Every
        other method gives them back first (:attr:`_settle`, under the
        lock), and the next step lends them again; a failed step gives them
        back before it raises.

        The C call writes the prediction into the next row of a block of
        :data:`_STEP_ROWS` rows and returns the row's index, and the array
        returned is that row (a view made with its block): a new array each
        step, never handed out twice, never written again. A block lives as
        long as one of its rows is referenced (at most :data:`_STEP_ROWS`
        predictions' memory).
        An exception between the call and the hand-out (a KeyboardInterrupt)
        leaves one row unused, nothing out of step.
        """
        ffi = self._ffi
        dt, xshape, ushape, m, n = self._dtype, self._xshape, self._ushape, self._m, self._n
        c_step, no_row = self._lib.pyrhonn_step_from, int(self._lib.PYRHONN_STEP_NO_ROW)
        real_array, empty = self._real_array, np.empty
        x_buf = ffi.new(real_array, n)
        u_buf = ffi.new(real_array, max(m, 1))
        v_buf = ffi.new("uint8_t[]", n)
        # The call's buffers and sizes (pyrhonn._build.STEP_GLUE). The struct
        # holds raw pointers; the closure keeps what they point to. No rows
        # yet: the first call asks for a block.
        call = ffi.new("pyrhonn_step_call *")
        call.net, call.x, call.u, call.valid = self._net, x_buf, u_buf, v_buf
        call.rows, call.n_rows, call.next_row, call.n = self._null, 0, 0, n
        call.x_bytes, call.u_bytes, call.valid_bytes = n * dt.itemsize, m * dt.itemsize, n
        call.work = self._null
        c_settle = self._lib.pyrhonn_step_settle
        keep: list[Any] = [self._net, x_buf, u_buf, v_buf]  # and the lanes' workspace once there is one
        lanes_decided = False
        acquire, release = self._lock.acquire, self._lock.release
        tobytes, null = np.ndarray.tobytes, self._null
        views: list[np.ndarray] = []  # the rows of the block the C call writes (call.rows), as arrays
        me = weakref.ref(self)

        def owner() -> Identifier:
            ident = me()
            if ident is None:  # only when step was kept and the identifier itself dropped
                raise ReferenceError("step: its Identifier no longer exists (keep the Identifier, not only "
                                     "its step method)")
            return ident

        def checked(x: Any, u: Any, valid: Any) -> np.ndarray:
            return owner()._step_checked(x, u, valid)

        def settle() -> None:
            # Under the lock; a no-op when nothing is lent. A refusal here
            # would mean the loan was lost, which only a call outside this
            # class can do.
            status = c_settle(call)
            if status:
                owner()._check(-status, "step (giving back the lanes)")

        def new_block() -> None:
            # Under the lock, when the C call found no row left. The block is
            # held here before the C call points at it, and its rows become
            # free only by the last assignment: interrupted anywhere before
            # it, the next call finds no row left and asks again.
            nonlocal views, lanes_decided
            if not lanes_decided:  # the first block: the lanes or not, once
                ident = me()  # (a step kept beyond its identifier steps on in rhonn_step)
                if ident is not None and ident._wide:
                    raw, work = _aligned_workspace(ident._build)
                    keep.append(raw)  # the identifier's own workspace: the loan lives in it between steps
                    call.work = work
                lanes_decided = True
            block = empty((_STEP_ROWS, n), dtype=dt)
            views = list(block)  # made here at once: after a C step, each would cost more
            call.rows = ffi.from_buffer(real_array, block)
            call.n_rows = _STEP_ROWS
            call.next_row = 0

        def step(x: np.ndarray, u: np.ndarray | None = None, valid: np.ndarray | None = None) -> np.ndarray:
            if type(x) is not _ndarray or x.dtype is not dt or x.shape != xshape:
                return checked(x, u, valid)
            if u is None:
                if m:
                    return checked(x, u, valid)
                ub = null
            elif type(u) is not _ndarray or u.dtype is not dt or u.shape != ushape or not m:
                return checked(x, u, valid)
            else:
                ub = tobytes(u)
            if valid is None:
                vb = null
            elif type(valid) is not _ndarray or valid.dtype is not _BOOL or valid.shape != xshape:
                return checked(x, u, valid)
            else:
                vb = tobytes(valid)
            xb = tobytes(x)
            acquire()  # one step at a time on this identifier (see the class docs)
            try:
                row: int = c_step(call, xb, ub, vb)  # the row it wrote, or minus its status
                if row < 0:
                    if row == no_row:
                        new_block()
                        row = c_step(call, xb, ub, vb)
                    if row < 0:
                        settle()
                        owner()._raise_step_error(-row, x[None, :], None if u is None else u[None, :],
                                                  None if valid is None else valid[None, :], 0, single=True)
                return views[row]
            finally:
                release()

        self._settle = settle
        functools.update_wrapper(step, Identifier.step)
        step._keep = keep  # type: ignore[attr-defined]  # the state and buffers the calls point to
        return step

    def _step_checked(self, x: np.ndarray, u: np.ndarray | None, valid: np.ndarray | None) -> np.ndarray:
        """:meth:`step` for any arguments: checks them (ValueError naming the
        argument), copies a non-contiguous one, then steps."""
        if type(x) is not np.ndarray or x.dtype != self._dtype or x.shape != self._xshape \
                or not x.flags.c_contiguous:
            self._require(x, "x", self._xshape)
            x = np.ascontiguousarray(x)
        ffi = self._ffi
        if u is None:
            if self._m:
                raise ValueError(f"u: expected an array of shape {self._ushape}, got None")
            u_ptr = self._no_inputs
        else:
            if type(u) is not np.ndarray or u.dtype != self._dtype or u.shape != self._ushape \
                    or not u.flags.c_contiguous:
                self._require(u, "u", self._ushape)
                u = np.ascontiguousarray(u)
            u_ptr = ffi.from_buffer(self._real_array, u) if self._m else self._no_inputs
        if valid is None:
            v_ptr = self._null
        else:
            if type(valid) is not np.ndarray or valid.dtype != np.bool_ or valid.shape != self._xshape:
                self._require_valid(valid, self._xshape)
            valid = np.ascontiguousarray(valid)
            v_ptr = ffi.from_buffer("uint8_t[]", valid)
        with self._lock:  # one step at a time on this identifier (see the class docs)
            self._settle()
            status = self._lib.rhonn_step(self._net, ffi.from_buffer(self._real_array, x), u_ptr, v_ptr,
                                          self._out_ptr)
            if status:
                self._raise_step_error(status, x[None, :], None if u is None else u[None, :],
                                       None if valid is None else valid[None, :], 0, single=True)
            return self._out.copy()

    def _checked_trajectory(self, X: object, U: object, valid: object) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """``(X, U, valid)`` of a whole trajectory, checked (shapes, dtypes, finite measured
        values and inputs) and C-contiguous; U (T, 0) when m = 0."""
        _, U = self._check_trajectory(X, U, valid)
        assert isinstance(X, np.ndarray) and (valid is None or isinstance(valid, np.ndarray))
        return self._finite_trajectory(X, U, valid)

    @_serialised
    def run(self, X: np.ndarray, U: np.ndarray | None = None, valid: np.ndarray | None = None,
            out: np.ndarray | None = None) -> np.ndarray:
        """A whole trajectory in one C call.

        ``X`` (T, n), ``U`` (T, m) (None when m = 0), ``valid`` None or bool
        (T, n). Row t of the result is x̂(t+1), the prediction made at sample
        t: the streaming convention of :meth:`step` and of the firmware, one
        row later than the measurement it estimates. (``pyrhonn identify``'s
        ``predictions.csv`` and :func:`pyrhonn.simulation.simulate` align
        rows with the measurements instead: their row k is x̂(k), that is
        ``np.vstack([prediction_before_the_run, result[:-1]])``.)
        C-contiguous arrays of the identifier's dtype are passed without
        copies; ``out`` (T, n), if given, receives the predictions. On any
        error nothing is applied: the identifier is as it was before the call.
        Where every neuron has the same number of terms and covariance form
        and there are enough neurons to fill the CPU's vector unit (3-8,
        ``rhonn_wide_pays``), the neurons' updates run side by side in it
        (``rhonn_run_wide``): the same bits as stepping.
        """
        Xc, Uc, Vc = self._checked_trajectory(X, U, valid)
        T = Xc.shape[0]
        if out is None:
            out = np.empty((T, self._n), dtype=self._dtype)
        else:
            self._require(out, "out", (T, self._n))
            if not out.flags.c_contiguous or not out.flags.writeable:
                raise ValueError("out: must be a writeable C-contiguous array")
        if T == 0:
            return out
        saved = self._checkpoint()
        done, status = self._pass(Xc, Uc, Vc, 0, T, out)
        if status:
            fault = int(self._net.fault_neuron)  # before the rollback below puts the old one back
            self._rollback(saved)
            self._raise_step_error(status, Xc, Uc, Vc, done, single=False, neuron=fault)
        return out

    # -- validation passes (used by pyrhonn.simulation; not public API) -----------------

    def _checkpoint(self) -> Any:
        """A copy of the core state that running can change, for :meth:`_rollback`:
        ``rhonn_t`` from ``n_groups`` to its end. What precedes it, ``magic``
        and ``cfg`` (the validated copy of the configuration, about 30% of
        the struct in either build), only ``rhonn_init`` writes (and a loan
        to the lanes, whose ``magic`` is given back before any checkpoint);
        a test holds running to that. The copy is not zeroed first (it is
        overwritten whole at once): with the smaller copy, a checkpoint of
        the large build costs about 20 us instead of 50. What :meth:`step`
        lent to the lanes is given back first (the caller holds the lock)."""
        self._settle()
        at, length = self._mutable
        saved = _raw_allocator(self._build)("char[]", length)
        self._ffi.memmove(saved, self._ffi.cast("char *", self._net) + at, length)
        return saved

    def _rollback(self, saved: Any) -> None:
        at, length = self._mutable
        self._ffi.memmove(self._ffi.cast("char *", self._net) + at, saved, length)

    def _pass(self, X: np.ndarray, U: np.ndarray, V: np.ndarray | None, first: int, stop: int,
              out: np.ndarray, *, ahead: int = 0, ahead_out: np.ndarray | None = None) -> tuple[int, int]:
        """Step rows ``first..stop-1`` of a checked, C-contiguous trajectory
        (:meth:`_checked_trajectory`), writing row t's output x̂(t+1) to
        ``out[t]``; ``out`` is C-contiguous (T, n) of the identifier's dtype.

        With ``ahead`` = h >= 2, after each row t the identifier also runs h-1
        samples on from its own outputs (every state not valid, learning
        off, inputs U[t+1..t+h-1]), writes x̂(t+h) to ``ahead_out[t+h]`` when
        t+h < T (NaN where that branch failed: the prediction diverged), and
        is then put back exactly as it was after row t. Learning off touches
        nothing before the field ``zbank`` (weights, covariances, their
        banks), so only the struct from there on is saved and restored; a
        test holds the result to a run without branches, bit for bit.

        Returns ``(rows done, status)``: 0 when every row ran, else the
        status of row ``first + done``, which was not applied (the rows
        before it were).
        """
        ffi, lib, net, n, m = self._ffi, self._lib, self._net, self._n, self._m
        T = X.shape[0]
        xp = ffi.from_buffer(self._real_array, X)
        up = ffi.from_buffer(self._real_array, U) if m else self._no_inputs
        vp = self._null if V is None else ffi.from_buffer("uint8_t[]", V)
        op = ffi.from_buffer(self._real_array, out)
        if ahead < 2:
            done = ffi.new("size_t *")
            args = (stop - first, xp + first * n, up + first * m if m else up,
                    self._null if V is None else vp + first * n, op + first * n, done)
            if self._wide:  # rhonn_run bit for bit, the neurons side by side
                status = lib.rhonn_run_wide(net, _workspace(self._build), *args)
            else:
                status = lib.rhonn_run(net, *args)
            return int(done[0]), int(status)
        assert ahead_out is not None
        tail_at = ffi.offsetof("rhonn_t", "zbank")
        tail_len = ffi.sizeof("rhonn_t") - tail_at
        tail = ffi.cast("char *", net) + tail_at
        saved = ffi.new("char[]", tail_len)
        not_valid = ffi.new("uint8_t[]", n)
        branch = np.empty(n, dtype=self._dtype)
        bp = ffi.from_buffer(self._real_array, branch)
        for t in range(first, stop):
            status = lib.rhonn_step(net, xp + t * n, up + t * m if m else up,
                                    self._null if V is None else vp + t * n, op + t * n)
            if status:
                return t - first, int(status)
            if t + ahead >= T:
                continue
            ffi.memmove(saved, tail, tail_len)
            net.learning = 0
            failed = False
            for j in range(t + 1, t + ahead):
                if lib.rhonn_step(net, xp + j * n, up + j * m if m else up, not_valid, bp):
                    failed = True
                    break
            ahead_out[t + ahead] = np.nan if failed else branch
            ffi.memmove(tail, saved, tail_len)
        return stop - first, 0

    def _check_trajectory(self, X: object, U: object, valid: object) -> tuple[int, np.ndarray]:
        """Shapes and dtypes of a run's ``X``, ``U``, ``valid``: (T, U), U an
        empty (T, 0) array when None and m = 0. ValueError naming the argument."""
        if not isinstance(X, np.ndarray) or X.ndim != 2:
            raise ValueError(f"X: expected a 2-D numpy array (T, {self._n}), got "
                             f"{type(X).__name__ if not isinstance(X, np.ndarray) else X.shape}")
        T = X.shape[0]
        self._require(X, "X", (T, self._n))
        if U is None:
            if self._m:
                raise ValueError(f"U: expected an array of shape {(T, self._m)}, got None")
            U = np.zeros((T, 0), dtype=self._dtype)
        self._require(U, "U", (T, self._m))
        if valid is not None:
            self._require_valid(valid, (T, self._n))
        assert isinstance(U, np.ndarray)
        return T, U

    def _finite_trajectory(self, X: np.ndarray, U: np.ndarray, valid: np.ndarray | None
                           ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """C-contiguous ``X``, ``U``, ``valid``, after refusing a non-finite
        measured state or input (before anything touches a filter)."""
        Xc, Uc = np.ascontiguousarray(X), np.ascontiguousarray(U)
        Vc = None if valid is None else np.ascontiguousarray(valid)
        measured = np.isfinite(Xc) if Vc is None else (np.isfinite(Xc) | ~Vc)
        if not measured.all():
            t, j = (int(v) for v in np.argwhere(~measured)[0])
            raise ValueError(f"X[{t}, {j}]: not finite (a measured state must be finite)")
        if self._m and not np.isfinite(Uc).all():
            t, j = (int(v) for v in np.argwhere(~np.isfinite(Uc))[0])
            raise ValueError(f"U[{t}, {j}]: not finite")
        return Xc, Uc, Vc

    @_serialised
    def reset(self) -> None:
        """Back to w(0), P(0), x̂(0) and an empty history; learning on."""
        self._check(self._lib.rhonn_reset(self._net), "reset")

    @_serialised
    def restart(self) -> None:
        """Forget the history and the pending comparison, keep what was learnt.

        For a break in the sample stream (lost samples, a restarted sender): the
        next step does not learn (x̂(k) was predicted for another sample) and
        fills every delayed tap with its own sample, as the first step does;
        weights, covariances, the learning switch and x̂(k) are kept.
        """
        self._check(self._lib.rhonn_restart(self._net), "restart")

    @_serialised
    def health(self, neuron: int) -> NeuronHealth:
        """Filter health of one neuron: the last innovation e_i, the normalised
        innovation squared e_i^2 / s_i (s_i = R_i + z^T P_i z, eq. 8), trace P_i
        and the counters of updates, refused updates, automatic covariance
        resets, bounded covariances and updates skipped by the innovation
        gate (since construction; :meth:`reset` keeps them)."""
        i = self._neuron_index(neuron)
        h = self._ffi.new("rhonn_health *")
        self._check(self._lib.rhonn_get_health(self._net, i, h), "health")
        return NeuronHealth(innovation=float(h.innovation), nis=float(h.nis), trace_p=float(h.trace_p),
                            updates=int(h.updates), rejected=int(h.rejected), resets=int(h.resets),
                            bounded=int(h.bounded), fail_run=int(h.fail_run), gated=int(h.gated))

    @property
    def healths(self) -> list[NeuronHealth]:
        """:meth:`health` of every neuron."""
        return [self.health(i) for i in range(self._n)]

    # -- errors ---------------------------------------------------------------------

    def _status_name(self, status: int) -> str:
        name: bytes = self._ffi.string(self._lib.rhonn_status_name(status))
        return name.decode()

    def _check(self, status: int, what: str) -> None:
        if status:
            raise IdentifierError(self._status_name(status), f"{what}: rejected by the C core "
                                                             f"({self._status_name(status)})")

    def _raise_step_error(self, status: int, X: np.ndarray, U: np.ndarray | None, V: np.ndarray | None,
                          t: int, single: bool, neuron: int | None = None) -> None:
        name = self._status_name(status)
        at = "" if single else f" at sample {t} (nothing applied)"
        lib = self._lib
        if status == lib.RHONN_E_INPUT_NONFINITE:
            row_ok = np.isfinite(X[t]) if V is None else (np.isfinite(X[t]) | ~V[t])
            if not row_ok.all():
                j = int(np.argmin(row_ok))
                where = f"x[{j}]" if single else f"X[{t}, {j}]"
            else:
                j = int(np.argmin(np.isfinite(U[t]))) if U is not None else 0
                where = f"u[{j}]" if single else f"U[{t}, {j}]"
            raise IdentifierError(name, f"{where}: not finite", None if single else t)
        if neuron is None:
            neuron = int(self._net.fault_neuron)
        if status == lib.RHONN_E_INNOVATION:
            msg = (f"neurons[{neuron}]: innovation variance R + z^T P z is not a positive finite number{at}; "
                   "either the covariance has lost positive definiteness (check P0, Q, R) or z^T P z overflowed "
                   "(check the size of the measurements and inputs the regressor z is built from)")
        elif status == lib.RHONN_E_COVARIANCE:
            msg = f"neurons[{neuron}]: the covariance update overflowed{at} (check P0 and Q)"
        elif status == lib.RHONN_E_DIVERGED:
            msg = f"neurons[{neuron}]: weights or prediction would not be finite{at}"
        elif status == lib.RHONN_E_NOT_PD:
            form = self._config.neurons[neuron].covariance.value
            msg = (f"neurons[{neuron}]: the updated covariance would not be positive definite at {self._dtype} "
                   f"precision{at}; nothing was committed"
                   + ("; covariance = \"ud\" (the U D U^T form) keeps it definite through rounding"
                      if form == "full" else "; check P0, Q and R"))
        else:
            msg = f"step rejected by the C core{at}"
        raise IdentifierError(name, f"{msg} [{name}]", None if single else t)

    # -- persistence ------------------------------------------------------------------

    @_serialised
    def save(self, path: str | Path) -> None:
        """Write the full filter state; see :mod:`pyrhonn.statefile`."""
        from .statefile import save_state

        save_state(self, path)

    @classmethod
    def load(cls, path: str | Path) -> Identifier:
        """Rebuild an identifier, mid-run, from a file written by :meth:`save`."""
        from .statefile import load_state

        return load_state(path, cls)

    def as_config(self) -> IdentifierConfig:
        """The config with w0 and P0 taken from the current weights and
        covariances: a trained identifier as a starting point (e.g. for
        :func:`pyrhonn.export.export_header`)."""
        from dataclasses import replace

        neurons = []
        for i, nr in enumerate(self._config.neurons):
            P = self.get_covariance(i).astype(np.float64)  # exactly symmetric: packed storage
            neurons.append(replace(nr, p0=P, w0=self.get_weights(i).astype(np.float64)))
        return self._config.replace(neurons=tuple(neurons))

    # -- state access for the state file (not public API) --------------------------------

    def _sample_offsets(self) -> tuple[int, int]:
        """Offsets of S(x) group 0 and of u in one sample of the core's history
        (RHONN_SAMPLE_LEN layout: x, S(x) per activation group, u, 1)."""
        N = int(self._lib.RHONN_MAX_STATES)
        return N, N * (N + 1)

    @_serialised
    def _history(self) -> dict[str, np.ndarray]:
        """What the next step reads of the past: ``x`` the effective x(k-d) and
        ``u`` u(k-d), newest first, d = 0..D-1 for the config's deepest delay
        D, and ``valid_run``: per state, the samples in a row (up to 255) in
        which it was measured."""
        net, D = self._net, self._config.max_delay
        H = int(self._lib.RHONN_HISTORY_LEN)
        _, u_off = self._sample_offsets()
        slots = [(int(net.head) - d) % H for d in range(D)]
        x = np.array([[net.hist[s][j] for j in range(self._n)] for s in slots], dtype=self._dtype).reshape(D, self._n)
        u = np.array([[net.hist[s][u_off + j] for j in range(self._m)] for s in slots],
                     dtype=self._dtype).reshape(D, self._m)
        valid_run = np.array([int(net.valid_run[j]) for j in range(self._n)], dtype=np.uint8)
        return {"x": x, "u": u, "valid_run": valid_run}

    @_serialised
    def _stored_covariance(self, neuron: int) -> np.ndarray:
        """P_i exactly as the core keeps it, packed: P_i, or its U D U^T factors."""
        L = self._config.neurons[neuron].n_terms
        packed = np.empty(L * (L + 1) // 2, dtype=self._dtype)
        self._check(self._lib.rhonn_get_factors(self._net, neuron, self._ffi.from_buffer(self._real_array, packed),
                                                packed.size), "covariance")
        return packed

    @_serialised
    def _restore(self, *, weights: list[np.ndarray], packed_cov: list[np.ndarray], regressors: list[np.ndarray],
                 prediction: np.ndarray, history: dict[str, np.ndarray], started: bool, learning: bool,
                 steps: int) -> None:
        """Load a mid-run state. Arguments are validated by the caller."""
        lib, net = self._lib, self._net
        self._check(lib.rhonn_reset(net), "reset")
        for i in range(self._n):
            w = np.ascontiguousarray(weights[i])
            self._check(lib.rhonn_set_weights(net, i, self._ffi.from_buffer(self._real_array, w), w.size),
                        f"w_{i}")
            p = np.ascontiguousarray(packed_cov[i])
            self._check(lib.rhonn_set_factors(net, i, self._ffi.from_buffer(self._real_array, p), p.size),
                        f"p_{i}")
            for t, v in enumerate(regressors[i]):
                net.z[int(net.zbank)][i][t] = float(v)
        for j in range(self._n):
            net.xhat[j] = float(prediction[j])
        H = int(lib.RHONN_HISTORY_LEN)
        s_off, u_off = self._sample_offsets()
        x_hist, u_hist = history["x"], history["u"]
        net.head = 0
        for d in range(x_hist.shape[0]):
            slot = (-d) % H
            for j in range(self._n):
                net.hist[slot][j] = float(x_hist[d, j])
                for g in range(int(net.n_groups)):
                    net.hist[slot][s_off * (1 + g) + j] = lib.rhonn_activate(
                        net.group_activation[g], net.group_beta[g], float(x_hist[d, j]))
            for j in range(self._m):
                net.hist[slot][u_off + j] = float(u_hist[d, j])
            net.hist[slot][u_off + int(lib.RHONN_MAX_INPUTS)] = 1.0
        for j in range(self._n):
            net.valid_run[j] = int(history["valid_run"][j])
        net.started = 1 if started else 0
        net.learning = 1 if learning else 0
        net.steps = steps
