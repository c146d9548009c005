"""Automatic structure search: candidate spaces chosen by how the model simulates on validation data.

:func:`pyrhonn.structure.select` chooses terms *within* a candidate space
(factor kinds, degree, delays) by an information criterion on the one-step
targets. Which space to give it is the question a user who knows neither
the plant's structure nor its delay cannot answer, and one-step criteria
answer it badly: on slow or integrating plants a model that copies x(k)
predicts one step well and simulates nothing. :func:`search` answers it
from data, in five steps:

1. **Input dead time** per input (:func:`dead_times`): for d = 0..D, the
   least-squares fit of every x_i(k+1) on x(k), x(k-1), 1 and u_j(k-d)
   alone; the d with the least residual (states scaled to unit variance)
   is the dead time of u_j. The grid's input taps start at the smallest.
   Likewise a state delay deeper than the grid's short taps
   (:func:`state_delay`): the tap x(k-d) that best joins x(k), x(k-1) and
   the delayed inputs, kept where it pays by BIC; every space with state
   factors is then tried with and without it.
2. **The grid** (:class:`SearchGrid`): every factor set (raw states, their
   activations S, inputs, bias), degree 1..G, state delays 0..D_x, input
   taps from the dead time to D_u beyond it; S is tried at beta = 1 and at
   the slope that maps the data's largest magnitude to 2 (so that S does
   not saturate on data far from unit scale).
3. **Each space** is selected by the information criterion (EBIC) on the
   fitting rows, its least-squares weights frozen, and run free over them:
   a space whose free run leaves the data's range there is rejected
   (reported with the sample). The others are run free over the ranking
   rows and scored by the free-run RRSE, averaged over the states. The
   ranking rows are the user's validation experiments; without them, two
   blocked cross-validation folds of the estimation data (the last
   ``holdout`` of each experiment ranks a fit on the rest, then the first
   ``holdout`` ranks a fit on the rest; the score is the mean of the two).
4. **The finalists**: the :data:`REFINED` best spaces by the free-run
   score, and, among the spaces whose score is within :data:`TIE` of the
   best (the folds cannot tell them apart), the :data:`REFINED` with the
   best geometric mean of the free-run and one-step errors there. Each is
   selected on all the estimation data and competes twice: with its
   least-squares weights and with its weights refined on the free-run and
   one-step errors together, each relative to its least-squares value
   (:func:`pyrhonn.refine.refine`, ``objective="balanced"``: a refinement
   on the free-run error alone gives up one-step accuracy for small gains
   in simulation). The objective of this final choice is
   the geometric mean of the free-run and the one-step mean squared errors
   (in state variances), so that a refinement is kept only where it gains
   more in simulation than it loses one step ahead: on the validation
   experiments; without them, on the estimation data with the information
   criterion N ln(that mean) + 2 k (k terms), since the folds are too short
   to judge a refinement.
5. **Fallback**: when no space's model stays in the data's range in a free
   run, or none runs free clearly better than the data's mean (a free-run
   RRSE of :data:`INFORMATIVE` or more: a chaotic plant's free run loses
   the phase whatever the model),
   the space with the best one-step error is chosen, with least-squares
   weights, and the result says that this model predicts but does not
   simulate (:attr:`SearchResult.by_one_step`).

Validation data never fit a weight: they only rank spaces and refinements,
and the report names which rows fitted and which validated. Caps are
stated: a space over ``max_candidates`` candidates is skipped, a neuron
whose path reached ``max_terms`` is flagged, and the search itself reads
at most ``search_samples`` estimation samples (the final fit reads all).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from typing import Sequence

import numpy as np
from threadpoolctl import threadpool_limits

from .config import Activation, IdentifierConfig
from .configfile import ConfigFile
from .experiments import Experiment, hold_out, merge, window_rows
from .identifier import capacities
from .refine import DataRange, Refinement, free_run_of, refine
from .structure import CandidateSpace, Criterion, Selection, check_capacity, check_data, parse_criterion, select
from .validation import check_int, check_real, fail

__all__ = ["SearchGrid", "SpaceScore", "SearchResult", "Validation", "dead_times", "search", "tied", "validate"]

#: Spaces whose free-run score is within this fraction of the best space's are taken as tied by it
#: (cross-validation folds are short: their free-run RRSE is not known closer than a few per cent);
#: the :data:`REFINED` tied spaces with the best one-step error join the finalists. A measured choice:
#: on the real-data benchmark 1, 2, 5 and 10 % give the same models on the cascaded tanks and Bouc-Wen,
#: and on Narendra-Li only 2 and 5 % are ahead of FROLS both one step ahead and in free run; ties judged
#: from the folds' own spread (one standard error of the paired per-block difference, or of the best
#: space's block scores) fell behind FROLS's free run there (docs: "How close is a tie").
TIE = 0.05
#: A deep state tap joins the grid only where it leaves at most this fraction of the scan's residual.
STATE_DELAY_GAIN = 0.9
#: A free run informs the choice only where the best space's free-run RRSE is below this: a model whose
#: free run settles on the mean scores about 1, and a chaotic plant's free run loses the phase whatever
#: the model (about 1.4).
INFORMATIVE = 0.95
#: How many of the best spaces (by the free run, and by both errors among the tied) are refined.
REFINED = 3


@dataclass(frozen=True)
class SearchGrid:
    """The candidate spaces :func:`search` tries.

    ``factor_sets``: the factor kinds of each space (``"u"`` is dropped for
    a plant without inputs); ``max_degree``: degrees 1..G; ``max_delay``:
    state taps 0..D for D = 0..max_delay; ``input_taps``: input taps from
    the dead time to up to this many samples beyond it; ``max_dead_time``:
    the deepest input dead time looked for; ``max_state_delay``: the
    deepest state delay the scan looks for beyond the short taps; ``max_candidates``: a space with
    more candidate terms is skipped; ``search_samples``: the estimation
    samples the search reads at most (the first ones of each experiment,
    shared out in proportion).
    """

    factor_sets: tuple[tuple[str, ...], ...] = (("x", "u", "1"), ("S", "x", "u", "1"), ("S", "u", "1"))
    max_degree: int = 3
    max_delay: int = 3
    input_taps: int = 3
    max_dead_time: int = 30
    max_state_delay: int = 30
    max_candidates: int = 3000
    search_samples: int = 20000

    def __post_init__(self) -> None:
        if not isinstance(self.factor_sets, tuple) or not self.factor_sets:
            raise fail("factor_sets", "expected a non-empty tuple of factor-kind tuples")
        for f, kinds in enumerate(self.factor_sets):
            CandidateSpace(factors=kinds)  # names the bad kind
            if not isinstance(kinds, tuple):
                raise fail(f"factor_sets[{f}]", "expected a tuple of factor kinds")
        check_int("max_degree", self.max_degree, 1, 4)
        check_int("max_delay", self.max_delay, 0, 254)
        check_int("input_taps", self.input_taps, 0, 254)
        check_int("max_dead_time", self.max_dead_time, 0, 254)
        check_int("max_state_delay", self.max_state_delay, 0, 254)
        check_int("max_candidates", self.max_candidates, 1)
        check_int("search_samples", self.search_samples, 100)


@dataclass(frozen=True)
class Validation:
    """A frozen model over validation experiments: per state RRSE and RMSE of the free run and one step,
    pooled over the experiments; ``left_range``: (experiment name, sample) where a free run left the data."""

    free_rrse: np.ndarray
    free_rmse: np.ndarray
    one_rrse: np.ndarray
    one_rmse: np.ndarray
    scored: int
    left_range: tuple[str, int] | None

    @property
    def score(self) -> float:
        """The mean free-run RRSE over the states (inf where a free run left the data)."""
        return math.inf if self.left_range is not None else float(np.mean(self.free_rrse))


def validate(config: IdentifierConfig, experiments: Sequence[Experiment], data_range: DataRange) -> Validation:
    """``config`` with its weights frozen over every experiment: free run and one step, scored from the
    first sample each free run predicts on its own (:func:`pyrhonn.refine.first_sample`)."""
    n = config.n_states
    se_f, se_o, dev, cnt = np.zeros(n), np.zeros(n), np.zeros(n), 0
    sums, sums2, ns = np.zeros(n), np.zeros(n), np.zeros(n)
    left: tuple[str, int] | None = None
    runs = []
    for ex in experiments:
        run = free_run_of(config, ex, data_range)
        if run.left_range is not None and left is None:
            left = (ex.name, run.left_range)
        runs.append((ex, run))
    for ex, run in runs:
        mask = ex.valid.copy()
        mask[: run.start] = False
        x = np.where(mask, ex.X, 0.0)
        with np.errstate(invalid="ignore"):
            ef = np.where(mask, run.free_run - x, 0.0)
            eo = np.where(mask, run.one_step - x, 0.0)
        se_f += np.sum(np.where(np.isfinite(ef), ef, 0.0) ** 2, axis=0)
        se_o += np.sum(eo ** 2, axis=0)
        sums += x.sum(axis=0)
        sums2 += (x ** 2).sum(axis=0)
        ns += mask.sum(axis=0)
        cnt += int(mask.sum())
    ns = np.maximum(ns, 1)
    dev = np.maximum(sums2 - sums ** 2 / ns, 1e-300)
    return Validation(free_rrse=np.sqrt(se_f / dev), free_rmse=np.sqrt(se_f / ns), one_rrse=np.sqrt(se_o / dev),
                      one_rmse=np.sqrt(se_o / ns), scored=cnt, left_range=left)


def dead_times(experiments: Sequence[Experiment], max_dead_time: int) -> tuple[int, ...]:
    """The estimated dead time of each input, in samples (step 1 of :func:`search`)."""
    X, U, valid, starts = merge(experiments)
    T, n = X.shape
    m = U.shape[1]
    if m == 0:
        return ()
    D = min(max_dead_time, max(0, T // 10))
    scale = DataRange.of(experiments).sigma
    ks = window_rows(valid, max(D, 1), reach=1, starts=starts)  # x(k-1), x(k), x(k+1) measured
    if ks.size < 10:
        return (0,) * m
    Y = X[ks + 1] / scale
    base = np.column_stack([X[ks] / scale, X[ks - 1] / scale, np.ones(ks.size)])
    out = []
    for j in range(m):
        rss = []
        for d in range(D + 1):
            A = np.column_stack([base, U[ks - d, j]])
            coef, *_ = np.linalg.lstsq(A, Y, rcond=None)
            r = Y - A @ coef
            rss.append(float(np.sum(r * r)))
        out.append(int(np.argmin(rss)))
    return tuple(out)


def state_delay(experiments: Sequence[Experiment], shallow: int, deepest: int,
                dead: tuple[int, ...]) -> int | None:
    """A state delay deeper than the grid's short taps, or None (step 1 of :func:`search`).

    For d = shallow+1..deepest, the least-squares fit of every x_i(k+1) (scaled
    to unit variance) on x(k), x(k-1), each u_j(k - dead_j), 1 and x(k-d);
    the d with the least residual is kept when adding its n taps pays by
    BIC over the fit without them, N n ln(RSS_0 / RSS_d) > n^2 ln(N n), and
    cuts the residual by at least 1 - :data:`STATE_DELAY_GAIN` (on a
    nonlinear plant the linear fit leaves structure that some deep tap
    always explains a little: 3 % on a NARX test plant without any delay).
    """
    X, U, valid, starts = merge(experiments)
    T, n = X.shape
    D = min(deepest, max(0, T // 10))
    if D <= shallow:
        return None
    scale = DataRange.of(experiments).sigma
    ks = window_rows(valid, max(D, max(dead, default=0), 1), starts=starts)
    if ks.size < 10 * (3 * n + 2):
        return None
    Xs = X / scale
    Y = Xs[ks + 1]
    base = np.column_stack([Xs[ks], Xs[ks - 1]] + [U[ks - d, j] for j, d in enumerate(dead)] + [np.ones(ks.size)])

    def rss(A: np.ndarray) -> float:
        coef, *_ = np.linalg.lstsq(A, Y, rcond=None)
        r = Y - A @ coef
        return float(np.sum(r * r))

    rss0 = rss(base)
    scores = {d: rss(np.column_stack([base, Xs[ks - d]])) for d in range(max(shallow + 1, 2), D + 1)}
    if not scores:
        return None
    d = min(scores, key=lambda k: (scores[k], k))
    N = ks.size
    if rss0 <= 0 or scores[d] <= 0 or N * n * math.log(rss0 / scores[d]) <= n * n * math.log(N * n):
        return None
    if scores[d] > STATE_DELAY_GAIN * rss0:  # a linear scan of a nonlinear plant finds small spurious gains
        return None
    return d


@dataclass(frozen=True)
class SpaceScore:
    """One space of the grid as the search scored it."""

    space: CandidateSpace
    terms: int  #: terms over all neurons (0 where skipped)
    status: str  #: "scored", or why the space was skipped or rejected
    validation: Validation | None = None
    capped: bool = False  #: a neuron's path reached max_terms

    @property
    def score(self) -> float:
        """The mean free-run RRSE on the validation rows; inf unless the space was scored."""
        return math.inf if self.validation is None or self.status != "scored" else self.validation.score

    @property
    def one_step(self) -> float:
        """The mean one-step RRSE on the validation rows (inf where the space gave no model)."""
        return math.inf if self.validation is None else float(np.mean(self.validation.one_rrse))

    def describe(self) -> str:
        sp = self.space
        taps = "none" if "u" not in sp.factors else f"{sp.input_min_delay}..{sp.input_max_delay}"
        extra = "".join(f",{d}" for d in sp.extra_delays)
        return f"{','.join(sp.factors):8s} degree {sp.degree}  x taps 0..{sp.max_delay}{extra}  u taps {taps}"


@dataclass(frozen=True)
class SearchResult:
    """What :func:`search` returns.

    ``selection`` and ``config``: the chosen space's selection on all the
    estimation data and its config (w0 refined on the free-run and one-step errors where
    that lowered it); ``scores``: every space of the grid, in grid order,
    with its validation score (pooled over the folds without validation
    experiments); ``chosen``: the index of the chosen one; ``validation``:
    the final model on the user's validation experiments (None without
    them); ``in_sample``: the final model over the estimation data;
    ``refinement``: the final refinement, None where it was off or did not help.
    """

    selection: Selection
    config: IdentifierConfig
    scores: tuple[SpaceScore, ...]
    chosen: int
    validation: Validation | None
    in_sample: Validation
    refinement: Refinement | None
    dead_times: tuple[int, ...]
    fit_rows: tuple[str, ...]  #: the rows that fitted, per experiment ("name rows a..b")
    validation_rows: tuple[str, ...]  #: the rows that ranked the spaces
    held_out: bool  #: the ranking rows were folds of the estimation data
    search_samples: int  #: estimation samples the grid read
    seconds: float
    notes: tuple[str, ...] = field(default=())
    by_one_step: bool = False  #: no model simulated: the space was chosen by the one-step error
    state_delay: int | None = None  #: a deep state delay found by the scan (its taps joined the grid)
    tie: float = TIE  #: the free-run tie between spaces the finalists were chosen with (:func:`tied`)

    def config_file(self, state_names: tuple[str, ...], input_names: tuple[str, ...]) -> ConfigFile:
        """The config with names, a description of the search and each neuron's terms as its ``why``."""
        sc = self.scores[self.chosen]
        how = ("two blocked cross-validation folds of the estimation data, then an information criterion "
               "on the free-run error" if self.held_out else "the free-run error on the validation data")
        description = (
            f"Structure found by pyrhonn select's automatic search of {len(self.scores)} candidate spaces: "
            f"{' '.join(sc.describe().split())}, ranked by {how}; terms by forward orthogonal least squares "
            f"({self.selection.criterion.value}) on {'; '.join(self.fit_rows)}; weights "
            + ("refined on the free-run and one-step errors." if self.refinement is not None else "by least squares."))
        why = tuple(f"{nr.activation.value}, beta {nr.beta:g}; ERR " + ", ".join(
            f"{t.text} {t.err:.3g}" for t in nr.terms) for nr in self.selection.neurons)
        return ConfigFile.from_config(self.config, state_names=state_names, input_names=input_names,
                                      description=description, why=why)

    def report(self, state_names: Sequence[str], input_names: Sequence[str]) -> str:
        """A readable report: the rows, the dead times, the best spaces, the chosen model's errors."""
        ranking = ("blocked cross-validation on the estimation data, each fold fitted on the rest: "
                   if self.held_out else "validation data: ")
        lines = [f"fitted on: {'; '.join(self.fit_rows)}",
                 f"spaces ranked by their free run on {ranking}{'; '.join(self.validation_rows)}",
                 "input dead time: " + (", ".join(f"{name} {d} sample(s)" for name, d in
                                                  zip(input_names, self.dead_times)) or "no inputs"),
                 "state delay beyond the short taps: " + ("none found" if self.state_delay is None else
                                                          f"{self.state_delay} samples (its taps joined the grid)"),
                 f"{len(self.scores)} candidate spaces in {self.seconds:.1f} s (the grid read "
                 f"{self.search_samples} estimation samples)",
                 "  rank  free-run RRSE  one-step RRSE  terms  space"]
        def key(s: int) -> tuple[float, int]:
            sc = self.scores[s]
            return (sc.one_step if self.by_one_step else sc.score, sc.terms)

        order = sorted(range(len(self.scores)), key=key)
        if self.by_one_step:
            lines[-1] += "  (ranked by the one-step error)"
        for rank, s in enumerate(order[:8], 1):
            sc = self.scores[s]
            if not math.isfinite(key(s)[0]):
                break
            mark = "*" if s == self.chosen else " "
            lines.append(f"  {mark}{rank:3d}  {sc.score:13.4g}  {sc.one_step:13.4g}  "
                         f"{sc.terms:5d}  {sc.describe()}" + ("  (max_terms reached)" if sc.capped else ""))
        if self.chosen not in order[:8]:
            sc = self.scores[self.chosen]
            lines.append(f"  * {order.index(self.chosen) + 1:3d}  {sc.score:13.4g}  {sc.one_step:13.4g}  {sc.terms:5d}  "
                         f"{sc.describe()}")
        reasons: dict[str, int] = {}
        for sc in self.scores:
            if sc.status != "scored":
                reason = sc.status.split(":")[0]
                reasons[reason] = reasons.get(reason, 0) + 1
        if reasons:
            lines.append("  not ranked: " + ", ".join(f"{c} {why}" for why, c in sorted(reasons.items())))
        if self.held_out:
            lines.append(f"chosen among the best {REFINED} by the free run and the best {REFINED} by the one-step and "
                         f"free-run errors of those within {self.tie:.0%} of the best free run, each fitted on all the "
                         "estimation data with least-squares and with refined weights, by N ln(geometric mean of the "
                         "free-run and one-step mean squared errors) + 2 k on it")
        if self.refinement is not None:
            r = self.refinement
            lines.append(f"weights refined on the free-run and one-step errors: free-run mean squared error "
                         f"{r.cost_before:.4g} -> {r.cost_after:.4g}, one-step {r.one_step_before:.4g} -> "
                         f"{r.one_step_after:.4g} (in state variances), {r.iterations} iterations, "
                         f"{r.evaluations} free runs, {r.seconds:.1f} s ({r.stopped})")
        else:
            lines.append("weights: least squares")
        for title, v in (("on the validation data", self.validation), ("on the estimation data", self.in_sample)):
            if v is None:
                continue
            width = max(5, *(len(s) for s in state_names))
            lines.append(f"the chosen model {title}, weights frozen:")
            lines.append(f"  {'state':<{width}}  {'free-run RMSE':>13}  {'RRSE':>9}  {'fit %':>7}  "
                         f"{'one-step RMSE':>13}  {'RRSE':>9}")
            for j, name in enumerate(state_names):
                gone = v.left_range is not None
                lines.append(f"  {name:<{width}}  {'diverged' if gone else f'{v.free_rmse[j]:.4g}':>13}  "
                             f"{'-' if gone else f'{v.free_rrse[j]:.4g}':>9}  "
                             f"{'-' if gone else f'{100 * (1 - v.free_rrse[j]):.1f}':>7}  "
                             f"{v.one_rmse[j]:13.4g}  {v.one_rrse[j]:9.4g}")
            if v.left_range is not None:
                lines.append(f"  the free run left the data's range at sample {v.left_range[1]} of {v.left_range[0]}")
        lines += [f"note: {n}" for n in self.notes]
        return "\n".join(lines)


