"""Instruction schedules: which caption the expert pursues, switched on completion or timeout,
drawn from the episode's seed; and the schedule's captions and ids."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from zoo.agents.instructions import instruction_schedule
from zoo.captions.vocabulary import load_vocabulary
from zoo.envs.constants import Achievement, Block, Item
from zoo.envs.schema import State, empty_state
from zoo.envs.tasks import TASKS
from zoo.experts.scripted.config import ExpertConfig
from zoo.experts.scripted.goals import INSTRUCTIONS
from zoo.experts.scripted.schedule import (
    CAPTION_SETS,
    COMPLETED_BY,
    InstructionSchedule,
    InstructionScheduler,
    add_tallies,
    instruction_events,
    read_schedule,
    tally_outcomes,
)

ROOT = Path(__file__).resolve().parents[3]
WOOD, TABLE = "obtain wood", "place table on grass"


class Listener:
    """Stands in for the ScriptedExpert: keeps what it was told, per env."""

    def __init__(self, num_envs: int) -> None:
        self.num_envs = num_envs
        self.config = ExpertConfig()
        self.told: list[str | None] = [None] * num_envs

    def instruct(self, instructions: list[str | None], mask: np.ndarray) -> None:
        for i in np.flatnonzero(mask):
            self.told[i] = instructions[i]


def _schedule(captions=(WOOD, TABLE), timeout: int = 5) -> InstructionSchedule:
    vocab = load_vocabulary()
    return InstructionSchedule(tuple(captions), tuple(vocab[c].id for c in captions), timeout)


def _day(num_envs: int) -> State:
    """States of a rested player at noon."""
    state = empty_state(num_envs)
    state["light_level"][:] = 1.0
    state["player_vitals"][:] = 9
    return state


def _after(state: State, env: int, caption: str | None) -> State:
    """``state`` one step on, where env ``env`` did what completes ``caption`` (None: nothing)."""
    cur = {k: v.copy() for k, v in state.items()}
    if caption == WOOD:
        cur["inventory"][env, Item.WOOD] += 1
    elif caption == TABLE:
        cur["map"][env, 3, 3] = Block.TABLE
    return cur


def test_every_followable_caption_has_its_completing_achievement_and_a_caption_id() -> None:
    assert set(COMPLETED_BY) == set(INSTRUCTIONS) == set(CAPTION_SETS["captions"])
    subgoals = {s.instruction for t in TASKS.values() for s in t.subtasks}
    assert set(CAPTION_SETS["subgoals"]) == subgoals
    vocab = load_vocabulary()
    schedule = instruction_schedule("captions", 7)
    assert schedule.caption_ids == tuple(vocab[c].id for c in INSTRUCTIONS)
    assert schedule.timeout == 7


def test_a_caption_file_names_the_captions(tmp_path) -> None:
    path = tmp_path / "goals.txt"
    path.write_text("# the two of T2\nplace plant on grass\n\n  place table on grass  # second\n")
    assert read_schedule(str(path)) == (("place plant on grass", "place table on grass"), None)
    assert instruction_schedule(str(path), 9).caption_ids == (21, 13)


def test_a_caption_file_can_weight_its_captions(tmp_path) -> None:
    path = tmp_path / "drink.txt"
    path.write_text("obtain wood\nobtain drink | 4  # the learner's weak spot\nobtain sapling\n")
    schedule = instruction_schedule(str(path), 9)
    assert schedule.captions == (WOOD, "obtain drink", "obtain sapling")
    assert schedule.weights == (1.0, 4.0, 1.0)
    rng = np.random.default_rng(0)
    firsts = np.bincount([schedule.draw(rng) for _ in range(6000)], minlength=3) / 6000
    np.testing.assert_allclose(firsts, [1 / 6, 4 / 6, 1 / 6], atol=0.02)
    after_drink = [schedule.draw(rng, exclude=1) for _ in range(2000)]
    assert 1 not in after_drink and abs(np.mean(np.equal(after_drink, 0)) - 0.5) < 0.04
    after_wood = np.bincount([schedule.draw(rng, exclude=0) for _ in range(5000)], minlength=3)
    assert after_wood[0] == 0 and abs(after_wood[1] / 5000 - 0.8) < 0.02
    # without weights a file is uniform, drawn as before weights existed
    path.write_text("obtain wood\nobtain drink | 1\n")
    assert instruction_schedule(str(path), 9).weights is None
    path.write_text("obtain wood | lots\n")
    with pytest.raises(ValueError, match=r"drink.txt:1: weight 'lots' is not a number"):
        instruction_schedule(str(path), 9)
    with pytest.raises(ValueError, match="one weight > 0 per caption"):
        InstructionSchedule((WOOD, TABLE), (0, 13), 5, (1.0, 0.0))


def test_the_shipped_caption_files_are_schedules_the_expert_follows() -> None:
    """configs/instructions is what `zoo data generate --instructions FILE` is given: each file
    must load, and the weighted one must weight coal and drink alone."""
    files = sorted((ROOT / "configs" / "instructions").glob("*.txt"))
    assert files, "no caption files under configs/instructions"
    schedules = {f.stem: instruction_schedule(str(f), 200) for f in files}
    uniform = schedules["captions_no_ripe_plant"]
    weighted = schedules["captions_coal_drink_x3"]
    assert uniform.weights is None and weighted.captions == uniform.captions
    assert {c: w for c, w in zip(weighted.captions, weighted.weights) if w != 1.0} == {
        "obtain coal": 3.0, "obtain drink": 3.0,
    }


@pytest.mark.parametrize("captions, ids, timeout, message", [
    (("dance",), (0,), 5, r"cannot follow \['dance'\]"),
    ((WOOD, WOOD), (0, 0), 5, "appear twice"),
    ((WOOD,), (0, 1), 5, "one caption id"),
    ((), (), 5, "at least one caption"),
    ((WOOD,), (0,), 0, "timeout must be >= 1"),
])
def test_bad_schedules_are_refused(captions, ids, timeout, message) -> None:
    with pytest.raises(ValueError, match=message):
        InstructionSchedule(captions, ids, timeout)


def test_unknown_specs_and_captions_are_refused(tmp_path) -> None:
    with pytest.raises(ValueError, match="expected captions or subgoals or a file"):
        read_schedule("nothing-here")
    (tmp_path / "bad.txt").write_text("obtain wood\nget rich\n")
    with pytest.raises(ValueError, match=r"cannot follow \['get rich'\]"):
        instruction_schedule(str(tmp_path / "bad.txt"), 5)


def test_instructions_switch_on_completion_and_on_timeout() -> None:
    expert, schedule = Listener(2), _schedule(timeout=5)
    scheduler = InstructionScheduler(schedule, expert)
    scheduler.reset(np.array([11, 12]))
    assert expert.told == scheduler.current
    state = _day(2)
    first = scheduler.current[0]
    # env 0 completes its instruction on its third action; env 1 never does
    for t in range(3):
        cur = _after(state, 0, first if t == 2 else None)
        switched = scheduler.update(state, cur)
        state = cur
        assert switched.tolist() == [t == 2, False]
    assert scheduler.current[0] != first and expert.told[0] == scheduler.current[0]
    for _ in range(2):
        switched = scheduler.update(state, state)
    assert switched.tolist() == [False, True]  # env 1's fifth action: timed out
    first_id = dict(zip(schedule.captions, schedule.caption_ids))[first]
    assert scheduler.finish(0)[0] == [0, 3, first_id, "completed"]
    assert [s[:2] + s[3:] for s in scheduler.finish(1)] == [[0, 5, "timed_out"]]


def test_finish_keeps_the_episode_and_an_idle_env_adds_nothing_to_it() -> None:
    scheduler = InstructionScheduler(_schedule(timeout=2), Listener(1))
    scheduler.reset(np.array([5]))
    state = _day(1)
    scheduler.update(state, state)
    segments = scheduler.finish(0)
    for _ in range(5):  # no next episode: the env still steps until the shard is done
        scheduler.update(state, state)
    assert segments == [[0, 1, segments[0][2], "ended"]]


def test_the_last_instruction_ends_with_the_episode_and_an_empty_one_is_dropped() -> None:
    scheduler = InstructionScheduler(_schedule(timeout=2), Listener(1))
    scheduler.reset(np.array([5]))
    state = _day(1)
    for _ in range(3):
        scheduler.update(state, state)
    segments = scheduler.finish(0)
    assert [s[1] - s[0] for s in segments] == [2, 1] and segments[-1][3] == "ended"
    scheduler.reset(np.array([5]))
    for _ in range(2):
        scheduler.update(state, state)  # timed out on the last action: nothing after it
    assert [s[3] for s in scheduler.finish(0)] == ["timed_out"]


def test_at_night_the_expert_rests_untold_and_gets_a_new_instruction_by_day() -> None:
    expert = Listener(1)
    scheduler = InstructionScheduler(_schedule(timeout=50), expert)
    scheduler.reset(np.array([4]))
    first = scheduler.current[0]
    day = _day(1)
    night = {**day, "light_level": np.array([0.3], np.float32)}
    asleep = {**night, "player_sleeping": np.array([True])}
    awake_tired = {**day, "player_vitals": np.array([[9, 9, 9, 3]], np.int8)}
    told = []
    for prev, cur in [(day, day), (day, night), (night, asleep), (asleep, day),
                      (day, awake_tired), (awake_tired, day), (day, day)]:
        scheduler.update(prev, cur)
        told.append((scheduler.ids[0], expert.told[0]))
    assert [t[1] is None for t in told] == [False, True, True, False, True, False, False]
    assert all((ids == -1) == (text is None) for ids, text in told)
    assert told[3][1] != first  # a new instruction after the night
    segments = scheduler.finish(0)
    assert [s[:2] + s[3:] for s in segments] == [
        [0, 2, "interrupted"], [4, 5, "interrupted"], [6, 7, "ended"],
    ]


def test_draws_follow_the_seed_alone_and_never_repeat_an_instruction() -> None:
    captions = CAPTION_SETS["captions"]

    def drawn(seeds, steps: int = 40) -> list[list[str]]:
        scheduler = InstructionScheduler(_schedule(captions, timeout=1), Listener(len(seeds)))
        scheduler.reset(np.array(seeds))
        state = _day(len(seeds))
        out = [scheduler.current]
        for _ in range(steps):
            scheduler.update(state, state)
            out.append(scheduler.current)
        return [list(col) for col in zip(*out)]

    alone, together = drawn([3]), drawn([9, 3])
    assert together[1] == alone[0] and together[0] != alone[0]
    assert all(a != b for a, b in zip(alone[0], alone[0][1:]))
    assert len(set(alone[0])) > 5


def test_placing_stone_counts_on_grass_each_time_and_not_on_water() -> None:
    prev = _day(3)
    prev["map"][:, 5, 5] = [Block.GRASS, Block.WATER, Block.GRASS]
    prev["achievements"][2, Achievement.PLACE_STONE] = True  # a repeat
    cur = {k: v.copy() for k, v in prev.items()}
    cur["map"][:, 5, 5] = Block.STONE
    assert instruction_events(prev, cur)[:, Achievement.PLACE_STONE].tolist() == [True, False, True]


def test_tallies_count_outcomes_per_caption_and_add_up() -> None:
    schedule = _schedule()
    wood, table = schedule.caption_ids
    segments = [[0, 4, wood, "completed"], [4, 9, table, "timed_out"], [9, 10, wood, "ended"]]
    tally = tally_outcomes(segments, schedule)
    assert tally[WOOD] == {
        "completed": 1, "timed_out": 0, "interrupted": 0, "ended": 1, "completed_actions": 4,
    }
    assert tally[TABLE]["timed_out"] == 1
    assert add_tallies([tally, tally])[WOOD]["completed_actions"] == 8
