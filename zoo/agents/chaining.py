"""Instruction chaining: a hand-written planner that tells an instruction follower what next.

The paper's heuristic planner (Instruction-Chaining, Table 5): it watches each env's
inventory, map and task progress and hands the low-level agent (C-Steve-1, or the scripted
expert) one caption at a time. Each sub-task expands into the captions that get it done from
the current state, e.g. T4 from an empty inventory: obtain wood (until enough for a table and
both pickaxes), place table on grass, craft wood pickaxe, obtain stone (until coal is in view),
obtain coal, (obtain wood, place table if none is near), craft wood pickaxe, obtain stone.
Only what an agent could see is used: a table is near, and a plant or coal is seen, only
inside the local view (9 columns by 7 rows around the player in both games;
``ChainConfig.view_cols`` / ``view_rows``).

Coal is searched for through stone (``ChainConfig.coal_via_stone``), the block it lies in:
until coal is in view the planner says "obtain stone", then "obtain coal". The C-Steve-1
shipped on 2026-12-08 reaches coal about as often either way, but more of its episodes go on
to finish T4; the export before it gains little (docs/results/notes/csteve1.md, "Coal
through stone, and leg 2 shipped").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from zoo.agents.base import InstructableAgent
from zoo.envs.base import Step
from zoo.envs.constants import Achievement as Ach
from zoo.envs.constants import VIEW, Block, Item
from zoo.envs.local_view import local_tiles
from zoo.envs.schema import State
from zoo.envs.tasks import TaskProgress, TaskSpec, get_task

WOOD_TOOLS = {Ach.MAKE_WOOD_PICKAXE: Item.WOOD_PICKAXE, Ach.MAKE_WOOD_SWORD: Item.WOOD_SWORD}
STONE_TOOLS = {Ach.MAKE_STONE_PICKAXE: Item.STONE_PICKAXE, Ach.MAKE_STONE_SWORD: Item.STONE_SWORD}
CRAFT = {
    Item.WOOD_PICKAXE: "craft wood pickaxe",
    Item.WOOD_SWORD: "craft wood sword",
    Item.STONE_PICKAXE: "craft stone pickaxe",
    Item.STONE_SWORD: "craft stone sword",
}
MINE = {Ach.COLLECT_STONE: "obtain stone", Ach.COLLECT_COAL: "obtain coal"}
SIMPLE = {
    Ach.COLLECT_SAPLING: "obtain sapling",
    Ach.COLLECT_DRINK: "obtain drink",
    Ach.COLLECT_WOOD: "obtain wood",
}


PLANNED = {*SIMPLE, *WOOD_TOOLS, *STONE_TOOLS, *MINE, Ach.PLACE_PLANT, Ach.PLACE_TABLE, Ach.EAT_PLANT}


def check_plannable(task: TaskSpec) -> None:
    """ValueError naming the sub-tasks of ``task`` the planner has no plan for."""
    missing = [s.achievement.name.lower() for s in task.subtasks if s.achievement not in PLANNED]
    if missing:
        raise ValueError(
            f"the chaining planner has no plan for {missing} in task {task.name!r}; "
            f"it plans {sorted(a.name.lower() for a in PLANNED)}"
        )


@dataclass(frozen=True)
class ChainConfig:
    """What the planner assumes about the game."""

    table_wood: int = 2
    """Wood a table takes (both games as installed)."""
    view_rows: int = VIEW[0] // 2
    """Map rows the agent sees above and below itself (the local view is 7 rows tall)."""
    view_cols: int = VIEW[1] // 2
    """Map columns the agent sees left and right of itself (the local view is 9 wide)."""
    coal_via_stone: bool = True
    """Say "obtain stone" until coal is in view, then "obtain coal" (False: "obtain coal" from
    the start, the planner before 2026-12-08)."""


def _local_view(state: State, i: int, config: ChainConfig) -> np.ndarray:
    """The tiles of env ``i``'s map the agent sees: the planner must not know more than it."""
    pos = (int(state["player_pos"][i][0]), int(state["player_pos"][i][1]))
    return local_tiles(state["map"][i], pos, config.view_rows, config.view_cols)