def _spaces(grid: SearchGrid, n: int, m: int, dead: int, beta_data: float, caps: dict[str, int],
            deep: int | None = None) -> list[CandidateSpace]:
    spaces = []
    u_hi = min(caps["RHONN_MAX_DELAY"], dead + grid.input_taps)
    for kinds in grid.factor_sets:
        if m == 0:
            kinds = tuple(k for k in kinds if k != "u")
            if not kinds or kinds == ("1",):
                continue
        betas = (1.0,) if "S" not in kinds or abs(beta_data - 1.0) < 1e-3 else (1.0, beta_data)
        for degree in range(1, min(grid.max_degree, caps["RHONN_MAX_FACTORS"]) + 1):
            for dx in range(min(grid.max_delay, caps["RHONN_MAX_DELAY"]) + 1):
                u_range = range(dead, u_hi + 1) if "u" in kinds else range(0, 1)
                for du in u_range:
                    space = CandidateSpace(factors=kinds, degree=degree, max_delay=dx, input_min_delay=dead
                                           if "u" in kinds else 0, input_max_delay=du, betas=betas,
                                           activations=(Activation.BIPOLAR, Activation.LOGISTIC))
                    if space not in spaces:
                        spaces.append(space)
                    if deep is not None and ("S" in kinds or "x" in kinds):
                        spaces.append(replace(space, extra_delays=(deep,)))
    return spaces


