"""Uniform balancing over categories (the paper) or rules, spread evenly below the unit, seeded."""

from __future__ import annotations

import numpy as np
import pytest

from zoo.captions.balance import (
    balance_indices,
    count_by,
    even_split,
    shares,
    unit_levels,
)


def test_even_split_by_hand():
    assert even_split([100, 100, 100], 10) == [3, 3, 4]
    assert even_split([1, 50, 50], 10) == [1, 4, 5]
    assert even_split([2, 3], 100) == [2, 3]  # quota above the supply keeps everything


@pytest.fixture
def nested():
    """3 categories, 5 rules, 6 captions; caption -> rule -> category is fixed.

    category 0: rule 0 (caption 0 x50, caption 1 x2), rule 1 (caption 2 x5)   -> 57 clips
    category 1: rule 2 (caption 3 x6)                                          ->  6 clips
    category 2: rule 3 (caption 4 x40), rule 4 (caption 5 x1)                 -> 41 clips
    """
    captions = np.repeat(np.arange(6), [50, 2, 5, 6, 40, 1])
    rules = np.array([0, 0, 1, 2, 3, 4])[captions]
    categories = np.array([0, 0, 0, 1, 2, 2])[captions]
    return categories, rules, captions


def kept_counts(nested, unit: str, **kwargs) -> tuple[list[int], ...]:
    """Clips kept per category, rule and caption."""
    levels = unit_levels(unit, *nested)
    kept = balance_indices(levels, seed=0, **kwargs)
    assert len(np.unique(kept)) == len(kept)
    return tuple(np.bincount(x[kept], minlength=x.max() + 1).tolist() for x in nested)


def test_category_unit_by_hand(nested):
    # Quota 6 (category 1's count). Category 0: rules 0/1 get 3/3, rule 0's 3 go 2/1 over
    # captions 0/1 (smallest first: caption 1 takes 3//2 = 1). Category 2: rule 4 keeps its
    # only clip, rule 3 the other 5.
    categories, rules, captions = kept_counts(nested, "category")
    assert categories == [6, 6, 6]
    assert rules == [3, 3, 6, 5, 1]
    assert captions == [2, 1, 3, 6, 5, 1]


def test_category_unit_with_a_per_unit_target(nested):
    # 20 per category: category 0 gives rule 1 all 5 and rule 0 15 (caption 1 both of its
    # clips, caption 0 13); category 1 has only 6; category 2: rule 4 1, rule 3 19.
    categories, rules, captions = kept_counts(nested, "category", per_unit=20)
    assert categories == [20, 6, 20]
    assert rules == [15, 5, 6, 19, 1]
    assert captions == [13, 2, 5, 6, 19, 1]


def test_rule_unit_by_hand(nested):
    # Quota 1 (rule 4's count): every rule keeps one clip; in rule 0 it goes to caption 0
    # (caption 1, filled first, gets 1 // 2 = 0).
    categories, rules, captions = kept_counts(nested, "rule")
    assert rules == [1, 1, 1, 1, 1]
    assert captions == [1, 0, 1, 1, 1, 1]
    assert categories == [2, 1, 2]


def test_rule_unit_with_a_per_unit_target(nested):
    categories, rules, captions = kept_counts(nested, "rule", per_unit=4)
    assert rules == [4, 4, 4, 4, 1]
    assert captions == [2, 2, 4, 4, 4, 1]
    assert categories == [8, 4, 5]


@pytest.mark.parametrize("unit", ["category", "rule"])
def test_balancing_is_deterministic_from_the_seed(nested, unit):
    levels = unit_levels(unit, *nested)
    a = balance_indices(levels, seed=3, per_unit=20)
    assert np.array_equal(a, balance_indices(levels, seed=3, per_unit=20))
    assert not np.array_equal(a, balance_indices(levels, seed=4, per_unit=20))


def test_none_keeps_everything_and_bad_arguments_are_named(nested):
    categories, rules, captions = nested
    assert len(balance_indices((rules, captions), seed=0, mode="none")) == len(rules)
    with pytest.raises(ValueError, match="'random' not in"):
        balance_indices((rules, captions), seed=0, mode="random")
    with pytest.raises(ValueError, match="'caption' not in"):
        unit_levels("caption", categories, rules, captions)
    with pytest.raises(ValueError, match="one length"):
        balance_indices((rules, captions[:-1]), seed=0)
    with pytest.raises(ValueError, match="per_unit must be >= 1"):
        balance_indices((rules, captions), seed=0, per_unit=0)


def test_count_by_lists_absent_names():
    assert count_by(["a", "b", "c"], np.array([0, 2, 2])) == {"a": 1, "b": 0, "c": 2}


def test_shares_are_fractions_of_the_total():
    assert shares({"a": 1, "b": 0, "c": 3}) == {"a": 0.25, "b": 0.0, "c": 0.75}
    assert shares({"a": 0}) == {"a": 0.0}
