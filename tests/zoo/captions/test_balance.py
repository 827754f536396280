"""Uniform rule balancing: same count per rule, spread over captions, seeded."""

from __future__ import annotations

import numpy as np
import pytest

from zoo.captions.balance import balance_indices, count_by, even_split


def test_even_split_by_hand():
    assert even_split([100, 100, 100], 10) == [3, 3, 4]
    assert even_split([1, 50, 50], 10) == [1, 4, 5]
    assert even_split([2, 3], 100) == [2, 3]  # quota above the supply keeps everything


@pytest.fixture
def skewed():
    rng = np.random.default_rng(0)
    rules = np.repeat([0, 1, 2, 3], [500, 37, 120, 9])
    captions = rules * 10 + rng.integers(0, 3, len(rules))
    return rules, captions


def test_uniform_gives_every_rule_the_rarest_count(skewed):
    rules, captions = skewed
    kept = balance_indices(rules, captions, seed=1)
    counts = np.bincount(rules[kept])
    assert counts.max() - counts.min() <= 1 and counts.min() == 9
    assert len(np.unique(kept)) == len(kept)


def test_per_rule_target_caps_large_rules_and_keeps_small_ones(skewed):
    rules, captions = skewed
    counts = np.bincount(rules[balance_indices(rules, captions, seed=1, per_rule=50)])
    assert counts.tolist() == [50, 37, 50, 9]


def test_quota_is_spread_over_captions_within_a_rule():
    rules = np.zeros(110, int)
    captions = np.array([0] * 100 + [1] * 10)
    other = np.ones(20, int)
    kept = balance_indices(np.r_[rules, other], np.r_[captions, other * 5], seed=0)
    assert np.bincount(np.r_[captions, other * 5][kept], minlength=6)[:2].tolist() == [10, 10]


def test_balancing_is_deterministic_from_the_seed(skewed):
    rules, captions = skewed
    a = balance_indices(rules, captions, seed=3)
    assert np.array_equal(a, balance_indices(rules, captions, seed=3))
    assert not np.array_equal(a, balance_indices(rules, captions, seed=4))


def test_none_keeps_everything_and_bad_mode_is_named(skewed):
    rules, captions = skewed
    assert len(balance_indices(rules, captions, seed=0, mode="none")) == len(rules)
    with pytest.raises(ValueError, match="'random' not in"):
        balance_indices(rules, captions, seed=0, mode="random")


def test_count_by_lists_absent_names():
    assert count_by(["a", "b", "c"], np.array([0, 2, 2])) == {"a": 1, "b": 0, "c": 2}