def _n_candidates(space: CandidateSpace, n: int, m: int) -> int:
    atoms = len(space.delays) * n * sum(k in space.factors for k in ("S", "x"))
    atoms += (space.input_max_delay - space.input_min_delay + 1) * m if "u" in space.factors else 0
    return math.comb(atoms + space.degree, space.degree) - 1 + ("1" in space.factors)


def _budget(experiments: list[Experiment], limit: int) -> list[Experiment]:
    total = sum(ex.n_samples for ex in experiments)
    if total <= limit:
        return experiments
    out = []
    for ex in experiments:
        take = max(2, int(ex.n_samples * limit / total))
        out.append(ex.cut(0, min(take, ex.n_samples)))
    return out


def _select(space: CandidateSpace, experiments: list[Experiment], criterion: Criterion, max_terms: int,
            names: tuple[Sequence[str], Sequence[str]]) -> Selection:
    X, U, valid, starts = merge(experiments)
    return select(X, U, valid, space=space, criterion=criterion, max_terms=max_terms, starts=starts,
                  state_names=names[0], input_names=names[1])


def _fit_score(space: CandidateSpace, fit: list[Experiment], val: list[Experiment], data_range: DataRange,
               crit: Criterion, max_terms: int, names: tuple[Sequence[str], Sequence[str]]
               ) -> tuple[IdentifierConfig, Selection, str | None, Validation]:
    """The space selected on ``fit``, its free run checked there, scored on ``val``."""
    sel = _select(space, fit, crit, max_terms, names)
    config = sel.config()
    for ex in fit:
        left = free_run_of(config, ex, data_range).left_range
        if left is not None:
            return config, sel, f"rejected: its free run left the data's range at sample {left} of {ex.name}", \
                validate(config, val, data_range)
    return config, sel, None, validate(config, val, data_range)


