"""One env's state as the scripted expert sees it: masks, costs and the distance field.

Built once per env per step from the batched schema arrays; every goal reads the same
``View``, so the (compiled) Dijkstra runs once per step however many goals are weighed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from zoo.envs.constants import DIRECTION_OFFSETS, Action, Block, Item, Mob
from zoo.envs.local_view import local_tiles
from zoo.envs.schema import State
from zoo.experts.scripted.navigation import UNREACHABLE, distance_field, first_step, next_to

WALKABLE = np.zeros(len(Block), bool)
WALKABLE[[Block.GRASS, Block.SAND, Block.PATH]] = True

# Tiles no mob can enter or shoot through (arrows fly over water, so water is left out).
WALL = np.zeros(len(Block), bool)
WALL[
    [
        Block.OUT_OF_BOUNDS, Block.STONE, Block.TREE, Block.COAL, Block.IRON, Block.DIAMOND,
        Block.TABLE, Block.FURNACE, Block.PLANT, Block.RIPE_PLANT,
    ]
] = True

# Tiles a stone, table or furnace may be placed on (both games; stone also fits on water/lava).
PLACEABLE = WALKABLE.copy()
STONE_PLACEABLE = WALKABLE.copy()
STONE_PLACEABLE[[Block.WATER, Block.LAVA]] = True

# Which pickaxe mines a tile (item slot), so paths may tunnel through it.
MINED_WITH = {
    Block.STONE: Item.WOOD_PICKAXE,
    Block.COAL: Item.WOOD_PICKAXE,
    Block.IRON: Item.STONE_PICKAXE,
    Block.DIAMOND: Item.IRON_PICKAXE,
}

_MINED_WITH_INT = tuple((int(b), int(t)) for b, t in MINED_WITH.items())
_STONE_ITEM, _WOOD_PICKAXE, _WATER = int(Item.STONE), int(Item.WOOD_PICKAXE), int(Block.WATER)
_ZOMBIE = int(Mob.ZOMBIE)

MOVES = (Action.MOVE_LEFT, Action.MOVE_RIGHT, Action.MOVE_UP, Action.MOVE_DOWN)
OPPOSITE = {
    Action.MOVE_LEFT: Action.MOVE_RIGHT,
    Action.MOVE_RIGHT: Action.MOVE_LEFT,
    Action.MOVE_UP: Action.MOVE_DOWN,
    Action.MOVE_DOWN: Action.MOVE_UP,
}


def direction_to(src: tuple[int, int], dst: tuple[int, int]) -> int:
    """The move action from a cell to a 4-neighbour."""
    for action, (d_row, d_col) in DIRECTION_OFFSETS.items():
        if (src[0] + d_row, src[1] + d_col) == dst:
            return int(action)
    raise ValueError(f"{dst} is not a 4-neighbour of {src}")


@dataclass(frozen=True)
class PathCosts:
    """Step costs of the planner: walking is 1; tunnelling and bridging cost their actions."""

    mine: int = 3
    bridge: int = 6
    near_zombie: int = 0


class View:
    """Env ``i`` of a batched state, with walkability, costs and distances from the player."""

    def __init__(self, state: State, i: int, costs: PathCosts = PathCosts()) -> None:
        self.map = state["map"][i]
        self.mobs = state["mob_map"][i]
        self.pos = (int(state["player_pos"][i][0]), int(state["player_pos"][i][1]))
        self.dir = int(state["player_dir"][i])
        health, food, drink, energy = (int(v) for v in state["player_vitals"][i])
        self.health, self.food, self.drink, self.energy = health, food, drink, energy
        self.inv = state["inventory"][i].astype(np.int64)
        self.ach = state["achievements"][i].astype(bool)
        self.light = float(state["light_level"][i])
        self.sleeping = bool(state["player_sleeping"][i])
        self.timestep = int(state["timestep"][i])
        rows, cols = self.map.shape
        self.shape = (rows, cols)
        live = state["arrows_status"][i][:, 0] > 0
        self.arrows = [
            ((int(p[0]), int(p[1])), (int(d[0]), int(d[1])))
            for p, d in zip(state["arrows_pos"][i][live], state["arrows_dir"][i][live])
        ]

        no_mob = self.mobs == 0
        self.free = WALKABLE[self.map] & no_mob
        self.free[self.pos] = True
        # Per-tile entry cost from what the inventory can mine or bridge; mobs block.
        table = WALKABLE.astype(np.int16)
        inv = self.inv.tolist()
        for block, tool in _MINED_WITH_INT:
            if inv[tool] > 0:
                table[block] = costs.mine
        if inv[_STONE_ITEM] > 0 and inv[_WOOD_PICKAXE] > 0:
            table[_WATER] = costs.bridge
        cost = table[self.map]
        zombies = self.mobs == _ZOMBIE
        if costs.near_zombie and zombies.any():
            # Stepping next to a zombie hands it the first strike: detour when it is cheap.
            cost[next_to(zombies) & (cost > 0)] += costs.near_zombie
        cost[~no_mob] = 0
        cost[self.pos] = 1
        self.cost = cost
        self.dist, self.parent = distance_field(cost, self.pos[0], self.pos[1])

    # --- cells -------------------------------------------------------------------------
    def in_bounds(self, cell: tuple[int, int]) -> bool:
        return 0 <= cell[0] < self.shape[0] and 0 <= cell[1] < self.shape[1]

    def block(self, cell: tuple[int, int]) -> int:
        """Tile id, OUT_OF_BOUNDS beyond the edge."""
        return int(self.map[cell]) if self.in_bounds(cell) else int(Block.OUT_OF_BOUNDS)

    def mob(self, cell: tuple[int, int]) -> int:
        return int(self.mobs[cell]) if self.in_bounds(cell) else int(Mob.NONE)

    def seen(self, mask: np.ndarray) -> bool:
        """Whether any cell of ``mask`` is on screen (the 7 x 9 tiles the player sees)."""
        return bool(local_tiles(mask, self.pos).any())

    def is_free(self, cell: tuple[int, int]) -> bool:
        """Walkable now: grass/sand/path without a mob (never lava)."""
        return self.in_bounds(cell) and bool(self.free[cell])

    def neighbour(self, cell: tuple[int, int], move: int) -> tuple[int, int]:
        d_row, d_col = DIRECTION_OFFSETS[move]
        return cell[0] + d_row, cell[1] + d_col

    @property
    def facing(self) -> tuple[int, int]:
        return self.neighbour(self.pos, self.dir)

    def has(self, item: Item, n: int = 1) -> bool:
        return bool(self.inv[item] >= n)

    def done(self, achievement) -> bool:
        return bool(self.ach[achievement])

    def mob_cells(self, mob: Mob) -> list[tuple[int, int]]:
        rows, cols = np.nonzero(self.mobs == mob)
        return list(zip(rows.tolist(), cols.tolist()))

    def manhattan(self, cell: tuple[int, int]) -> int:
        return abs(cell[0] - self.pos[0]) + abs(cell[1] - self.pos[1])

    def reachable(self, cell: tuple[int, int]) -> bool:
        return bool(self.dist[cell] < UNREACHABLE)

    # --- moving ------------------------------------------------------------------------
    def step_to(self, goal: tuple[int, int]) -> int | None:
        """The action that makes progress along the cheapest path to ``goal``."""
        if goal == self.pos:
            return None
        nxt = first_step(self.parent, self.pos[0], self.pos[1], goal[0], goal[1])
        if nxt[0] < 0:
            return None
        return self.enter(nxt)

    def enter(self, cell: tuple[int, int]) -> int:
        """Walk into a neighbouring cell, mining or bridging it first when it is solid."""
        move = direction_to(self.pos, cell)
        block = self.block(cell)
        if self.is_free(cell):
            return move
        if block == Block.LAVA:
            return int(Action.NOOP)  # walking into lava kills: never turn towards it by moving
        if self.dir != move:
            return move  # the cell is solid (or holds a mob): this only turns the player
        if block == Block.WATER:
            return int(Action.PLACE_STONE)
        if block in MINED_WITH:
            return int(Action.DO)
        return int(Action.NOOP)
