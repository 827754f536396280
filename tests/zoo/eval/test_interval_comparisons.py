"""The two comparisons the reports give beside Wilson 95% intervals: disjoint intervals (every
"separated" verdict) and the pooled two-proportion z-test, against hand-computed values."""

from __future__ import annotations

import math

import pytest

from zoo.eval.stats import disjoint_above, p_text, two_proportion_p


@pytest.mark.parametrize(
    "a, b, above",
    [
        ([50.0, 60.0], [40.0, 49.9], True),  # a gap of 0.1 points
        ([50.0, 60.0], [40.0, 50.0], False),  # touching at 50: a shared point, not disjoint
        ([50.0, 60.0], [40.0, 55.0], False),  # overlapping
        ([40.0, 49.9], [50.0, 60.0], False),  # disjoint, but below
    ],
)
def test_disjoint_above_needs_a_gap_between_the_intervals(
    a: list[float], b: list[float], above: bool
) -> None:
    assert disjoint_above(a, b) is above


def test_two_proportion_p_by_hand() -> None:
    """38/50 vs 27/50: pooled rate 65/100 = 0.65, standard error sqrt(0.65 * 0.35 * (1/50 +
    1/50)) = sqrt(0.0091) = 0.095394, z = (0.76 - 0.54) / 0.095394 = 2.30623, two-sided p =
    erfc(2.30623 / sqrt 2) = 2 (1 - Phi(2.30623)) = 0.021098 (yet their Wilson 95% intervals,
    62.6-85.7% and 40.4-67.0%, overlap). Unequal n, 10/20 vs 10/40: pooled 1/3, standard error
    sqrt(1/3 * 2/3 * (1/20 + 1/40)) = sqrt(1/60) = 0.129099, z = 0.25 / 0.129099 = 1.93649, p =
    0.052808. 50/50 vs 0/50: pooled 0.5, standard error 0.1, z = 10, p = erfc(10 / sqrt 2)."""
    assert two_proportion_p(38, 50, 27, 50) == pytest.approx(0.021098, abs=1e-6)
    assert two_proportion_p(27, 50, 38, 50) == pytest.approx(0.021098, abs=1e-6)  # two-sided
    assert two_proportion_p(10, 20, 10, 40) == pytest.approx(0.052808, abs=1e-6)
    assert two_proportion_p(10, 40, 10, 20) == pytest.approx(0.052808, abs=1e-6)
    assert two_proportion_p(50, 50, 0, 50) == pytest.approx(math.erfc(10 / math.sqrt(2)))
    assert two_proportion_p(31, 50, 31, 50) == 1.0  # z = 0
    assert two_proportion_p(0, 50, 0, 20) == two_proportion_p(9, 9, 4, 4) == 1.0  # no variance


@pytest.mark.parametrize("k1, n1, k2, n2", [(38, 50, 27, 50), (10, 20, 10, 40), (3, 7, 90, 100),
                                            (99, 100, 92, 100), (1, 50, 0, 50)])
def test_two_proportion_p_matches_scipy(k1: int, n1: int, k2: int, n2: int) -> None:
    """Cross-check: the pooled z-test is the uncorrected chi-squared test of the 2 x 2 table
    (chi2 = z squared), which scipy computes on its own."""
    stats = pytest.importorskip("scipy.stats")
    table = [[k1, n1 - k1], [k2, n2 - k2]]
    expected = stats.chi2_contingency(table, correction=False).pvalue
    assert two_proportion_p(k1, n1, k2, n2) == pytest.approx(expected, rel=1e-9)


def test_two_proportion_p_rejects_impossible_counts() -> None:
    for counts in ((51, 50, 0, 50), (0, 50, -1, 50), (0, 0, 0, 50)):
        with pytest.raises(ValueError, match="need 0 <= k <= n and n >= 1"):
            two_proportion_p(*counts)


def test_p_values_print_with_three_decimals() -> None:
    assert [p_text(p) for p in (0.021098, 1.0, 0.001, 0.000999)] == [
        "0.021", "1.000", "0.001", "< 0.001"]
