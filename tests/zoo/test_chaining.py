"""The instruction-chaining planner: the captions it hands out on hand-built state sequences
for T1-T4, and the scripted expert playing T4 under it."""

from __future__ import annotations

import numpy as np
import pytest

from zoo.agents.chaining import (
    PLANNED,
    ChainConfig,
    ChainingAgent,
    check_plannable,
    plan_instruction,
)
from zoo.envs.base import Step
from zoo.envs.constants import Achievement, Block, Item
from zoo.envs.schema import empty_state
from zoo.envs.tasks import TASKS, SubTask, TaskSpec, make_task_env
from zoo.eval.task_eval import evaluate_task
from zoo.experts.scripted import ScriptedExpert


class RecordingAgent:
    """An InstructableAgent that only remembers what it was told."""

    name = "recorder"
    needs_pixels = False

    def __init__(self) -> None:
        self.told: list[str | None] = []

    def reset(self, seeds, mask=None) -> None:
        pass

    def instruct(self, instructions, mask=None) -> None:
        if mask is None or mask[0]:
            self.told.append(instructions[0])

    def act(self, step: Step) -> np.ndarray:
        return np.zeros(1, np.int32)


class Script:
    """Builds one env's state sequence: each call edits a copy of the last state."""

    def __init__(self) -> None:
        state = empty_state(1)
        state["map"][0] = Block.GRASS
        state["player_pos"][0] = (10, 10)
        self.states = [state]

    def then(self, pos=None, tiles=(), **items) -> Script:
        state = {k: v.copy() for k, v in self.states[-1].items()}
        for name, count in items.items():
            state["inventory"][0, Item[name.upper()]] = count
        for (row, col), block in tiles:
            state["map"][0, row, col] = block
        if pos is not None:
            state["player_pos"][0] = pos
        self.states.append(state)
        return self


def _told(task: str, script: Script) -> list[str | None]:
    inner = RecordingAgent()
    agent = ChainingAgent(inner, task)
    agent.reset(np.array([0]))
    for state in script.states:
        agent.act(Step(None, state, np.zeros(1, np.float32), np.zeros(1, bool)))
    return inner.told


def test_t1_chain_replants_a_lost_plant_and_waits_for_it_to_ripen():
    script = (
        Script()
        .then(sapling=1)
        .then(sapling=0, tiles=[((10, 11), Block.PLANT)])
        .then(tiles=[((10, 11), Block.GRASS)])  # trampled before it ripened
        .then(sapling=1)
        .then(sapling=0, tiles=[((10, 11), Block.PLANT)])
        .then(tiles=[((10, 11), Block.RIPE_PLANT)])
        .then(tiles=[((10, 11), Block.PLANT)])  # eaten
    )
    assert _told("T1", script) == [
        "obtain sapling", "place plant on grass", "obtain ripe plant", "obtain sapling",
        "place plant on grass", "obtain ripe plant", None,
    ]


def test_t2_chain():
    script = (
        Script()
        .then(sapling=1)
        .then(sapling=0, tiles=[((10, 11), Block.PLANT)])
        .then(wood=1)
        .then(wood=2)
        .then(wood=0, tiles=[((11, 10), Block.TABLE)])
    )
    assert _told("T2", script) == [
        "obtain sapling", "place plant on grass", "obtain wood", "place table on grass", None,
    ]


def test_t3_chain():
    script = (
        Script()
        .then(wood=2)
        .then(wood=3)
        .then(wood=1, tiles=[((11, 10), Block.TABLE)])
        .then(wood=0, wood_pickaxe=1)
        .then(sapling=1)
    )
    assert _told("T3", script) == [
        "obtain wood", "place table on grass", "craft wood pickaxe", "obtain sapling", None,
    ]


