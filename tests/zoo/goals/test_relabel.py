"""Hindsight relabelling: goals stay in their episode, window and event segment."""

from __future__ import annotations

import numpy as np
import pytest

from zoo.goals.relabel import (
    NO_CAPTION,
    RelabelParams,
    drop_sequence_goals,
    episode_rng,
    relabel_episode,
)


def _pieces(goal_step: np.ndarray) -> list[tuple[int, int]]:
    """(first step, goal step) of every piece."""
    starts = np.flatnonzero(np.diff(np.concatenate([[-1], goal_step])) != 0)
    return [(int(s), int(goal_step[s])) for s in starts]


def _random_captions(rng: np.random.Generator, length: int) -> np.ndarray:
    """Runs of captions (or none) of random lengths, like a real episode's."""
    out = []
    while len(out) < length:
        caption = NO_CAPTION if rng.random() < 0.3 else int(rng.integers(0, 61))
        out += [caption] * int(rng.integers(1, 15))
    return np.array(out[:length])


@pytest.mark.parametrize("mode", ["event", "event_any", "plain"])
def test_goals_lie_ahead_within_the_gap_and_cover_every_step(mode: str) -> None:
    params = RelabelParams(mode=mode, min_gap=3, max_gap=10)
    rng = np.random.default_rng(0)
    for episode in range(50):
        captions = _random_captions(rng, int(rng.integers(1, 400)))
        out = relabel_episode(captions, params, episode_rng(0, 0, episode))
        length = len(captions)
        assert out.goal_step.shape == (length,) and out.goal_step.dtype == np.int64
        assert np.all(out.goal_step >= np.arange(length)) and np.all(out.goal_step < length)
        for start, goal in _pieces(out.goal_step):
            ahead = goal - start + 1
            assert ahead <= params.max_gap
            assert ahead >= params.min_gap or goal == length - 1  # the episode's end cuts a piece
            assert np.all(out.goal_step[start : goal + 1] == goal)
            assert len(set(out.conditioned[start : goal + 1])) == 1  # one decision per piece


def test_event_goals_take_the_first_segment_in_the_window() -> None:
    params = RelabelParams(mode="event", min_gap=1, max_gap=10, uncond_prob=0.0)
    rng = np.random.default_rng(1)
    used_event = 0
    for episode in range(50):
        captions = _random_captions(rng, 300)
        out = relabel_episode(captions, params, episode_rng(0, 0, episode))
        for start, goal in _pieces(out.goal_step):
            window = captions[start : min(start + params.max_gap, len(captions))]
            events = np.flatnonzero(window != NO_CAPTION)
            if len(events) == 0:
                assert not out.from_event[start]
                continue
            used_event += 1
            first = start + int(events[0])
            assert out.from_event[start]
            assert first <= goal, "the goal must not be before the first event in its window"
            # the goal is inside that first segment: same caption all the way from its start
            assert np.all(captions[first : goal + 1] == captions[first])
    assert used_event > 1000


def test_three_events_in_three_steps_get_three_goals() -> None:
    """The paper's example: place table, craft pickaxe, craft sword on consecutive steps."""
    table, pickaxe, sword = 13, 22, 25
    captions = np.array([NO_CAPTION, NO_CAPTION, table, pickaxe, sword, NO_CAPTION])
    out = relabel_episode(captions, RelabelParams(uncond_prob=0.0), np.random.default_rng(0))
    assert out.goal_step.tolist()[:5] == [2, 2, 2, 3, 4]


def test_event_any_also_labels_the_run_up_to_a_later_event() -> None:
    """Walking, then place table, then craft stone pickaxe: ``event`` only ever gives the first
    step the walk's goal; ``event_any`` gives it each of the three events in turn."""
    walk, table, pickaxe = 40, 13, 23
    captions = np.array([walk] * 4 + [table, pickaxe] + [NO_CAPTION] * 10)
    firsts = {"event": set(), "event_any": set()}
    for mode, seen in firsts.items():
        for seed in range(200):
            out = relabel_episode(
                captions, RelabelParams(mode=mode, uncond_prob=0.0), np.random.default_rng(seed)
            )
            seen.add(int(captions[out.goal_step[0]]))
            assert out.from_event[0]
    assert firsts == {"event": {walk}, "event_any": {walk, table, pickaxe}}