def _blend(v: Validation) -> float:
    """The finalists' objective: ln of the geometric mean of the free-run and one-step mean squared
    errors (in state variances), so that a refinement that halves one and doubles the other is neutral."""
    if v.left_range is not None:
        return math.inf
    free = max(float(np.mean(v.free_rrse ** 2)), 1e-300)
    one = max(float(np.mean(v.one_rrse ** 2)), 1e-300)
    return 0.5 * (math.log(free) + math.log(one))


def tied(scores: np.ndarray, best: int, fraction: float = TIE) -> np.ndarray:
    """Which spaces are tied with space ``best`` by the free run: a boolean per entry of ``scores`` (each
    space's free-run score), true where it is at most ``scores[best]`` times 1 + ``fraction``."""
    if not isinstance(scores, np.ndarray) or scores.ndim != 1 or scores.size < 1 or scores.dtype.kind != "f":
        raise fail("scores", "expected a non-empty 1-D float array, one score per space, got "
                   + (f"shape {scores.shape} of {scores.dtype}" if isinstance(scores, np.ndarray)
                      else type(scores).__name__))
    if isinstance(best, bool) or not isinstance(best, (int, np.integer)) or not 0 <= best < scores.size:
        raise fail("best", f"expected an index of scores (0..{scores.size - 1}), got {best!r}")
    if not math.isfinite(scores[best]) or scores[best] < 0:
        raise fail("scores", f"the best space's score scores[{best}] must be finite and >= 0, got {scores[best]}")
    fraction = check_real("fraction", fraction, nonnegative=True)
    with np.errstate(invalid="ignore"):
        out = scores <= scores[best] * (1.0 + fraction)
    out[best] = True
    return out


