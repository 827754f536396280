"""Goal sources for C-Steve-1: hindsight, the commanded instructions (caption or completing
clip), and their mix, on synthetic episodes where every answer is known."""

from __future__ import annotations

import numpy as np
import pytest

from zoo.goals.relabel import Relabelling
from zoo.goals.sources import CAPTION_GOAL_STEP, GoalSourceParams, episode_goals

D = 4
SEGMENT = 3


def _episode(segments: int, seed: int = 0):
    """Goal rows, hindsight labels (each step its own goal) and segments of SEGMENT actions,
    captions 0..4 in turn, completed and timed out in turn, the last one ended."""
    rng = np.random.default_rng(seed)
    length = segments * SEGMENT + 1
    goals = rng.normal(size=(length, D)).astype(np.float16)
    labels = Relabelling(np.arange(length), np.ones(length, bool), np.zeros(length, bool))
    outcomes = ["completed", "timed_out"]
    parts = [
        [k * SEGMENT, (k + 1) * SEGMENT, k % 5, outcomes[k % 2]] for k in range(segments)
    ]
    parts[-1][3] = "ended"
    return goals, labels, parts


PROTOTYPES = {c: np.full(D, c + 1, np.float16) for c in range(4)}  # caption 4 never fired


def _goals(source: str, goal: str = "caption", weight: float = 0.5, segments: int = 20,
           conditioned: np.ndarray | None = None) -> tuple[dict, np.ndarray, list]:
    goals, labels, parts = _episode(segments)
    if conditioned is not None:
        labels.conditioned = conditioned
    params = GoalSourceParams(source, weight, goal)
    out = episode_goals(goals, labels, parts, params, PROTOTYPES, np.random.default_rng(1))
    return out, goals, parts


def test_hindsight_ignores_the_instructions() -> None:
    out, goals, _ = _goals("hindsight")
    np.testing.assert_array_equal(out["goal"], goals)
    np.testing.assert_array_equal(out["goal_step"], np.arange(len(goals)))


def test_commanded_captions_give_each_step_its_captions_embedding() -> None:
    out, goals, parts = _goals("commanded")
    for start, stop, caption, _ in parts:
        if caption in PROTOTYPES:
            assert (out["goal"][start:stop] == PROTOTYPES[caption]).all()
            assert (out["goal_step"][start:stop] == CAPTION_GOAL_STEP).all()
        else:  # a caption without embedding keeps hindsight goals
            np.testing.assert_array_equal(out["goal"][start:stop], goals[start:stop])
    np.testing.assert_array_equal(out["goal"][-1], goals[-1])  # the final observation


def test_commanded_completions_give_the_completing_clip_or_hindsight() -> None:
    out, goals, parts = _goals("commanded", "completion")
    for start, stop, _, outcome in parts:
        if outcome == "completed":
            assert (out["goal_step"][start:stop] == stop - 1).all()
            assert (out["goal"][start:stop] == goals[stop - 1]).all()
        else:
            np.testing.assert_array_equal(out["goal_step"][start:stop], np.arange(start, stop))


@pytest.mark.parametrize("weight", [0.2, 0.7])
def test_mix_gives_commanded_goals_to_its_share_of_segments(weight: float) -> None:
    segments = 3000
    out, goals, parts = _goals("mix", weight=weight, segments=segments)
    commanded = (out["goal_step"] == CAPTION_GOAL_STEP)[[s[0] for s in parts]]
    with_embedding = np.array([s[2] in PROTOTYPES for s in parts])
    share = commanded[with_embedding].mean()
    assert abs(share - weight) < 0.04  # ~5 standard deviations at 2,400 segments
    kept = out["goal_step"] != CAPTION_GOAL_STEP  # the others keep their hindsight goals
    np.testing.assert_array_equal(out["goal"][kept], goals[kept])


