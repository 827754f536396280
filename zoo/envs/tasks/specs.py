"""The task registry: what each task of the suites starts with and asks for, in order."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from zoo.envs.constants import Achievement, Item

VITAL_MAX = 9
ITEM_MAX = 9  # inventory cap of every item in both games
DRINK = 2  # column of ``player_vitals``
THIRST = 2  # column of ``player_counters``


@dataclass(frozen=True)
class SubTask:
    """One step of a task: the achievement whose event completes it and the caption that asks
    for it (a caption text of zoo/captions/captions.yaml, as instruction-following agents read)."""

    achievement: Achievement
    instruction: str


@dataclass(frozen=True)
class TaskSpec:
    """A task variant of the game.

    Args:
        name: registry key (``zoo eval --task NAME``).
        subtasks: completed in this order for success.
        inventory: items the agent holds after reset (all other items 0).
        peaceful: no mobs and no vitals decay (food, drink, energy kept at 9).
        max_steps: episode step limit.
        description: one line for reports and ``--help``.
    """

    name: str
    subtasks: tuple[SubTask, ...]
    inventory: dict[Item, int] = field(default_factory=dict)
    peaceful: bool = False
    max_steps: int = 1000
    description: str = ""

    def __post_init__(self) -> None:
        if not self.subtasks:
            raise ValueError(f"task {self.name!r} has no sub-tasks")
        if self.max_steps < 1:
            raise ValueError(f"task {self.name!r}: max_steps must be >= 1, got {self.max_steps}")
        bad = {k: v for k, v in self.inventory.items() if not 0 <= v <= ITEM_MAX}
        if bad:
            raise ValueError(f"task {self.name!r}: item counts must lie in [0, 9], got {bad}")

    @property
    def instructions(self) -> tuple[str, ...]:
        return tuple(s.instruction for s in self.subtasks)

    def inventory_vector(self) -> np.ndarray:
        """The starting inventory in schema order (``zoo.envs.Item``)."""
        vec = np.zeros(len(Item), np.int16)
        for item, count in self.inventory.items():
            vec[Item(item)] = count
        return vec


def _sub(achievement: Achievement, instruction: str) -> SubTask:
    return SubTask(achievement, instruction)


SAPLING = _sub(Achievement.COLLECT_SAPLING, "obtain sapling")
DRINK_SUB = _sub(Achievement.COLLECT_DRINK, "obtain drink")
PLANT = _sub(Achievement.PLACE_PLANT, "place plant on grass")
TABLE = _sub(Achievement.PLACE_TABLE, "place table on grass")
EAT_PLANT = _sub(Achievement.EAT_PLANT, "obtain ripe plant")
WOOD_PICKAXE = _sub(Achievement.MAKE_WOOD_PICKAXE, "craft wood pickaxe")
COAL = _sub(Achievement.COLLECT_COAL, "obtain coal")
STONE = _sub(Achievement.COLLECT_STONE, "obtain stone")

SINGLE_STEP_LIMIT = 500  # the paper gives none; well above the goal-directed expert's medians
_WOOD_TOOL = {Item.WOOD: 3}
_STONE_TOOL = {Item.WOOD: 3, Item.STONE: 1, Item.WOOD_PICKAXE: 1}

def _single_step(
    name: str, sub: SubTask, inventory: dict[Item, int], description: str
) -> TaskSpec:
    return TaskSpec(name, (sub,), inventory, max_steps=SINGLE_STEP_LIMIT, description=description)


TASKS: dict[str, TaskSpec] = {
    t.name: t
    for t in (
        _single_step("collect_sapling", SAPLING, {}, "collect a sapling"),
        _single_step("collect_drink", DRINK_SUB, {}, "drink water"),
        _single_step("make_wood_pickaxe", WOOD_PICKAXE, _WOOD_TOOL, "craft a wood pickaxe"),
        _single_step(
            "make_wood_sword", _sub(Achievement.MAKE_WOOD_SWORD, "craft wood sword"), _WOOD_TOOL,
            "craft a wood sword",
        ),
        _single_step(
            "make_stone_pickaxe", _sub(Achievement.MAKE_STONE_PICKAXE, "craft stone pickaxe"),
            _STONE_TOOL, "craft a stone pickaxe",
        ),
        _single_step(
            "make_stone_sword", _sub(Achievement.MAKE_STONE_SWORD, "craft stone sword"),
            _STONE_TOOL, "craft a stone sword",
        ),
        TaskSpec(
            "T1", (SAPLING, PLANT, EAT_PLANT), peaceful=True,
            description="collect sapling, place plant, eat the ripe plant (no mobs, no decay)",
        ),
        TaskSpec("T2", (PLANT, TABLE), description="place plant, then place table"),
        TaskSpec("T3", (WOOD_PICKAXE, SAPLING), description="make wood pickaxe, then sapling"),
        TaskSpec(
            "T4", (COAL, WOOD_PICKAXE, STONE),
            description="collect coal, then make a wood pickaxe, then collect stone",
        ),
    )
}
SINGLE_STEP_TASKS = tuple(n for n, t in TASKS.items() if len(t.subtasks) == 1)
LONG_HORIZON_TASKS = ("T1", "T2", "T3", "T4")


def get_task(name: str) -> TaskSpec:
    try:
        return TASKS[name]
    except KeyError:
        raise ValueError(f"unknown task {name!r}; expected one of {sorted(TASKS)}") from None


# --- events ---------------------------------------------------------------------------------
