"""Rule balancing: the paper balances CrafterCaption uniformly over rules (60.8M -> 2.3M pairs).

Every rule keeps the same number of samples: the count of the rarest rule that fired (or a
chosen ``per_rule`` target; rules with fewer keep all theirs). Inside a rule the quota is
spread as evenly as possible over its captions, so "craft iron sword" is not drowned by
"craft wood pickaxe", and the samples kept per caption are a seeded random subset.
"""

from __future__ import annotations

import numpy as np

BALANCE_MODES = ("uniform", "none")


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


def balance_indices(
    rules: np.ndarray,
    captions: np.ndarray,
    seed: int | np.random.SeedSequence,
    mode: str = "uniform",
    per_rule: int | None = None,
) -> np.ndarray:
    """Indices (sorted) of the samples kept.

    Args:
        rules: (n,) rule id per sample.
        captions: (n,) caption id per sample.
        seed: seeds the choice of samples kept; same inputs and seed -> same indices.
        mode: "uniform" (same count per rule) or "none" (keep everything).
        per_rule: target per rule for "uniform"; default: the rarest rule's count.
    """
    rules, captions = np.asarray(rules), np.asarray(captions)
    if mode not in BALANCE_MODES:
        raise ValueError(f"balance mode {mode!r} not in {BALANCE_MODES}")
    if len(rules) != len(captions):
        raise ValueError(f"rules ({len(rules)}) and captions ({len(captions)}) differ in length")
    if mode == "none" or len(rules) == 0:
        return np.arange(len(rules))
    rule_ids, rule_counts = np.unique(rules, return_counts=True)
    quota = int(rule_counts.min()) if per_rule is None else int(per_rule)
    if quota < 1:
        raise ValueError(f"per_rule must be >= 1, got {per_rule}")
    rng = np.random.default_rng(seed)
    kept = []
    for rule in rule_ids:
        in_rule = np.flatnonzero(rules == rule)
        caption_ids, caption_counts = np.unique(captions[in_rule], return_counts=True)
        for caption, n in zip(caption_ids, even_split(caption_counts.tolist(), quota)):
            pool = in_rule[captions[in_rule] == caption]
            kept.append(rng.choice(pool, size=n, replace=False) if n < len(pool) else pool)
    return np.sort(np.concatenate(kept))


def count_by(names: list[str], ids: np.ndarray) -> dict[str, int]:
    """Samples per name (ids index ``names``); names with no sample are listed with 0."""
    counts = np.bincount(np.asarray(ids, np.int64), minlength=len(names))
    return {name: int(c) for name, c in zip(names, counts)}
