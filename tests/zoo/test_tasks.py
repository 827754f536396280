"""Task variants: what each sets in both games, and ordered sub-task detection on
hand-built state sequences."""

from __future__ import annotations

import numpy as np
import pytest

from zoo.captions.vocabulary import load_vocabulary
from zoo.envs.constants import Achievement, Block, Item
from zoo.envs.schema import empty_state
from zoo.envs.tasks import (
    LONG_HORIZON_TASKS,
    SINGLE_STEP_TASKS,
    TASKS,
    TaskEnv,
    TaskProgress,
    TaskSpec,
    achievement_events,
    get_task,
)

EXPECTED_INVENTORY = {
    "collect_sapling": {},
    "collect_drink": {},
    "make_wood_pickaxe": {Item.WOOD: 3},
    "make_wood_sword": {Item.WOOD: 3},
    "make_stone_pickaxe": {Item.WOOD: 3, Item.STONE: 1, Item.WOOD_PICKAXE: 1},
    "make_stone_sword": {Item.WOOD: 3, Item.STONE: 1, Item.WOOD_PICKAXE: 1},
    "T1": {}, "T2": {}, "T3": {}, "T4": {},
}


# Craftax compiles its step, and the task edit, for ~30 s each on a busy CPU: its checks run
# with -m slow (as does the expert sweep, which plays every task in both games).
GAMES = ["crafter", pytest.param("craftax", marks=pytest.mark.slow)]


@pytest.fixture
def game(request):
    """The session's shared env of the game named by the test's ``game_name`` parameter."""
    return request.getfixturevalue(f"{request.param}_env")


def test_registry_names_the_paper_tasks_with_caption_instructions():
    assert set(SINGLE_STEP_TASKS) == {
        "collect_sapling", "collect_drink", "make_wood_pickaxe", "make_wood_sword",
        "make_stone_pickaxe", "make_stone_sword",
    }
    assert LONG_HORIZON_TASKS == ("T1", "T2", "T3", "T4")
    captions = load_vocabulary()
    for task in TASKS.values():
        assert all(text in captions for text in task.instructions), task.name
        assert task.max_steps == (1000 if task.name in LONG_HORIZON_TASKS else 500)
        assert task.peaceful == (task.name == "T1")
    assert TASKS["T4"].instructions == ("obtain coal", "craft wood pickaxe", "obtain stone")
    with pytest.raises(ValueError, match="unknown task 'T9'; expected one of"):
        get_task("T9")


def test_bad_specs_are_rejected():
    sub = TASKS["T2"].subtasks
    with pytest.raises(ValueError, match="no sub-tasks"):
        TaskSpec("empty", ())
    with pytest.raises(ValueError, match="item counts must lie in"):
        TaskSpec("greedy", sub, {Item.WOOD: 12})


@pytest.mark.parametrize("game", GAMES, indirect=True)
def test_each_variant_sets_exactly_its_inventory(game):
    for name in TASKS:
        step = TaskEnv(game, TASKS[name]).reset(np.array([3, 4]))
        want = np.zeros(len(Item), np.int16)
        for item, count in EXPECTED_INVENTORY[name].items():
            want[item] = count
        np.testing.assert_array_equal(step.state["inventory"], np.stack([want, want]), name)
        assert not step.state["achievements"].any()  # given items unlock nothing


@pytest.mark.parametrize("game", GAMES, indirect=True)
def test_reset_rewrites_masked_envs_only_and_their_frames(game):
    plain = game.reset(np.array([5, 6])).frames.copy()
    step = TaskEnv(game, TASKS["make_stone_sword"]).reset(np.array([5, 6]))
    assert (plain != step.frames).any(axis=(1, 2, 3)).all()  # the frames show the items
    if game.name == "crafter":
        np.testing.assert_array_equal(step.frames[0], game.raw_state[0].render())
    else:
        assert np.asarray(game.raw_state.inventory.wood_pickaxe).tolist() == [1, 1]
    step = TaskEnv(game, TASKS["T2"]).reset(np.array([7, 8]), np.array([True, False]))
    assert step.state["inventory"][0].sum() == 0
    assert step.state["inventory"][1, Item.WOOD] == 3  # not reset: still the last task's


@pytest.mark.parametrize("game", GAMES, indirect=True)
def test_the_game_itself_holds_the_items(game):
    env = TaskEnv(game, TASKS["make_stone_sword"])
    env.reset(np.array([5, 6]))
    step = env.step(np.zeros(2, np.int32))  # noop: what the game exports after a step
    assert step.state["inventory"][:, Item.WOOD_PICKAXE].tolist() == [1, 1]
    assert step.state["inventory"][:, Item.WOOD].tolist() == [3, 3]


def _no_mobs(state) -> bool:
    return all(
        not state[f"{kind}_status"][:, :, 0].any()
        for kind in ("cows", "zombies", "skeletons", "arrows")
    ) and not state["mob_map"].any()


@pytest.mark.parametrize("game", GAMES, indirect=True)
def test_t1_has_no_mobs_and_no_decay_while_other_tasks_do(game):
    rng = np.random.default_rng(0)
    actions = rng.choice([1, 2, 3, 4, 5, 5, 5], size=(150, 2)).astype(np.int32)
    env = TaskEnv(game, TASKS["T1"])
    step = env.reset(np.array([11, 12]))
    assert _no_mobs(step.state)
    for a in actions:
        step = env.step(a)
        assert _no_mobs(step.state)
        assert (step.state["player_vitals"][:, 1:] == 9).all()
        assert (step.state["player_vitals"][:, 0] == 9).all()  # nothing hurts the player
    if game.name == "crafter":
        from crafter import objects

        kinds = (objects.Zombie, objects.Skeleton, objects.Cow, objects.Arrow)
        assert not any(isinstance(o, kinds) for g in game.raw_state for o in g._world.objects)
    else:
        raw = game.raw_state
        assert not any(np.asarray(getattr(raw, k).mask).any() for k in ("zombies", "cows"))
    env = TaskEnv(game, TASKS["T2"])
    step = env.reset(np.array([11, 12]))
    mobs = []
    for a in actions:
        step = env.step(a)
        mobs.append(not _no_mobs(step.state))
    assert any(mobs)  # the ordinary game spawns mobs (cows at least) within 150 steps
    assert (step.state["player_vitals"][:, 1:] < 9).any()


