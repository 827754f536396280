"""What each relabelling mode teaches, counted on a constructed caption sequence."""

from __future__ import annotations

import numpy as np

from zoo.captions.vocabulary import load_vocabulary
from zoo.goals.relabel import NO_CAPTION
from zoo.goals.relabel_stats import mode_stats


def _episodes() -> dict[int, np.ndarray]:
    """Walk 4 steps, place a table, craft a stone pickaxe, then nothing: 40 such episodes."""
    vocab = load_vocabulary()
    walk = next(c.id for c in vocab.captions if c.category == "movement")
    table, pickaxe = vocab["place table on grass"].id, vocab["craft stone pickaxe"].id
    captions = np.array([walk] * 4 + [table, pickaxe] + [NO_CAPTION] * 10)
    return {episode: captions for episode in range(40)}


def test_first_segment_never_gives_the_pickaxe_a_run_up() -> None:
    stats = mode_stats(_episodes(), "event")["captions"]["craft stone pickaxe"]
    assert stats["steps"] == 40  # only the crafting step itself, once per episode
    assert stats["mean_ahead"] == 0 and stats["run_up_share"] == 0


def test_any_segment_labels_the_table_steps_with_the_pickaxe() -> None:
    stats = mode_stats(_episodes(), "event_any")["captions"]["craft stone pickaxe"]
    assert stats["steps"] > 40 and stats["mean_ahead"] > 0
    assert 0 < stats["run_up_share"] <= 1
    total = mode_stats(_episodes(), "event_any")
    assert total["steps"] == 40 * 16
    assert 0 < total["achievement_goal_share"] < 1