def test_t4_chain_gathers_wood_for_both_pickaxes_and_a_new_table_when_far():
    script = (
        Script()
        .then(wood=3)
        .then(wood=4)  # a table and two pickaxes
        .then(wood=2, tiles=[((11, 10), Block.TABLE)])
        .then(wood=1, wood_pickaxe=1)  # no coal in view: dig through stone for it
        .then(pos=(40, 40), stone=2)  # walks off into the stone
        .then(tiles=[((42, 43), Block.COAL)])  # coal in view
        .then(coal=1)  # the table is out of sight: wood for a new one and the pickaxe
        .then(wood=3)
        .then(wood=1, tiles=[((41, 40), Block.TABLE)])
        .then(wood=0, wood_pickaxe=2)
        .then(stone=3)
    )
    assert _told("T4", script) == [
        "obtain wood", "place table on grass", "craft wood pickaxe", "obtain stone",
        "obtain coal", "obtain wood", "place table on grass", "craft wood pickaxe",
        "obtain stone", None,
    ]


@pytest.mark.parametrize(
    ("coal", "via_stone", "told"),
    [((13, 14), True, "obtain coal"), ((14, 10), True, "obtain stone"),
     ((10, 15), True, "obtain stone"), ((14, 10), False, "obtain coal")],
)
def test_coal_is_asked_for_once_it_is_in_the_local_view(coal, via_stone, told):
    """Until coal is seen the planner says "obtain stone" (coal lies in stone); off, the old
    plan says "obtain coal" at once."""
    state = Script().then(wood_pickaxe=1, tiles=[(coal, Block.COAL)]).states[-1]  # at (10, 10)
    config = ChainConfig(coal_via_stone=via_stone)
    assert plan_instruction(TASKS["T4"], 0, state, 0, config) == told


def test_chain_instructs_only_on_change_and_again_after_reset():
    inner = RecordingAgent()
    agent = ChainingAgent(inner, "T3")
    agent.reset(np.array([0]))
    state = Script().states[0]
    step = Step(None, state, np.zeros(1, np.float32), np.zeros(1, bool))
    for _ in range(3):
        agent.act(step)
    agent.reset(np.array([1]))
    agent.act(step)
    assert inner.told == ["obtain wood", "obtain wood"]


def test_chain_refuses_what_it_cannot_plan():
    task = TaskSpec("hunt", (SubTask(Achievement.DEFEAT_ZOMBIE, "kill zombie"),))
    with pytest.raises(ValueError, match=r"no plan for \['defeat_zombie'\] in task 'hunt'"):
        check_plannable(task)
    from zoo.agents.base import RandomAgent

    with pytest.raises(ValueError, match="does not follow instructions"):
        ChainingAgent(RandomAgent(1), "T4")
    for t in TASKS.values():
        check_plannable(t)
    assert {s.achievement for t in TASKS.values() for s in t.subtasks} <= PLANNED


@pytest.mark.parametrize(
    ("table", "near"),
    [((13, 10), True), ((7, 10), True), ((14, 10), False), ((6, 10), False),
     ((10, 14), True), ((10, 6), True), ((10, 15), False), ((13, 14), True)],
)
def test_a_table_is_near_only_inside_the_9_by_7_local_view(table, near):
    state = Script().then(wood=3, tiles=[(table, Block.TABLE)]).states[-1]  # player at (10, 10)
    told = plan_instruction(TASKS["T3"], 0, state, 0)
    assert told == ("craft wood pickaxe" if near else "place table on grass")


def test_the_view_size_is_configurable():
    state = Script().then(wood=3, tiles=[((14, 10), Block.TABLE)]).states[-1]
    wide = ChainConfig(view_rows=4)
    assert plan_instruction(TASKS["T3"], 0, state, 0, wide) == "craft wood pickaxe"


@pytest.mark.parametrize(
    ("plant", "told"), [((10, 12), "obtain ripe plant"), ((10, 63), "obtain sapling")]
)
def test_the_eat_plant_step_sees_only_plants_in_the_local_view(plant, told):
    """4 columns away the plant is seen; 55 away it is not, so a new one is planted."""
    state = Script().then(pos=(10, 8), tiles=[(plant, Block.RIPE_PLANT)]).states[-1]
    assert plan_instruction(TASKS["T1"], 2, state, 0) == told


def test_scripted_expert_solves_t4_under_the_chain():
    env = make_task_env("T4", "crafter", 2, pixels=False)
    agent = ChainingAgent(ScriptedExpert(2), "T4")
    results, _ = evaluate_task(agent, env, 4, seed=0, progress=False)
    assert sum(r.success for r in results) >= 3
