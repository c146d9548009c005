"""Recordings as experiments: estimation and validation data kept apart.

An :class:`Experiment` is one recording of the plant: states ``X`` (T, n)
float64 with NaN where ``valid`` is False, inputs ``U`` (T, m), and a name
for reports. Fitting and validation take *lists* of experiments, so that

- several recordings can be merged for fitting (as MATLAB's ``merge`` of
  ``iddata``): :func:`merge` stacks them and returns where each starts, and
  no regressor row, free run or identifier history reads across a
  boundary (the identifier is restarted at each);
- estimation and validation data never mix: a validation experiment is
  only ever simulated with frozen weights.

:func:`hold_out` splits one experiment into the rows that fit and the rows
that validate (the last fraction), for a user who brings one recording.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from .validation import check_real, fail

__all__ = ["Experiment", "merge", "hold_out", "window_rows"]


@dataclass(frozen=True)
class Experiment:
    """One recording: ``X`` (T, n) float64, ``U`` (T, m) float64, ``valid`` (T, n) bool.

    ``first`` is the index of the recording's first sample in the file it
    came from (0 unless it was cut from a longer one), so that reports can
    name the rows that fitted and the rows that validated.
    """

    X: np.ndarray
    U: np.ndarray
    valid: np.ndarray
    name: str = "data"
    first: int = 0

    def __post_init__(self) -> None:
        X, U, valid = self.X, self.U, self.valid
        if not isinstance(X, np.ndarray) or X.ndim != 2 or X.dtype != np.float64 or X.shape[1] < 1:
            raise fail(f"{self.name}: X", "expected a (T, n) float64 numpy array, n >= 1")
        T, n = X.shape
        if not isinstance(U, np.ndarray) or U.ndim != 2 or U.dtype != np.float64 or U.shape[0] != T:
            raise fail(f"{self.name}: U", f"expected a ({T}, m) float64 numpy array")
        if not isinstance(valid, np.ndarray) or valid.dtype != np.bool_ or valid.shape != (T, n):
            raise fail(f"{self.name}: valid", f"expected a ({T}, {n}) bool numpy array")
        if T < 2:
            raise fail(f"{self.name}", f"{T} sample(s); an experiment needs at least 2")
        bad = np.argwhere(~np.isfinite(X) & valid)
        if bad.size:
            k, j = (int(v) for v in bad[0])
            raise fail(f"{self.name}: X", f"sample {k}, state {j}: not finite but marked valid")
        if not np.all(np.isfinite(U)):
            k, j = (int(v) for v in np.argwhere(~np.isfinite(U))[0])
            raise fail(f"{self.name}: U", f"sample {k}, input {j}: not finite")

    @property
    def n_samples(self) -> int:
        return int(self.X.shape[0])

    @property
    def rows(self) -> str:
        """The samples of the source file this experiment holds, as ``a..b`` (0-based, inclusive)."""
        return f"{self.first}..{self.first + self.n_samples - 1}"

    def cut(self, start: int, stop: int, name: str | None = None) -> Experiment:
        """Samples ``start`` .. ``stop - 1`` as an experiment of their own."""
        if not 0 <= start < stop <= self.n_samples or stop - start < 2:
            raise fail(f"{self.name}", f"cannot cut samples {start}..{stop - 1} from {self.n_samples}")
        return Experiment(self.X[start:stop].copy(), self.U[start:stop].copy(), self.valid[start:stop].copy(),
                          self.name if name is None else name, self.first + start)

    def frozen_inputs(self, dtype: str) -> tuple[np.ndarray, np.ndarray]:
        """``(X, U)`` in ``dtype`` for the core, missing states as 0 (never read: not valid)."""
        return np.where(self.valid, self.X, 0.0).astype(dtype), self.U.astype(dtype)


def _check_list(name: str, experiments: Sequence[Experiment]) -> list[Experiment]:
    exps = list(experiments)
    if not exps:
        raise fail(name, "expected at least one experiment")
    for e, ex in enumerate(exps):
        if not isinstance(ex, Experiment):
            raise fail(f"{name}[{e}]", f"expected an Experiment, got {type(ex).__name__}")
    n, m = exps[0].X.shape[1], exps[0].U.shape[1]
    for e, ex in enumerate(exps):
        if ex.X.shape[1] != n or ex.U.shape[1] != m:
            raise fail(f"{name}[{e}]", f"{ex.X.shape[1]} states and {ex.U.shape[1]} inputs; "
                                       f"{name}[0] has {n} and {m}")
    return exps


def merge(experiments: Sequence[Experiment]) -> tuple[np.ndarray, np.ndarray, np.ndarray, tuple[int, ...]]:
    """``(X, U, valid, starts)``: the experiments stacked in order, and the
    index where each after the first begins (what :func:`pyrhonn.structure.select`
    takes as ``starts``)."""
    exps = _check_list("experiments", experiments)
    starts = tuple(int(s) for s in np.cumsum([ex.n_samples for ex in exps])[:-1])
    return (np.vstack([ex.X for ex in exps]), np.vstack([ex.U for ex in exps]),
            np.vstack([ex.valid for ex in exps]), starts)


def hold_out(experiment: Experiment, fraction: float) -> tuple[Experiment, Experiment]:
    """``(fit, validate)``: the first ``1 - fraction`` of the samples and the last ``fraction``."""
    f = check_real("fraction", fraction)
    if not 0.0 < f < 1.0:
        raise fail("fraction", f"expected a fraction in (0, 1), got {fraction!r}")
    T = experiment.n_samples
    cut = int(round(T * (1.0 - f)))
    if cut < 2 or T - cut < 2:
        raise fail("fraction", f"{experiment.name}: {T} samples cannot be split {1 - f:.2f} / {f:.2f} (record "
                               "more, or give validation data)")
    return experiment.cut(0, cut, f"{experiment.name} (fit)"), experiment.cut(cut, T, f"{experiment.name} (validate)")


def window_rows(valid: np.ndarray, lead: int, *, reach: int | None = None, starts: Sequence[int] = (),
                stop: int | None = None) -> np.ndarray:
    """The regressor rows k, lead <= k < stop - 1 (``stop`` default: every sample), whose samples
    k - reach .. k + 1 (``reach`` default: ``lead``) are measured in every state and whose window
    k - lead .. k + 1 lies inside one experiment (``starts``: where each after the first begins, as
    :func:`merge` gives them). ``valid`` (T, n) bool."""
    T = valid.shape[0]
    stop = T if stop is None else stop
    reach = lead if reach is None else reach
    bad = np.concatenate([[0], np.cumsum(~valid.all(axis=1))])
    ks = np.arange(lead, max(lead, stop - 1))
    keep = bad[ks + 2] - bad[ks - reach] == 0
    for b in starts:
        keep &= ~((ks - lead < b) & (b <= ks + 1))  # the row's window would read two experiments
    return ks[keep]
