"""A population of identifiers of one structure over one trajectory, in one C call.

:func:`run_population` runs up to ``RHONN_MAX_POPULATION`` (8 unless the
extension was built otherwise; :func:`max_population`) configurations that
share their structure -- the states, inputs, and every neuron's terms,
activation and covariance form -- and differ in their tuning (x0, beta, eta,
R, Q, w0, P0, forgetting, p_trace_max, reset_after, skip_refused, gate), over the same
``X``, ``U``, ``valid``. It calls ``rhonn_run_population``
(``csrc/include/rhonn_population.h``): every member performs exactly the
floating-point operations of :meth:`pyrhonn.Identifier.run`, in the same
order, so each member's predictions are bit for bit those of running its
config alone; the full-form EKF arithmetic is laid out across members so the
compiler can vectorise it, and the regressor is formed once when it is the
same for every member (a neuron with ``skip_refused`` skips its refused
update in the lanes too, and each member's innovation gate in force is tested
in the lanes where ``rhonn_step`` tests it: members with and without gates
run together, a gated member keeping that neuron's weights and covariance for
the step).
:func:`run_identifiers` does the same for existing
identifiers, which continue from their current state.
"""
from __future__ import annotations

from contextlib import ExitStack
from typing import Any, Sequence

import numpy as np

from .config import IdentifierConfig
from .identifier import _BUILDS, Identifier, IdentifierError, _backend, _workspace

__all__ = ["max_population", "run_identifiers", "run_identifiers_outcomes", "run_population", "structure_key"]


def max_population(dtype: str = "float64") -> int:
    """How many members one call runs (the builds' ``RHONN_MAX_POPULATION``)."""
    _backend(dtype)  # ValueError naming an unknown dtype
    return min(int(build.lib.RHONN_MAX_POPULATION) for build in _BUILDS[dtype])


def structure_key(config: IdentifierConfig) -> tuple[Any, ...]:
    """A hashable key, equal for two configs exactly when they can run in one
    population: the same dtype, states, inputs, and every neuron's terms,
    activation and covariance form (what :func:`run_population` checks). For
    callers that sort many configs into populations (the structure search)."""
    if not isinstance(config, IdentifierConfig):
        raise ValueError(f"config: expected an IdentifierConfig, got {type(config).__name__}")
    return (config.dtype, config.n_states, config.n_inputs,
            tuple((tuple(tuple(t) for t in nr.terms), nr.activation, nr.covariance) for nr in config.neurons))


def _structure_difference(a: IdentifierConfig, b: IdentifierConfig) -> str | None:
    """The first structural field in which ``b`` differs from ``a`` (None: the same structure)."""
    if a.n_states != b.n_states:
        return "n_states"
    if a.n_inputs != b.n_inputs:
        return "n_inputs"
    for i, (na, nb) in enumerate(zip(a.neurons, b.neurons)):
        if na.n_terms != nb.n_terms:
            return f"neurons[{i}].terms (count)"
        for t, (ta, tb) in enumerate(zip(na.terms, nb.terms)):
            if tuple(ta) != tuple(tb):
                return f"neurons[{i}].terms[{t}]"
        if na.activation != nb.activation:
            return f"neurons[{i}].activation"
        if na.covariance != nb.covariance:
            return f"neurons[{i}].covariance"
    return None


def _check_members(configs: Sequence[IdentifierConfig], what: str) -> None:
    limit = max_population(configs[0].dtype) if configs and isinstance(configs[0], IdentifierConfig) else 0
    if not 1 <= len(configs) <= max(limit, 1):
        raise ValueError(f"{what}: expected 1..{limit} members (RHONN_MAX_POPULATION), got {len(configs)}")
    first = configs[0]
    for k, cfg in enumerate(configs):
        if cfg.dtype != first.dtype:
            raise ValueError(f"{what}[{k}].dtype: {cfg.dtype!r} differs from {what}[0].dtype {first.dtype!r} "
                             "(a population runs in one precision)")
        field = _structure_difference(first, cfg)
        if field is not None:
            raise ValueError(f"{what}[{k}].{field}: differs from {what}[0] (the members must share their "
                             "structure: states, inputs, terms, activations, covariance forms)")


def run_population(configs: Sequence[IdentifierConfig], X: np.ndarray, U: np.ndarray | None = None,
                   valid: np.ndarray | None = None) -> list[np.ndarray]:
    """Run every config, from its initial state, over one trajectory.

    ``X`` (T, n), ``U`` (T, m) (None when m = 0) and ``valid`` (None or bool
    (T, n)) are as for :meth:`pyrhonn.Identifier.run`, of the configs' dtype.
    Returns one (T, n) array per config, row t the prediction made at sample
    t, each bit for bit what ``Identifier(configs[k]).run(X, U, valid)``
    returns. ``ValueError`` names the offending config and field (a dtype or
    structure that differs from ``configs[0]``'s, a config the core refuses)
    or argument; :class:`~pyrhonn.IdentifierError` names the config whose
    run stopped (as ``Identifier.run`` would raise it).
    """
    members = _members(configs)
    return _run(members, X, U, valid, "configs")