def test_event_any_goals_stay_inside_a_segment_of_their_window() -> None:
    params = RelabelParams(mode="event_any", min_gap=1, max_gap=10, uncond_prob=0.0)
    rng = np.random.default_rng(5)
    later = 0
    for episode in range(50):
        captions = _random_captions(rng, 300)
        out = relabel_episode(captions, params, episode_rng(0, 0, episode))
        for start, goal in _pieces(out.goal_step):
            window = captions[start : min(start + params.max_gap, len(captions))]
            if np.all(window == NO_CAPTION):
                assert not out.from_event[start]
                continue
            assert out.from_event[start] and captions[goal] != NO_CAPTION
            first = start + int(np.flatnonzero(window != NO_CAPTION)[0])
            later += bool(np.any(captions[first : goal + 1] != captions[first]))
    assert later > 100, "goals past the window's first segment must occur"


def test_plain_packing_ignores_events() -> None:
    captions = np.full(200, 5)
    captions[::7] = NO_CAPTION
    out = relabel_episode(captions, RelabelParams(mode="plain"), np.random.default_rng(0))
    assert not out.from_event.any()


def test_unconditional_share_is_the_configured_probability() -> None:
    params = RelabelParams(uncond_prob=0.1)
    rng = np.random.default_rng(2)
    pieces = conditioned = 0
    for episode in range(300):
        out = relabel_episode(_random_captions(rng, 300), params, episode_rng(3, 0, episode))
        starts = [start for start, _ in _pieces(out.goal_step)]
        pieces += len(starts)
        conditioned += int(out.conditioned[starts].sum())
    share = 1 - conditioned / pieces
    # ~15k pieces: the binomial std of the share is ~0.0025
    assert abs(share - 0.1) < 0.01, share


def test_relabelling_follows_seed_epoch_and_episode() -> None:
    captions = _random_captions(np.random.default_rng(4), 500)
    params = RelabelParams()

    def goals(seed: int, epoch: int, episode: int) -> list[int]:
        return relabel_episode(captions, params, episode_rng(seed, epoch, episode)).goal_step.tolist()

    assert goals(0, 0, 7) == goals(0, 0, 7)
    assert goals(0, 0, 7) != goals(0, 1, 7)
    assert goals(0, 0, 7) != goals(1, 0, 7)


def test_bad_parameters_are_named() -> None:
    with pytest.raises(ValueError, match="min_gap=0"):
        RelabelParams(min_gap=0)
    with pytest.raises(ValueError, match="relabel mode 'hindsight'"):
        RelabelParams(mode="hindsight")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="uncond_prob"):
        RelabelParams(uncond_prob=1.5)


def test_uncond_per_sequence_leaves_every_piece_conditioned() -> None:
    """With STEVE-1's per-sequence dropping, relabelling itself drops no piece."""
    captions = np.repeat(np.arange(40), 5)
    params = RelabelParams(uncond_prob=1.0, uncond_per="sequence")
    labels = relabel_episode(captions, params, np.random.default_rng(0))
    assert labels.conditioned.all()
    assert not relabel_episode(
        captions, RelabelParams(uncond_prob=1.0), np.random.default_rng(0)
    ).conditioned.any()


def test_drop_sequence_goals_zeroes_whole_sequences_at_the_given_rate() -> None:
    dropped = 0
    for episode in range(2000):
        sequence = {
            "episode": np.full(8, episode), "step": np.arange(8) + 100,
            "goal": np.ones((8, 4), np.float16), "goal_mask": np.ones(8, bool),
        }
        out = drop_sequence_goals(sequence, 0.1, seed=0, epoch=0)
        assert out["goal_mask"].all() or not out["goal_mask"].any()  # all or nothing
        assert (out["goal"] == 0).all() == (not out["goal_mask"].any())
        dropped += not out["goal_mask"].any()
        again = drop_sequence_goals(sequence, 0.1, seed=0, epoch=0)
        assert (again["goal_mask"] == out["goal_mask"]).all()  # the draw is a function of its key
    assert 150 < dropped < 250  # 10% of 2,000: 200 +- 3 sigma (sigma 13.4)


def test_unknown_uncond_per_is_refused() -> None:
    with pytest.raises(ValueError, match="uncond_per='episode'"):
        RelabelParams(uncond_per="episode")  # type: ignore[arg-type]
