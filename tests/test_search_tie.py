"""The tie between candidate spaces by the free run: which spaces join the finalists by their one-step error."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import pyrhonn.search as search_module
from pyrhonn.search import TIE, SearchGrid, search, tied
from test_search import plant

score_arrays = hnp.arrays(np.float64, st.integers(1, 12), elements=st.floats(0.0, 3.0, allow_nan=False, width=64))
fractions = st.floats(0.0, 1.0)


@settings(max_examples=80, deadline=None)
@given(scores=score_arrays, fraction=fractions, data=st.data())
def test_the_best_space_is_always_tied_with_itself(scores: np.ndarray, fraction: float, data: st.DataObject) -> None:
    best = data.draw(st.integers(0, scores.size - 1))
    assert tied(scores, best, fraction)[best]


@settings(max_examples=60, deadline=None)
@given(score=st.floats(0.0, 3.0), spaces=st.integers(1, 12), fraction=fractions)
def test_spaces_with_identical_scores_are_all_tied(score: float, spaces: int, fraction: float) -> None:
    assert tied(np.full(spaces, score), 0, fraction).all()


@settings(max_examples=80, deadline=None)
@given(scores=score_arrays, narrow=fractions, wider=fractions)
def test_a_wider_tie_ties_no_fewer_spaces(scores: np.ndarray, narrow: float, wider: float) -> None:
    narrow, wider = min(narrow, wider), max(narrow, wider)
    best = int(np.argmin(scores))
    before, after = tied(scores, best, narrow), tied(scores, best, wider)
    assert not (before & ~after).any()  # every space tied by the narrower tie stays tied


def test_the_tie_is_a_fraction_of_the_best_score() -> None:
    scores = np.array([0.50, 0.50 * (1 + TIE) - 1e-9, 0.50 * (1 + TIE) + 1e-9, np.inf])
    assert tied(scores, 0).tolist() == [True, True, False, False]
    assert tied(scores, 0, 0.0).tolist() == [True, False, False, False]


@pytest.mark.parametrize(("scores", "best", "fraction", "message"), [
    (np.array([[0.1, 0.2]]), 0, TIE, "scores"),
    (np.zeros(0), 0, TIE, "scores"),
    (np.array([1, 2]), 0, TIE, "scores"),
    ([0.1, 0.2], 0, TIE, "scores"),
    (np.array([0.1, 0.2]), 2, TIE, "best"),
    (np.array([0.1, 0.2]), True, TIE, "best"),
    (np.array([np.inf, 0.2]), 0, TIE, "scores"),
    (np.array([0.1, 0.2]), 0, -0.01, "fraction"),
    (np.array([0.1, 0.2]), 0, float("nan"), "fraction"),
])
def test_tied_names_bad_arguments(scores: object, best: object, fraction: object, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        tied(scores, best, fraction)  # type: ignore[arg-type]


def test_search_ties_the_ranked_spaces_by_their_free_run_scores(monkeypatch: pytest.MonkeyPatch) -> None:
    seen: list[np.ndarray] = []

    def spy(scores: np.ndarray, best: int, fraction: float = TIE) -> np.ndarray:
        seen.append(scores)
        return tied(scores, best, fraction)

    monkeypatch.setattr(search_module, "tied", spy)
    grid = SearchGrid(factor_sets=(("x", "u", "1"),), max_degree=1, max_delay=1, input_taps=1)
    found = search([plant(400, 3, noise=0.02)], grid=grid, state_names=["y"], input_names=["u"])
    assert len(seen) == 1
    ranked = sorted(sc.score for sc in found.scores if np.isfinite(sc.score))
    np.testing.assert_array_equal(seen[0], ranked)  # the best first