def _finalists(scored: list[SpaceScore], ranked: list[int], count: int, tie: float) -> list[int]:
    """The spaces fitted on all the estimation data: the ``count`` best by the free-run score, then the
    ``count`` best by the one-step and free-run errors together (:func:`_blend`) among the spaces tied
    with the best by the free run (:func:`tied`, within ``tie``); fewer where they coincide."""
    if count <= 1:
        return ranked[:count]
    same = tied(np.array([scored[s].score for s in ranked], dtype=np.float64), 0, tie)
    tied_spaces = [s for s, t in zip(ranked, same) if t]

    def one_step_first(s: int) -> tuple[float, int]:
        v = scored[s].validation
        assert v is not None  # a ranked space was scored
        return _blend(v), scored[s].terms

    tied_spaces.sort(key=one_step_first)
    return list(dict.fromkeys(ranked[:count] + tied_spaces[:count]))


def _pooled(parts: list[Validation]) -> Validation:
    """Fold scores as one: the mean of each figure, the first departure from the data's range."""
    left = next((v.left_range for v in parts if v.left_range is not None), None)
    return Validation(free_rrse=np.mean([v.free_rrse for v in parts], axis=0),
                      free_rmse=np.mean([v.free_rmse for v in parts], axis=0),
                      one_rrse=np.mean([v.one_rrse for v in parts], axis=0),
                      one_rmse=np.mean([v.one_rmse for v in parts], axis=0),
                      scored=sum(v.scored for v in parts), left_range=left)