# --- events and ordered progress on hand-built states -------------------------------------
def _states(n: int):
    """n consecutive one-env states on an all-grass map, to be edited step by step."""
    base = empty_state(1)
    base["map"][0] = Block.GRASS
    return [{k: v.copy() for k, v in base.items()} for _ in range(n)]


def _run(task: TaskSpec, states) -> TaskProgress:
    progress = TaskProgress(task, 1)
    progress.reset(states[0])
    for state in states[1:]:
        progress.update(state)
    return progress


def _carry(states, t: int, edit) -> None:
    """Apply ``edit`` to the states from step t on (what happened stays in the inventory)."""
    for state in states[t:]:
        edit(state)


def test_events_count_repeats_not_only_first_unlocks():
    prev, cur = _states(2)
    prev["achievements"][0, Achievement.MAKE_WOOD_PICKAXE] = True  # Craftax: stays True
    cur["achievements"][0, Achievement.MAKE_WOOD_PICKAXE] = True
    prev["inventory"][0, Item.WOOD_PICKAXE] = 1
    cur["inventory"][0, Item.WOOD_PICKAXE] = 2
    prev["inventory"][0, Item.SAPLING] = 1  # a sapling spent: a plant placed
    prev["map"][0, 5, 5] = Block.RIPE_PLANT
    cur["map"][0, 5, 5] = Block.PLANT  # eaten (both games reset an eaten plant)
    cur["map"][0, 7, 7] = Block.TABLE
    cur["player_vitals"][0, 2] = 3  # drank
    events = achievement_events(prev, cur)[0]
    happened = {Achievement(i).name for i in np.flatnonzero(events)}
    assert happened == {
        "MAKE_WOOD_PICKAXE", "PLACE_PLANT", "EAT_PLANT", "PLACE_TABLE", "COLLECT_DRINK",
    }


def test_t2_ignores_a_table_placed_before_the_plant():
    states = _states(6)
    _carry(states, 1, lambda s: s["map"][0].__setitem__((3, 3), Block.TABLE))  # out of order
    _carry(states, 2, lambda s: s["inventory"][0].__setitem__(Item.SAPLING, 1))
    _carry(states, 3, lambda s: s["inventory"][0].__setitem__(Item.SAPLING, 0))  # plant placed
    _carry(states, 3, lambda s: s["map"][0].__setitem__((4, 4), Block.PLANT))
    progress = _run(TASKS["T2"], states[:5])
    assert progress.done_at.tolist() == [[3, -1]] and not progress.success[0]
    _carry(states, 5, lambda s: s["map"][0].__setitem__((6, 6), Block.TABLE))
    progress = _run(TASKS["T2"], states)
    assert progress.done_at.tolist() == [[3, 5]] and progress.success[0]


def test_t4_needs_a_wood_pickaxe_made_after_the_coal():
    states = _states(7)

    def give(t, item, count, ach=None):
        def edit(s):
            s["inventory"][0, item] = count
            if ach is not None:
                s["achievements"][0, ach] = True

        _carry(states, t, edit)

    give(1, Item.WOOD_PICKAXE, 1, Achievement.MAKE_WOOD_PICKAXE)  # before the coal: no count
    give(2, Item.STONE, 1, Achievement.COLLECT_STONE)  # out of order
    give(3, Item.COAL, 1, Achievement.COLLECT_COAL)
    give(4, Item.STONE, 2)  # stone again, still before the second pickaxe
    give(5, Item.WOOD_PICKAXE, 2)  # the flag is already set: only the inventory tells
    give(6, Item.STONE, 3)
    progress = _run(TASKS["T4"], states)
    assert progress.done_at.tolist() == [[3, 5, 6]] and progress.success[0]
    assert progress.current_instructions() == [None]


def test_one_step_completes_at_most_one_sub_task():
    states = _states(3)

    def both(s):  # coal and a pickaxe in the same step (impossible in play, but well-defined)
        s["inventory"][0, Item.COAL] = 1
        s["inventory"][0, Item.WOOD_PICKAXE] = 1

    _carry(states, 1, both)
    progress = _run(TASKS["T4"], states)
    assert progress.done_at.tolist() == [[1, -1, -1]]
    assert progress.current_instructions() == ["craft wood pickaxe"]


def test_t1_completes_on_eating_the_plant_it_placed():
    states = _states(6)
    _carry(states, 1, lambda s: s["inventory"][0].__setitem__(Item.SAPLING, 1))
    _carry(states, 2, lambda s: s["inventory"][0].__setitem__(Item.SAPLING, 0))
    _carry(states, 2, lambda s: s["map"][0].__setitem__((2, 3), Block.PLANT))
    _carry(states, 4, lambda s: s["map"][0].__setitem__((2, 3), Block.RIPE_PLANT))
    _carry(states, 5, lambda s: s["map"][0].__setitem__((2, 3), Block.PLANT))
    progress = _run(TASKS["T1"], states)
    assert progress.done_at.tolist() == [[1, 2, 5]]