def plan_instruction(
    task: TaskSpec, k: int, state: State, i: int, config: ChainConfig = ChainConfig()
) -> str | None:
    """The caption to give env ``i`` working on sub-task ``k`` of ``task`` (None when done)."""
    if k >= len(task.subtasks):
        return None
    inv = state["inventory"][i].astype(np.int64)
    remaining = [s.achievement for s in task.subtasks[k:]]
    view = _local_view(state, i, config)
    near = bool((view == Block.TABLE).any())

    def craft(tool: Item, prerequisite: bool = False) -> str:
        """Wood for every tool still to come (+ a table if none is near) first, then craft."""
        tools = sum(a in WOOD_TOOLS or a in STONE_TOOLS for a in remaining) + prerequisite
        wanted = tools + (0 if near else config.table_wood)
        if inv[Item.WOOD] < min(wanted, 9):
            return "obtain wood"
        if not near:
            return "place table on grass"
        return CRAFT[tool]

    def plant() -> str:
        return "place plant on grass" if inv[Item.SAPLING] > 0 else "obtain sapling"

    ach = remaining[0]
    if ach in SIMPLE:
        return SIMPLE[ach]
    if ach == Ach.PLACE_PLANT:
        return plant()
    if ach == Ach.PLACE_TABLE:
        return "place table on grass" if inv[Item.WOOD] >= config.table_wood else "obtain wood"
    if ach == Ach.EAT_PLANT:
        grown = (view == Block.PLANT) | (view == Block.RIPE_PLANT)
        return "obtain ripe plant" if grown.any() else plant()
    if ach in WOOD_TOOLS:
        return craft(WOOD_TOOLS[ach])
    if ach in STONE_TOOLS:
        if inv[Item.STONE] < 1:
            return craft(Item.WOOD_PICKAXE, True) if inv[Item.WOOD_PICKAXE] < 1 else "obtain stone"
        return craft(STONE_TOOLS[ach])
    if ach in MINE:
        if inv[Item.WOOD_PICKAXE] < 1:
            return craft(Item.WOOD_PICKAXE, True)
        if ach == Ach.COLLECT_COAL and config.coal_via_stone and not (view == Block.COAL).any():
            return MINE[Ach.COLLECT_STONE]
        return MINE[ach]
    check_plannable(task)
    raise AssertionError(f"{ach!r} is in PLANNED but has no plan")


class ChainingAgent:
    """An Agent that plays ``task`` by chaining instructions to an InstructableAgent.

    It keeps its own ``TaskProgress`` from the states it is shown (the first ``act`` after a
    reset sees the reset state) and instructs the inner agent only when an env's caption
    changes, so an agent that restarts its prompt on ``instruct`` is not restarted each step.
    """

    def __init__(
        self, inner: InstructableAgent, task: TaskSpec | str, config: ChainConfig = ChainConfig()
    ) -> None:
        if not hasattr(inner, "instruct"):
            raise ValueError(f"agent {inner.name!r} does not follow instructions (no instruct)")
        self.inner = inner
        self.task = get_task(task) if isinstance(task, str) else task
        check_plannable(self.task)  # fail now, not mid-episode
        self.config = config
        self.name = f"chain-{inner.name}"
        self.needs_pixels = inner.needs_pixels
        self._progress: TaskProgress | None = None
        self._fresh = np.zeros(0, bool)
        self._given: list[str | None] = []

    def reset(self, seeds: np.ndarray, mask: np.ndarray | None = None) -> None:
        self.inner.reset(seeds, mask)
        n = len(seeds)
        if self._progress is None:
            self._progress = TaskProgress(self.task, n)
            self._fresh = np.ones(n, bool)
            self._given = [None] * n
        self._fresh |= np.ones(n, bool) if mask is None else np.asarray(mask, bool)

    def act(self, step: Step) -> np.ndarray:
        if self._progress is None:
            raise RuntimeError("ChainingAgent.act called before reset")
        fresh = self._fresh.copy()
        if not fresh.all():  # fresh rows are overwritten below: their update is moot
            self._progress.update(step.state)
        if fresh.any():
            self._progress.reset(step.state, fresh)
        wanted = [
            plan_instruction(self.task, int(k), step.state, i, self.config)
            for i, k in enumerate(self._progress.next)
        ]
        changed = fresh | np.array([w != g for w, g in zip(wanted, self._given)])
        if changed.any():
            self.inner.instruct(wanted, changed)
            self._given = wanted
        self._fresh[:] = False
        return self.inner.act(step)