def _in_dtype(sel: Selection, config: IdentifierConfig, dtype: str) -> IdentifierConfig:
    """``config`` (its w0) with the P0 and Q :meth:`Selection.config` gives for ``dtype``."""
    fresh = sel.config(dtype=dtype)
    return fresh.replace(neurons=tuple(replace(f, w0=c.w0_vector()) for f, c in zip(fresh.neurons, config.neurons)))


def _by_one_step(scored: list[SpaceScore], est: list[Experiment], searched: list[Experiment],
                 data_range: DataRange, crit: Criterion, max_terms: int, names: tuple[Sequence[str], Sequence[str]],
                 dtype: str, dead: tuple[int, ...], val_rows: tuple[str, ...], user_val: list[Experiment],
                 t0: float, notes: list[str], why: str, deep: int | None) -> SearchResult:
    """The fallback when no model simulates: the space with the best one-step error, least-squares weights."""
    usable = [s for s, sc in enumerate(scored) if math.isfinite(sc.one_step)]
    if not usable:
        skipped = next((sc.status for sc in scored if sc.status.startswith("skipped")), None)
        raise ValueError(f"search: no candidate space gives a model ({len(scored)} tried"
                         + (f"; the first skipped: {skipped.partition(': ')[2]}" if skipped else "")
                         + "); record more data or lower max_terms")
    chosen = min(usable, key=lambda s: (scored[s].one_step, scored[s].terms))
    sel = _select(scored[chosen].space, est, crit, max_terms, names)
    config = sel.config()
    notes = notes + [f"{why}: the structure was chosen by the one-step error on the validation rows, with "
                     "least-squares weights; this model predicts one step ahead but does not simulate"]
    return SearchResult(
        selection=sel, config=_in_dtype(sel, config, dtype), scores=tuple(scored), chosen=chosen,
        validation=validate(config, user_val, data_range) if user_val else None,
        in_sample=validate(config, est, data_range), refinement=None, dead_times=dead,
        fit_rows=tuple(f"{ex.name} rows {ex.rows}" for ex in est), validation_rows=val_rows, held_out=not user_val,
        search_samples=sum(ex.n_samples for ex in searched), seconds=time.perf_counter() - t0, notes=tuple(notes),
        by_one_step=True, state_delay=deep)


