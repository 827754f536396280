"""Balancing CrafterCaption: the paper evens out rule *categories* (60.8M -> 2.3M pairs).

Appendix C, Training Details: "As we observed the imbalance between rule categories in the
original CrafterCaption dataset, we balanced the CrafterCaption dataset uniformly." So the
default unit is the category: each of the 4 categories keeps the same number of clips (the
rarest category's count, or a chosen ``per_unit``; a category with fewer keeps all its clips).
``unit="rule"`` evens out the 15 rules instead.

Below the unit the quota is spread as evenly as possible level by level (category -> rules ->
captions; rule -> captions). Without that, balancing categories would just rescale the raw mix
inside one: Achievement would be mostly "obtain wood" and nearly never "go to sleep" or
"craft iron sword", and the balancing would not help the rare behaviours it is there for.
The clips a caption keeps are a seeded random subset.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

BALANCE_MODES = ("uniform", "none")
BALANCE_UNITS = ("category", "rule")
DEFAULT_BALANCE_UNIT = "category"


def even_split(counts: list[int], quota: int) -> list[int]:
    """Split ``quota`` over groups as evenly as possible, no group above its count.

    Groups are filled smallest first; each takes its fair share of what is left, so uncapped
    groups differ by at most one.
    """
    take = [0] * len(counts)
    remaining = min(quota, sum(counts))
    order = sorted(range(len(counts)), key=lambda i: counts[i])
    for k, i in enumerate(order):
        take[i] = min(counts[i], remaining // (len(order) - k))
        remaining -= take[i]
    return take


def unit_levels(
    unit: str, categories: np.ndarray, rules: np.ndarray, captions: np.ndarray
) -> tuple[np.ndarray, ...]:
    """The label levels ``balance_indices`` takes for ``unit``: the unit, then those below it."""
    if unit not in BALANCE_UNITS:
        raise ValueError(f"balance unit {unit!r} not in {BALANCE_UNITS}")
    return (categories, rules, captions)[BALANCE_UNITS.index(unit) :]


def _spread(
    levels: Sequence[np.ndarray], idx: np.ndarray, take: int
) -> list[tuple[np.ndarray, int]]:
    """(pool, count) per finest group: ``take`` of the samples ``idx`` split evenly over the
    groups of ``levels[0]``, each share split the same way over the next level, and so on."""
    if not levels:
        return [(idx, take)]
    labels = levels[0][idx]
    groups, counts = np.unique(labels, return_counts=True)
    return [
        leaf
        for group, n in zip(groups, even_split(counts.tolist(), take))
        for leaf in _spread(levels[1:], idx[labels == group], n)
    ]


def balance_indices(
    levels: Sequence[np.ndarray],
    seed: int | np.random.SeedSequence,
    mode: str = "uniform",
    per_unit: int | None = None,
) -> np.ndarray:
    """Indices (sorted) of the samples kept.

    Args:
        levels: per-sample label arrays, coarsest first (see ``unit_levels``). ``levels[0]`` is
            the unit every value of which keeps the same count; the quota of a unit is spread
            evenly over the groups of ``levels[1]`` in it, and so on down.
        seed: seeds the choice of samples kept; same inputs and seed -> same indices.
        mode: "uniform" (same count per unit) or "none" (keep everything).
        per_unit: target per unit for "uniform"; default: the rarest unit's count.
    """
    levels = [np.asarray(level) for level in levels]
    if mode not in BALANCE_MODES:
        raise ValueError(f"balance mode {mode!r} not in {BALANCE_MODES}")
    if not levels or len({len(level) for level in levels}) != 1:
        raise ValueError(f"need label levels of one length, got {[len(x) for x in levels]}")
    n = len(levels[0])
    if mode == "none" or n == 0:
        return np.arange(n)
    units, unit_counts = np.unique(levels[0], return_counts=True)
    quota = int(unit_counts.min()) if per_unit is None else int(per_unit)
    if quota < 1:
        raise ValueError(f"per_unit must be >= 1, got {per_unit}")
    rng = np.random.default_rng(seed)
    kept = []
    for unit, count in zip(units, unit_counts):
        in_unit = np.flatnonzero(levels[0] == unit)
        for pool, take in _spread(levels[1:], in_unit, min(quota, int(count))):
            kept.append(rng.choice(pool, size=take, replace=False) if take < len(pool) else pool)
    return np.sort(np.concatenate(kept))


def count_by(names: Sequence[str], ids: np.ndarray) -> dict[str, int]:
    """Samples per name (ids index ``names``); names with no sample are listed with 0."""
    counts = np.bincount(np.asarray(ids, np.int64), minlength=len(names))
    return {name: int(c) for name, c in zip(names, counts)}


def shares(counts: dict[str, int]) -> dict[str, float]:
    """Each name's fraction of all the samples counted (4 decimals; all 0 when none)."""
    total = sum(counts.values())
    return {name: round(n / total, 4) if total else 0.0 for name, n in counts.items()}
