"""The logged success window counts episodes in seed order, so short outcomes that end first
do not crowd it."""

from __future__ import annotations

import pytest

from zoo.rl.envs import EpisodeStats
from zoo.rl.window import SeedOrderWindow


def _ep(index: int, success: bool, length: int) -> EpisodeStats:
    return EpisodeStats(success, int(success), length, index)


def test_short_successes_that_end_first_wait_for_the_long_failure_before_them():
    window = SeedOrderWindow(size=3)
    # env A fails a long episode 0; env B meanwhile succeeds quickly in episodes 1, 2, 3
    window.add([_ep(1, True, 50), _ep(2, True, 50)])
    assert window.episodes == []  # "the last 100 that ended" would say 2/2 succeeded
    window.add([_ep(0, False, 300)])
    assert [e.success for e in window.episodes] == [False, True, True]
    window.add([_ep(3, True, 50)])
    assert [e.episode for e in window.episodes] == [1, 2, 3]  # size 3: the oldest left
    assert [e.success for e in window.episodes] == [True, True, True]
    window.add([_ep(5, False, 10)])
    assert [e.episode for e in window.episodes] == [1, 2, 3]  # 4 still running
    window.add([_ep(4, False, 400)])
    assert [e.episode for e in window.episodes] == [3, 4, 5]


def test_a_resumed_window_starts_at_its_first_episode_and_rejects_repeats():
    window = SeedOrderWindow(size=2, start=32)
    window.add([_ep(32, True, 5)])
    assert window.episodes == []  # not full yet
    window.add([_ep(33, False, 5)])
    assert [e.episode for e in window.episodes] == [32, 33]
    with pytest.raises(ValueError, match="episode 32 ended twice"):
        window.add([_ep(32, True, 5)])
    with pytest.raises(ValueError, match="size must be >= 1"):
        SeedOrderWindow(size=0)
