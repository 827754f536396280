"""The game facts every part of the zoo shares: actions, achievements, blocks, items, mobs.

Defined once here (ids follow Craftax-Classic, which follows crafter's own order), so an
agent trained on one env plays the other and a dataset means the same thing everywhere.
"""

from __future__ import annotations

from enum import IntEnum


class Action(IntEnum):
    """The 17 discrete actions, in the id order both crafter and Craftax-Classic use."""

    NOOP = 0
    MOVE_LEFT = 1
    MOVE_RIGHT = 2
    MOVE_UP = 3
    MOVE_DOWN = 4
    DO = 5
    SLEEP = 6
    PLACE_STONE = 7
    PLACE_TABLE = 8
    PLACE_FURNACE = 9
    PLACE_PLANT = 10
    MAKE_WOOD_PICKAXE = 11
    MAKE_STONE_PICKAXE = 12
    MAKE_IRON_PICKAXE = 13
    MAKE_WOOD_SWORD = 14
    MAKE_STONE_SWORD = 15
    MAKE_IRON_SWORD = 16


class Achievement(IntEnum):
    """The 22 achievements, in Craftax-Classic's (tech-tree) order; names match crafter's."""

    COLLECT_WOOD = 0
    PLACE_TABLE = 1
    EAT_COW = 2
    COLLECT_SAPLING = 3
    COLLECT_DRINK = 4
    MAKE_WOOD_PICKAXE = 5
    MAKE_WOOD_SWORD = 6
    PLACE_PLANT = 7
    DEFEAT_ZOMBIE = 8
    COLLECT_STONE = 9
    PLACE_STONE = 10
    EAT_PLANT = 11
    DEFEAT_SKELETON = 12
    MAKE_STONE_PICKAXE = 13
    MAKE_STONE_SWORD = 14
    WAKE_UP = 15
    PLACE_FURNACE = 16
    COLLECT_COAL = 17
    COLLECT_IRON = 18
    COLLECT_DIAMOND = 19
    MAKE_IRON_PICKAXE = 20
    MAKE_IRON_SWORD = 21


class Block(IntEnum):
    """Map tile ids (Craftax-Classic's BlockType); crafter's materials are mapped onto these."""

    INVALID = 0
    OUT_OF_BOUNDS = 1
    GRASS = 2
    WATER = 3
    STONE = 4
    TREE = 5
    WOOD = 6
    PATH = 7
    COAL = 8
    IRON = 9
    DIAMOND = 10
    TABLE = 11
    FURNACE = 12
    SAND = 13
    LAVA = 14
    PLANT = 15
    RIPE_PLANT = 16


class Item(IntEnum):
    """Inventory slots, in Craftax-Classic's order."""

    WOOD = 0
    STONE = 1
    COAL = 2
    IRON = 3
    DIAMOND = 4
    SAPLING = 5
    WOOD_PICKAXE = 6
    STONE_PICKAXE = 7
    IRON_PICKAXE = 8
    WOOD_SWORD = 9
    STONE_SWORD = 10
    IRON_SWORD = 11


class Mob(IntEnum):
    """Values of the mob map: which creature stands on a tile (0: none)."""

    NONE = 0
    COW = 1
    ZOMBIE = 2
    SKELETON = 3
    ARROW = 4


ACTION_NAMES: tuple[str, ...] = tuple(a.name.lower() for a in Action)
ACHIEVEMENT_NAMES: tuple[str, ...] = tuple(a.name.lower() for a in Achievement)
BLOCK_NAMES: tuple[str, ...] = tuple(b.name.lower() for b in Block)
ITEM_NAMES: tuple[str, ...] = tuple(i.name.lower() for i in Item)
MOB_NAMES: tuple[str, ...] = tuple(m.name.lower() for m in Mob)

NUM_ACTIONS = len(Action)
NUM_ACHIEVEMENTS = len(Achievement)

# The cooldown a mob's attack resets (both games; it only counts down otherwise), so a mob
# whose cooldown equals it at t+1 attacked at t.
ZOMBIE_ATTACK_COOLDOWN = 5
SKELETON_RELOAD = 4

VIEW: tuple[int, int] = (7, 9)
"""Map tiles the player sees (rows, cols), standing on the centre one: both games show 9 x 9
tiles less 2 rows of inventory."""

# Row/column offsets of a step in each facing direction; direction ids are the move actions.
DIRECTION_OFFSETS: dict[int, tuple[int, int]] = {
    Action.MOVE_LEFT: (0, -1),
    Action.MOVE_RIGHT: (0, 1),
    Action.MOVE_UP: (-1, 0),
    Action.MOVE_DOWN: (1, 0),
}