def search(estimation: Sequence[Experiment], validation: Sequence[Experiment] = (), *,
           grid: SearchGrid | None = None, criterion: Criterion | str = Criterion.EBIC, max_terms: int = 16,
           holdout: float = 0.3, refine_weights: bool = True, dtype: str = "float64",
           state_names: Sequence[str] | None = None, input_names: Sequence[str] | None = None,
           tie: float = TIE) -> SearchResult:
    """Choose a candidate space, its terms and weights from data; see the module docs.

    ``estimation``: the experiments that fit; ``validation``: the experiments
    that rank spaces (none: two blocked folds of the estimation experiments,
    each holding out ``holdout`` of every experiment, the last part in one
    fold and the first in the other). ``tie``: the spaces whose free-run
    score is within this fraction of the best one's are tied with it, and
    the one-step error picks finalists among them (:func:`tied`). ``dtype`` is written to the config
    (the search runs in float64). Where no model simulates, the result is
    chosen by the one-step error and says so (:attr:`SearchResult.by_one_step`);
    ValueError only where no space of the grid gives a model at all, or for
    bad arguments and data (naming them).
    """
    # Small least-squares problems by the thousand: BLAS threads only wait on each other (on a loaded
    # 2-CPU machine a 1,400 x 15 QR took 20 ms with two threads, 0.6 ms with one).
    with threadpool_limits(limits=1, user_api="blas"):
        return _search(estimation, validation, grid, criterion, max_terms, holdout, refine_weights, dtype,
                       state_names, input_names, tie)