def _members(configs: Sequence[IdentifierConfig]) -> list[Identifier]:
    if isinstance(configs, IdentifierConfig) or not isinstance(configs, Sequence):
        raise ValueError(f"configs: expected a sequence of IdentifierConfig, got {type(configs).__name__}")
    for k, cfg in enumerate(configs):
        if not isinstance(cfg, IdentifierConfig):
            raise ValueError(f"configs[{k}]: expected an IdentifierConfig, got {type(cfg).__name__}")
    if not configs:
        raise ValueError("configs: expected at least one IdentifierConfig, got none")
    _check_members(configs, "configs")
    members = []
    for k, cfg in enumerate(configs):
        try:
            members.append(Identifier(cfg))
        except ValueError as exc:
            raise ValueError(f"configs[{k}].{exc}") from None
    return members


def run_identifiers(identifiers: Sequence[Identifier], X: np.ndarray, U: np.ndarray | None = None,
                    valid: np.ndarray | None = None) -> list[np.ndarray]:
    """Run existing identifiers of one structure (distinct objects) over one
    trajectory, each continuing from its current state, as
    ``[ident.run(X, U, valid) for ident in identifiers]`` would, bit for bit.
    On any error no identifier is changed (as ``Identifier.run``)."""
    return _run(_identifiers(identifiers), X, U, valid, "identifiers")


def run_identifiers_outcomes(identifiers: Sequence[Identifier], X: np.ndarray, U: np.ndarray | None = None,
                             valid: np.ndarray | None = None) -> list[np.ndarray | IdentifierError]:
    """:func:`run_identifiers`, with the outcome of each member instead of the
    first failure: its (T, n) predictions, or the :class:`~pyrhonn.IdentifierError`
    its own ``Identifier.run`` would raise (naming the sample; that identifier
    is left as it was, the members that ran through are unaffected by it). For
    searches that score many tunings of one structure and count the failing
    ones (``pyrhonn tune --batch``). Bad arguments still raise ``ValueError``."""
    return _run(_identifiers(identifiers), X, U, valid, "identifiers", outcomes=True)


def _identifiers(identifiers: Sequence[Identifier]) -> list[Identifier]:
    if not isinstance(identifiers, Sequence) or not identifiers:
        raise ValueError("identifiers: expected a non-empty sequence of Identifier")
    for k, ident in enumerate(identifiers):
        if not isinstance(ident, Identifier):
            raise ValueError(f"identifiers[{k}]: expected an Identifier, got {type(ident).__name__}")
    if len({id(i) for i in identifiers}) != len(identifiers):
        raise ValueError("identifiers: the same Identifier is given twice (each member is its own state)")
    _check_members([i.config for i in identifiers], "identifiers")
    return list(identifiers)


def _run(members: list[Identifier], X: np.ndarray, U: np.ndarray | None, valid: np.ndarray | None,
         what: str, outcomes: bool = False) -> list[Any]:
    first = members[0]
    n, m = first.n_states, first.n_inputs
    T, U = first._check_trajectory(X, U, valid)
    N = len(members)
    out = np.empty((N, T, n), dtype=first.dtype)
    if T == 0:
        return list(out)
    Xc, Uc, Vc = first._finite_trajectory(X, U, valid)
    # The members share their structure, so the same (smallest) build of the core holds them all.
    backend = first._build
    if any(ident._build is not backend for ident in members):
        raise AssertionError("members of one structure on different builds of the core")
    ffi, lib = backend.ffi, backend.lib
    real = "double[]" if first.config.dtype == "float64" else "float[]"
    with ExitStack() as locks:
        for ident in sorted(members, key=id):  # one order for every caller: no lock-order deadlock
            locks.enter_context(ident._lock)
        saved = [ident._checkpoint() for ident in members]
        nets = ffi.new("rhonn_t *[]", [ident._net for ident in members])
        status = ffi.new("rhonn_status[]", N)
        done = ffi.new("size_t[]", N)
        where = ffi.new("rhonn_population_error *")
        rc = lib.rhonn_run_population(
            nets, N, _workspace(backend), T, ffi.from_buffer(real, Xc),
            ffi.from_buffer(real, Uc) if m else first._no_inputs,
            ffi.NULL if Vc is None else ffi.from_buffer("uint8_t[]", Vc),
            ffi.from_buffer(real, out), status, done, where)
        if rc == lib.RHONN_E_CONFIG:  # _check_members makes this unreachable; kept as the core's word
            for s, ident in zip(saved, members):
                ident._rollback(s)
            raise ValueError(f"{what}[{int(where.member)}]: structure differs from {what}[0] "
                             f"(rhonn_field {int(where.field)}, neuron {int(where.neuron)})")
        if rc == lib.RHONN_OK:
            return list(out)
        # each stopped member's error, as its own run would raise it (read before any restore)
        errors: dict[int, IdentifierError] = {}
        for k in range(N):
            if status[k] != lib.RHONN_OK:
                try:
                    members[k]._raise_step_error(int(status[k]), Xc, Uc, Vc, int(done[k]), single=False,
                                                 neuron=int(members[k]._net.fault_neuron))
                except IdentifierError as exc:
                    errors[k] = exc
        # outcomes: the stopped members as they were, the others on; else all as they were
        for k in (errors if outcomes else range(N)):
            members[k]._rollback(saved[k])
        if outcomes:
            return [errors.get(k, out[k]) for k in range(N)]
        k = min(errors)
        raise IdentifierError(errors[k].status, f"{what}[{k}]: {errors[k]}", errors[k].sample)