def test_unconditional_steps_stay_unconditional_whatever_the_source() -> None:
    conditioned = np.arange(20 * SEGMENT + 1) % 4 != 0
    out, _, _ = _goals("commanded", conditioned=conditioned)
    assert (out["goal"][~conditioned] == 0).all() and (out["goal"][conditioned] != 0).any()
    np.testing.assert_array_equal(out["goal_mask"], conditioned)


def test_episodes_without_instructions_keep_hindsight_goals() -> None:
    goals, labels, _ = _episode(5)
    params = GoalSourceParams("commanded")
    out = episode_goals(goals, labels, None, params, PROTOTYPES, np.random.default_rng(0))
    np.testing.assert_array_equal(out["goal"], goals)


@pytest.mark.parametrize("kwargs, message", [
    ({"source": "oracle"}, "goal_source='oracle'"),
    ({"commanded_goal": "text"}, "commanded_goal='text'"),
    ({"source": "mix", "commanded_weight": 1.5}, "must lie in"),
])
def test_bad_goal_sources_are_refused(kwargs, message) -> None:
    with pytest.raises(ValueError, match=message):
        GoalSourceParams(**kwargs)


def test_prior_goals_draw_one_of_the_captions_samples_per_segment() -> None:
    """``prior``: prototypes hold K goals per caption; a segment gets one of them throughout."""
    samples = {c: np.stack([np.full(D, 10 * c + k, np.float16) for k in range(5)])
               for c in range(4)}
    goals, labels, parts = _episode(40)
    params = GoalSourceParams("commanded", 1.0, "prior")
    out = episode_goals(goals, labels, parts, params, samples, np.random.default_rng(1))
    drawn = set()
    for start, stop, caption, _ in parts:
        if caption not in samples:
            np.testing.assert_array_equal(out["goal"][start:stop], goals[start:stop])
            continue
        row = out["goal"][start]
        assert (out["goal"][start:stop] == row).all()
        assert any((row == s).all() for s in samples[caption])
        drawn.add((caption, float(row[0])))
    assert len(drawn) > 8  # several samples of the same caption were drawn


def test_completed_segments_only_leave_the_others_their_hindsight_goals() -> None:
    goals, labels, parts = _episode(20)
    params = GoalSourceParams("commanded", 1.0, "caption", "completed")
    out = episode_goals(goals, labels, parts, params, PROTOTYPES, np.random.default_rng(1))
    for start, stop, caption, outcome in parts:
        if outcome == "completed" and caption in PROTOTYPES:
            assert (out["goal"][start:stop] == PROTOTYPES[caption]).all()
        else:
            np.testing.assert_array_equal(out["goal"][start:stop], goals[start:stop])
    with pytest.raises(ValueError, match="commanded_segments='some'"):
        GoalSourceParams("commanded", 1.0, "caption", "some")


def test_hindsight_goals_are_the_clips_of_the_relabelled_goal_steps() -> None:
    """The paper's example (place table, craft pickaxe, craft sword on steps 2, 3, 4): steps
    0-2 get the table clip (step 2's row), step 3 the pickaxe's, step 4 the sword's; the
    unconditional piece (step 5's own) gets zeros. Each row is a step's own clip embedding, so
    a goal taken from the step itself or from an earlier one shows as another row."""
    goals = (np.arange(6 * D).reshape(6, D) + 1).astype(np.float16)  # row t: 4t+1 .. 4t+4
    labels = Relabelling(
        np.array([2, 2, 2, 3, 4, 5]), np.array([True] * 5 + [False]), np.ones(6, bool)
    )
    out = episode_goals(goals, labels, None, GoalSourceParams(), {}, np.random.default_rng(0))
    expected = np.array([goals[2], goals[2], goals[2], goals[3], goals[4], np.zeros(D)])
    np.testing.assert_array_equal(out["goal"], expected.astype(np.float16))
    np.testing.assert_array_equal(out["goal_step"], [2, 2, 2, 3, 4, 5])
    np.testing.assert_array_equal(out["goal_mask"], [True] * 5 + [False])