def _search(estimation: Sequence[Experiment], validation: Sequence[Experiment], grid: SearchGrid | None,
            criterion: Criterion | str, max_terms: int, holdout: float, refine_weights: bool, dtype: str,
            state_names: Sequence[str] | None, input_names: Sequence[str] | None, tie: float) -> SearchResult:
    t0 = time.perf_counter()
    grid = SearchGrid() if grid is None else grid
    if not isinstance(grid, SearchGrid):
        raise fail("grid", f"expected a SearchGrid, got {type(grid).__name__}")
    crit = parse_criterion(criterion)
    max_terms = check_int("max_terms", max_terms, 1, 255)
    holdout = check_real("holdout", holdout)
    if not isinstance(refine_weights, bool):
        raise fail("refine_weights", f"expected a bool, got {refine_weights!r}")
    tie = check_real("tie", tie, nonnegative=True)
    est = list(estimation)
    if not est:
        raise fail("estimation", "expected at least one experiment")
    merge(est + list(validation))  # every experiment has the same states and inputs
    n, m = est[0].X.shape[1], est[0].U.shape[1]
    snames = tuple(state_names) if state_names else tuple(f"x{j + 1}" for j in range(n))
    inames = tuple(input_names) if input_names else tuple(f"u{j + 1}" for j in range(m))
    X, U, valid, _ = merge(est)
    check_data(X, U, valid, snames, inames)  # data defects are errors, not spaces to skip
    check_capacity(CandidateSpace(factors=("x",)), n, m, max_terms)
    names = (snames, inames)
    held_out = not validation
    caps = capacities()
    dead = dead_times(est, min(grid.max_dead_time, caps["RHONN_MAX_DELAY"]))
    deep = state_delay(est, grid.max_delay, min(grid.max_state_delay, caps["RHONN_MAX_DELAY"]), dead)
    data_range = DataRange.of(est)
    biggest = float(max(np.nanmax(np.abs(np.where(ex.valid, ex.X, np.nan))) for ex in est))
    beta_data = float(f"{2.0 / biggest:.2g}") if biggest > 0 else 1.0
    searched = _budget(est, grid.search_samples)
    notes = []
    if sum(ex.n_samples for ex in searched) < sum(ex.n_samples for ex in est):
        notes.append(f"the search read the first {sum(ex.n_samples for ex in searched)} of "
                     f"{sum(ex.n_samples for ex in est)} estimation samples (search_samples); the final "
                     "terms are selected on all of them")
    if held_out:
        tail = [hold_out(ex, holdout) for ex in searched]
        cuts = [(ex, int(round(ex.n_samples * holdout))) for ex in searched]
        head = [(ex.cut(c, ex.n_samples, f"{ex.name} (fit)"), ex.cut(0, c, f"{ex.name} (validate)")) for ex, c in cuts]
        folds = [([p[0] for p in tail], [p[1] for p in tail]), ([p[0] for p in head], [p[1] for p in head])]
        val_rows = tuple(f"{ex.name} rows {ex.rows}" for _, v in folds for ex in v)
    else:
        folds = [(searched, list(validation))]
        val_rows = tuple(f"{ex.name} rows {ex.rows}" for ex in validation)

    scored: list[SpaceScore] = []
    for space in _spaces(grid, n, m, min(dead, default=0), beta_data, caps, deep):
        M = _n_candidates(space, n, m)
        if M > grid.max_candidates:
            scored.append(SpaceScore(space, 0, f"skipped: {M} candidates (max_candidates {grid.max_candidates})"))
            continue
        parts, terms, capped, status = [], 0, False, "scored"
        try:
            for fit, val in folds:
                _, sel, why, v = _fit_score(space, fit, val, data_range, crit, max_terms, names)
                parts.append(v)
                terms = max(terms, sum(len(nr.terms) for nr in sel.neurons))
                capped |= any(len(nr.terms) >= max_terms for nr in sel.neurons)
                if why is not None:
                    status = why
                    break
        except ValueError as exc:
            scored.append(SpaceScore(space, 0, f"skipped: {exc}"))
            continue
        scored.append(SpaceScore(space, terms, status, _pooled(parts), capped))
    ranked = sorted((s for s, sc in enumerate(scored) if math.isfinite(sc.score)),
                    key=lambda s: (scored[s].score, scored[s].terms))
    if ranked and scored[ranked[0]].score >= INFORMATIVE:
        return _by_one_step(scored, est, searched, data_range, crit, max_terms, names, dtype, dead, val_rows,
                            list(validation), t0, notes, f"no space's free run clearly beats the data's mean (the "
                            f"best free-run RRSE is {scored[ranked[0]].score:.3g}: a chaotic or drifting plant, or "
                            "too little data)", deep)
    if not ranked:
        return _by_one_step(scored, est, searched, data_range, crit, max_terms, names, dtype, dead, val_rows,
                            list(validation), t0, notes, "no space's model stays in the data's range in a free run",
                            deep)

    # the finalists, fitted on all the estimation data (weights refined on both errors),
    # are compared: on the user's validation data, or by an information criterion on the free-run error
    finalists = []
    for s in _finalists(scored, ranked, REFINED if refine_weights else 1, tie):
        sel = _select(scored[s].space, est, crit, max_terms, names)
        versions: list[tuple[IdentifierConfig, Refinement | None]] = []
        if refine_weights:
            refined = refine(sel.config(), searched, data_range, objective="balanced")
            versions.append((refined.config, refined))
        versions.append((sel.config(), None))  # least squares may predict and simulate better together
        for config, ref in versions:
            runs = [free_run_of(config, ex, data_range) for ex in searched]
            if any(r.left_range is not None for r in runs):
                continue
            if held_out:
                v_in = validate(config, searched, data_range)
                N = max(v_in.scored, 1)
                k = sum(len(nr.terms) for nr in sel.neurons)
                key = N * _blend(v_in) + 2.0 * k
            else:
                key = _blend(validate(config, list(validation), data_range))
            finalists.append((key, s, sel, config, ref))
    if not finalists:
        return _by_one_step(scored, est, searched, data_range, crit, max_terms, names, dtype, dead, val_rows,
                            list(validation), t0, notes, "the best spaces, fitted on all the estimation data, leave the "
                                                 "data's range in a free run", deep)
    _, chosen, sel, config, refinement = min(finalists, key=lambda f: (f[0], f[1]))
    if refinement is not None and refinement.cost_after >= refinement.cost_before:
        refinement = None
    final_val = validate(config, list(validation), data_range) if not held_out else None
    if any(len(nr.terms) >= max_terms for nr in sel.neurons):
        notes.append(f"a neuron's selection reached max_terms ({max_terms}): the criterion did not stop it; "
                     "raise max_terms to let it decide")
    return SearchResult(
        selection=sel, config=_in_dtype(sel, config, dtype), scores=tuple(scored), chosen=chosen,
        validation=final_val, in_sample=validate(config, est, data_range), refinement=refinement,
        dead_times=dead, fit_rows=tuple(f"{ex.name} rows {ex.rows}" for ex in est), validation_rows=val_rows,
        held_out=held_out, search_samples=sum(ex.n_samples for ex in searched),
        seconds=time.perf_counter() - t0, notes=tuple(notes), state_delay=deep, tie=tie)
