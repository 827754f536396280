"""Crafter Score, normalized Return and the chunked protocol against hand-computed values."""

from __future__ import annotations

import math

import numpy as np
import pytest

from zoo.envs import ACHIEVEMENT_NAMES
from zoo.metrics import chunked, crafter_score, normalized_return, success_rates

WOOD = ACHIEVEMENT_NAMES.index("collect_wood")


def test_score_extremes():
    assert crafter_score(np.zeros(22)) == 0.0
    assert crafter_score(np.full(22, 100.0)) == pytest.approx(100.0)


def test_score_mixed_vector_by_hand():
    # Half the achievements at 0 %, half at 99 %: exp(mean(ln 1, ln 100)) - 1 = sqrt(100) - 1.
    assert crafter_score(np.array([0.0] * 11 + [99.0] * 11)) == pytest.approx(9.0)
    # Two achievements always unlocked, the rest never: 101 ** (2 / 22) - 1.
    rates = np.zeros(22)
    rates[[0, 5]] = 100.0
    assert crafter_score(rates) == pytest.approx(101 ** (1 / 11) - 1)
    # A geometric mean sits below the arithmetic one (3 % everywhere would score 3).
    assert crafter_score(np.full(22, 3.0)) == pytest.approx(3.0)


def test_score_rejects_fractions_and_bad_shapes():
    with pytest.raises(ValueError, match=r"\[0, 100\]"):
        crafter_score(np.full(22, 150.0))
    with pytest.raises(ValueError, match="shape"):
        crafter_score(np.zeros((2, 22)))


def test_success_rates_in_percent():
    unlocks = np.zeros((4, 22), bool)
    unlocks[:3, WOOD] = True
    unlocks[0, 1] = True
    rates = success_rates(unlocks)
    assert rates.shape == (22,)
    assert rates[WOOD] == 75.0 and rates[1] == 25.0 and rates.sum() == 100.0
    with pytest.raises(ValueError, match=r"\(episodes >= 1, 22\)"):
        success_rates(np.zeros((3, 21), bool))


def test_normalized_return_is_percent_of_22():
    returns = np.array([22.0, 11.0, 0.0, -1.1])
    np.testing.assert_allclose(normalized_return(returns), [100, 50, 0, -5])


def test_chunked_mean_std_by_hand():
    stat = chunked(np.mean, np.arange(1, 11, dtype=float), chunks=5)
    assert stat.per_chunk == [1.5, 3.5, 5.5, 7.5, 9.5]
    assert stat.mean == pytest.approx(5.5)
    assert stat.std == pytest.approx(math.sqrt(8.0))  # (16 + 4 + 0 + 4 + 16) / 5, ddof=0
    assert stat.pooled == pytest.approx(5.5)
    assert stat.chunk_sizes == [2, 2, 2, 2, 2]
    assert chunked(np.mean, np.arange(7.0), chunks=3).chunk_sizes == [3, 2, 2]


def test_chunked_score_is_per_chunk_then_averaged():
    unlocks = np.zeros((4, 22), bool)
    unlocks[:2, WOOD] = True  # chunk 0 always collects wood, chunk 1 never
    stat = chunked(lambda u: crafter_score(success_rates(u)), unlocks, chunks=2)
    one = 101 ** (1 / 22) - 1
    assert stat.per_chunk == pytest.approx([one, 0.0])
    assert stat.mean == pytest.approx(one / 2) and stat.std == pytest.approx(one / 2)
    assert stat.pooled == pytest.approx(51 ** (1 / 22) - 1)  # 50 % over all four


def test_chunked_needs_an_episode_per_chunk():
    with pytest.raises(ValueError, match="3 episodes cannot fill 5 chunks"):
        chunked(np.mean, np.ones(3), chunks=5)
