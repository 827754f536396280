"""Which achievements happened between two states, repeats and the item cap included."""

from __future__ import annotations

import numpy as np

from zoo.envs.constants import Achievement, Block, Item
from zoo.envs.schema import State
from zoo.envs.tasks.specs import DRINK, ITEM_MAX, THIRST

_ITEM_EVENTS = {
    Achievement.COLLECT_WOOD: Item.WOOD,
    Achievement.COLLECT_STONE: Item.STONE,
    Achievement.COLLECT_COAL: Item.COAL,
    Achievement.COLLECT_IRON: Item.IRON,
    Achievement.COLLECT_DIAMOND: Item.DIAMOND,
    Achievement.COLLECT_SAPLING: Item.SAPLING,
    Achievement.MAKE_WOOD_PICKAXE: Item.WOOD_PICKAXE,
    Achievement.MAKE_STONE_PICKAXE: Item.STONE_PICKAXE,
    Achievement.MAKE_IRON_PICKAXE: Item.IRON_PICKAXE,
    Achievement.MAKE_WOOD_SWORD: Item.WOOD_SWORD,
    Achievement.MAKE_STONE_SWORD: Item.STONE_SWORD,
    Achievement.MAKE_IRON_SWORD: Item.IRON_SWORD,
}
_BLOCK_EVENTS = {Achievement.PLACE_TABLE: Block.TABLE, Achievement.PLACE_FURNACE: Block.FURNACE}
# What collecting leaves on the tile in both games as installed: the trace at the item cap.
_MINED = {
    Achievement.COLLECT_WOOD: (Block.TREE, Block.GRASS),
    Achievement.COLLECT_STONE: (Block.STONE, Block.PATH),
    Achievement.COLLECT_COAL: (Block.COAL, Block.PATH),
    Achievement.COLLECT_IRON: (Block.IRON, Block.PATH),
    Achievement.COLLECT_DIAMOND: (Block.DIAMOND, Block.PATH),
}
# Tool pairs and the materials making either spends (item -> amounts allowed): the trace of a
# tool made at the cap. Iron tools cost stone in Craftax-Classic only.
_RECIPES: tuple[tuple[tuple[Item, Item], dict[Item, tuple[int, ...]]], ...] = (
    (
        (Item.WOOD_PICKAXE, Item.WOOD_SWORD),
        {Item.WOOD: (1,), Item.STONE: (0,), Item.COAL: (0,), Item.IRON: (0,)},
    ),
    (
        (Item.STONE_PICKAXE, Item.STONE_SWORD),
        {Item.WOOD: (1,), Item.STONE: (1,), Item.COAL: (0,), Item.IRON: (0,)},
    ),
    (
        (Item.IRON_PICKAXE, Item.IRON_SWORD),
        {Item.WOOD: (1,), Item.STONE: (0, 1), Item.COAL: (1,), Item.IRON: (1,)},
    ),
)
_MADE = {item: ach for ach, item in _ITEM_EVENTS.items()}


def achievement_events(prev: State, cur: State) -> np.ndarray:
    """(N, 22) bool: which achievements happened between two consecutive batched states.

    A flag flip always counts; the achievements in the module docstring also count when they
    happen again, at the item cap too. Others (eat cow, defeat mobs, place stone, wake up)
    count on the flip only.
    """
    events = cur["achievements"].astype(bool) & ~prev["achievements"].astype(bool)
    before, after = prev["inventory"].astype(np.int32), cur["inventory"].astype(np.int32)
    inv_up = after > before
    for ach, item in _ITEM_EVENTS.items():
        events[:, ach] |= inv_up[:, item]
    for ach, (block, left) in _MINED.items():
        events[:, ach] |= ((prev["map"] == block) & (cur["map"] == left)).any(axis=(1, 2))
    spent = before - after
    for pair, costs in _RECIPES:
        paid = np.all([np.isin(spent[:, item], amounts) for item, amounts in costs.items()], 0)
        made_at_cap = paid & ~inv_up[:, list(pair)].any(axis=1)
        for tool, sibling in (pair, pair[::-1]):
            only_tool_full = (before[:, tool] >= ITEM_MAX) & (before[:, sibling] < ITEM_MAX)
            events[:, _MADE[tool]] |= made_at_cap & only_tool_full
    thirst, was = cur["player_counters"][:, THIRST], prev["player_counters"][:, THIRST]
    events[:, Achievement.COLLECT_DRINK] |= (
        cur["player_vitals"][:, DRINK].astype(np.int32) > prev["player_vitals"][:, DRINK]
    ) | ((thirst > 0) & (thirst < was))  # drinking restarts it at 0 (+1 this step)
    events[:, Achievement.PLACE_PLANT] |= after[:, Item.SAPLING] < before[:, Item.SAPLING]
    for ach, block in _BLOCK_EVENTS.items():
        tiles_before, tiles_after = ((s["map"] == block).sum(axis=(1, 2)) for s in (prev, cur))
        events[:, ach] |= tiles_after > tiles_before
    eaten = (prev["map"] == Block.RIPE_PLANT) & (cur["map"] == Block.PLANT)
    events[:, Achievement.EAT_PLANT] |= eaten.any(axis=(1, 2))
    return events
