"""The goal logic of one env: survival first, then side achievements and the tech tree.

``EnvPlanner.act`` walks a fixed priority list each step; each goal returns an action or
None ("nothing to do / cannot"), and the first action wins. Nothing is cached between steps
but a few decisions that must persist (the pocket being sealed, an exploration target).
"""

from __future__ import annotations

import numpy as np

from zoo.envs.constants import Achievement as Ach
from zoo.envs.constants import Action, Block, Item, Mob
from zoo.experts.scripted.config import ExpertConfig
from zoo.experts.scripted.farming import FarmingGoals
from zoo.experts.scripted.navigation import next_to
from zoo.experts.scripted.skills import (
    act_on,
    craft,
    crafting_spots,
    explore_step,
    face_free,
    go_to,
    goal_distance,
    pick_explore_target,
)
from zoo.experts.scripted.survival import SurvivalGoals
from zoo.experts.scripted.world import MOVES, PLACEABLE, STONE_PLACEABLE, View

# Tool -> (action, wood, stone, coal, iron, needs furnace). Craftax also takes stone for iron tools.
RECIPES = {
    Item.WOOD_PICKAXE: (Action.MAKE_WOOD_PICKAXE, 1, 0, 0, 0, False),
    Item.WOOD_SWORD: (Action.MAKE_WOOD_SWORD, 1, 0, 0, 0, False),
    Item.STONE_PICKAXE: (Action.MAKE_STONE_PICKAXE, 1, 1, 0, 0, False),
    Item.STONE_SWORD: (Action.MAKE_STONE_SWORD, 1, 1, 0, 0, False),
    Item.IRON_PICKAXE: (Action.MAKE_IRON_PICKAXE, 1, 1, 1, 1, True),
    Item.IRON_SWORD: (Action.MAKE_IRON_SWORD, 1, 1, 1, 1, True),
}


class EnvPlanner(SurvivalGoals, FarmingGoals):
    """Memory and decisions of the expert in one env; re-created at every episode start."""

    def __init__(self, seed: int, config: ExpertConfig) -> None:
        super().__init__(config)
        self.rng = np.random.default_rng(seed)
        self.explore_target: tuple[int, int] | None = None
        self.explore_until = 0
        self.last_goal = ""  # which goal chose the last action (for traces and tests)
        self.instruction: str | None = None  # a caption of INSTRUCTIONS; None: normal play

    # --- the priority list ---------------------------------------------------------------
    def act(self, v: View) -> int:
        """The action of the first goal, in priority order, that has something to do."""
        if v.sleeping:
            self.last_goal = "asleep"
            return int(Action.NOOP)  # both games ignore actions while the player sleeps
        goals = self._normal_goals() if self.instruction is None else self._instructed_goals()
        for goal in goals:
            action = goal(v)
            if action is not None:
                self.last_goal = goal.__name__
                return int(action)
        self.last_goal = "random"
        moves = [m for m in MOVES if v.is_free(v.neighbour(v.pos, m))]  # never into lava
        return int(self.rng.choice(moves)) if moves else int(Action.NOOP)

    def _instructed_goals(self) -> tuple:
        """Goal-directed play: stay alive (threats, needs), then only the instruction.

        No night shelter and no side goals: the instruction is the task, and a task's 1,000
        steps are too few to spend a night in a pocket.
        """
        return (
            self._arm,
            self._flee_unarmed,
            self._fight_adjacent,
            self._dodge_arrows,
            self._engage_zombie,
            self._critical_needs,
            self._urgent_needs,
            self._instructed,
            self._explore,
        )

    def _instructed(self, v: View) -> int | None:
        return INSTRUCTIONS[self.instruction](self, v)

    def _normal_goals(self) -> tuple:
        return (
            self._arm,
            self._flee_unarmed,
            self._fight_adjacent,
            self._dodge_arrows,
            self._engage_zombie,
            self._critical_needs,
            self._dusk_supplies,
            self._sleep,
            self._urgent_needs,
            self._first_plant,
            self._basic_tools,
            self._first_stone,
            self._stone_tools,
            self._side_goals,
            self._tech_tree,
            self._late_goals,
            self._explore,
        )

    # --- cheap achievements and top-ups ----------------------------------------------------
    def _side_goals(self, v: View) -> int | None:
        """Achievements that are cheap when at hand: mobs, ripe plants, water, cows, saplings."""
        cfg = self.cfg
        if not v.done(Ach.DEFEAT_ZOMBIE) and v.health >= cfg.fight_health:
            action = act_on(v, v.mobs == Mob.ZOMBIE, int(Action.DO), cfg.hunt_dist)
            if action is not None:
                return action
        if self._skeleton_ready(v):
            action = act_on(v, v.mobs == Mob.SKELETON, int(Action.DO), cfg.hunt_dist)
            if action is not None:
                return action
        if not v.done(Ach.EAT_PLANT):
            action = act_on(v, v.map == Block.RIPE_PLANT, int(Action.DO))
            if action is not None:
                return action
        if not v.done(Ach.COLLECT_DRINK) or v.drink < 9:
            limit = cfg.near if not v.done(Ach.COLLECT_DRINK) else 2
            action = self._drink(v, limit)
            if action is not None:
                return action
        if not v.done(Ach.EAT_COW) or v.food < 7:
            limit = cfg.near if not v.done(Ach.EAT_COW) else 3
            action = act_on(v, v.mobs == Mob.COW, int(Action.DO), limit)
            if action is not None:
                return action
        action = self._plants(v)
        if action is not None:
            return action
        if v.has(Item.STONE) and not v.done(Ach.PLACE_STONE):
            valid = STONE_PLACEABLE[v.map] & (v.mobs == 0)
            action = face_free(v, valid, int(Action.PLACE_STONE), max_dist=cfg.near)
            if action is not None:
                return action
        return None

    def _skeleton_ready(self, v: View) -> bool:
        """Skeletons shoot: chase them only armed (a stone sword kills in one hit) and healthy."""
        return (
            not v.done(Ach.DEFEAT_SKELETON)
            and v.has(Item.STONE_SWORD)
            and v.health >= self.cfg.skeleton_health
        )

    # --- the tech tree ---------------------------------------------------------------------
    def _basic_tools(self, v: View) -> int | None:
        """A wood sword and pickaxe first (fists take five hits per zombie), and wood to spare
        for the stone tools: trees are scarce where stone is."""
        missing = [t for t in (Item.WOOD_SWORD, Item.WOOD_PICKAXE) if not v.has(t)]
        if not missing:
            return None
        table_dist = goal_distance(v, crafting_spots(v, Block.TABLE) & v.free)
        table_near = table_dist <= self.cfg.station_dist
        wanted = min(9, self._wood_wanted(v) + (0 if table_near else self.cfg.table_wood))
        if v.inv[Item.WOOD] < wanted:
            action = act_on(v, v.map == Block.TREE, int(Action.DO), 2 * self.cfg.near)
            if action is not None:
                return action
        return self._make(v, missing[0])

    @staticmethod
    def _minable_stone(v: View) -> np.ndarray:
        """Stone worth mining: not the stones that fence in a plant."""
        plants = (v.map == Block.PLANT) | (v.map == Block.RIPE_PLANT)
        return (v.map == Block.STONE) & ~next_to(plants)

    def _first_stone(self, v: View) -> int | None:
        """A few stones early: pockets to sleep in at night are built from them."""
        if v.has(Item.WOOD_PICKAXE) and v.inv[Item.STONE] < self.cfg.early_stone:
            return act_on(v, self._minable_stone(v), int(Action.DO))
        return None

    def _stone_tools(self, v: View) -> int | None:
        """Stone sword and pickaxe as soon as there is stone: two-hit zombies, and iron."""
        if not v.has(Item.STONE):
            return None
        for tool in (Item.STONE_SWORD, Item.STONE_PICKAXE):
            if not v.has(tool):
                return self._make(v, tool)
        return None

    def _tech_tree(self, v: View) -> int | None:
        """Wood and stone stock, stone tools, furnace, coal and iron, iron tools, diamond."""
        cfg = self.cfg
        if v.inv[Item.WOOD] < self._wood_wanted(v):
            action = act_on(v, v.map == Block.TREE, int(Action.DO), cfg.near)
            if action is not None:
                return action
        if v.inv[Item.STONE] < self._stone_wanted(v):
            action = act_on(v, self._minable_stone(v), int(Action.DO))
            if action is not None:
                return action
        for tool in (Item.STONE_PICKAXE, Item.STONE_SWORD):
            if not v.has(tool):
                return self._make(v, tool)
        if not v.done(Ach.PLACE_FURNACE):
            action = self._station(v, furnace=True)
            if action is not None:
                return action
        iron_tools_missing = sum(not v.has(t) for t in (Item.IRON_PICKAXE, Item.IRON_SWORD))
        for item, block, target in (
            (Item.COAL, Block.COAL, cfg.coal_target),
            (Item.IRON, Block.IRON, cfg.iron_target),
        ):
            if v.inv[item] < min(iron_tools_missing, target):
                action = act_on(v, v.map == block, int(Action.DO))
                if action is not None:
                    return action
        for tool in (Item.IRON_PICKAXE, Item.IRON_SWORD):
            if not v.has(tool):
                action = self._make(v, tool)
                if action is not None:
                    return action
        if v.has(Item.IRON_PICKAXE) and not v.done(Ach.COLLECT_DIAMOND):
            return act_on(v, v.map == Block.DIAMOND, int(Action.DO))
        return None

    def _wood_wanted(self, v: View) -> int:
        """Wood for the tools still missing plus one spare table."""
        tools = sum(not v.has(t) for t in RECIPES)
        return min(self.cfg.wood_target, tools + self.cfg.table_wood)

    def _stone_wanted(self, v: View) -> int:
        return self.cfg.stone_target if v.has(Item.WOOD_PICKAXE) else 0

    def _make(self, v: View, tool: Item) -> int | None:
        """Fetch what ``tool`` takes, reach (or build) its stations and craft it."""
        action, wood, stone, coal, iron, furnace = RECIPES[tool]
        cfg = self.cfg
        for item, n, block in (
            (Item.WOOD, wood, Block.TREE),
            (Item.STONE, stone, Block.STONE),
            (Item.COAL, coal, Block.COAL),
            (Item.IRON, iron, Block.IRON),
        ):
            if v.inv[item] < n:
                target = self._minable_stone(v) if block == Block.STONE else v.map == block
                return act_on(v, target, int(Action.DO))
        blocks = (Block.TABLE, Block.FURNACE) if furnace else (Block.TABLE,)
        spots = crafting_spots(v, *blocks)
        if goal_distance(v, spots & v.free) <= cfg.station_dist:
            return craft(v, spots, int(action))
        station = self._station(v, furnace, extra_wood=wood, extra_stone=stone)
        if station is not None:
            return station
        return craft(v, spots, int(action))

    def _station(
        self, v: View, furnace: bool, extra_wood: int = 0, extra_stone: int = 0
    ) -> int | None:
        """Build a table (and a furnace beside it) near the player."""
        cfg = self.cfg
        table_spots = crafting_spots(v, Block.TABLE)
        valid = PLACEABLE[v.map] & (v.mobs == 0)
        if goal_distance(v, table_spots & v.free) > cfg.station_dist:
            if v.inv[Item.WOOD] < cfg.table_wood + extra_wood:
                return act_on(v, v.map == Block.TREE, int(Action.DO))
            return face_free(v, valid, int(Action.PLACE_TABLE))
        if not furnace:
            return None
        if v.inv[Item.STONE] < cfg.furnace_stone + extra_stone:
            if not v.has(Item.WOOD_PICKAXE):
                return None
            return act_on(v, self._minable_stone(v), int(Action.DO))
        return face_free(v, valid, int(Action.PLACE_FURNACE), stand=table_spots)

    # --- after the tree: the hunts that need luck --------------------------------------------
    def _late_goals(self, v: View) -> int | None:
        """Seek skeletons in the tunnels (they spawn on path tiles); else stock up nearby."""
        cfg = self.cfg
        if self._skeleton_ready(v):
            path = v.map == Block.PATH
            tunnels = path & (_box_count(path, 4) >= cfg.tunnel_density) & v.free
            action = go_to(v, tunnels)
            if action is not None and self.rng.random() < cfg.tunnel_bias:
                return action
        if v.inv[Item.WOOD] < cfg.late_wood:
            action = act_on(v, v.map == Block.TREE, int(Action.DO), cfg.near)
            if action is not None:
                return action
        if v.drink < cfg.dusk_drink:
            action = self._drink(v, cfg.near * 2)
            if action is not None:
                return action
        if v.food < cfg.dusk_food:
            action = self._eat(v, cfg.near * 2)
            if action is not None:
                return action
        return None

    def _explore(self, v: View) -> int | None:
        """Walk to random far cells (seeded per env) when nothing else applies."""
        cfg = self.cfg
        stale = v.timestep >= self.explore_until or v.pos == self.explore_target
        if self.explore_target is None or stale:
            self.explore_target = pick_explore_target(v, self.rng, cfg.explore_dist)
            self.explore_until = v.timestep + cfg.explore_steps
        return explore_step(v, self.explore_target)


def _box_count(mask: np.ndarray, radius: int) -> np.ndarray:
    """Number of ``mask`` cells in the (2r+1)^2 box around each cell."""
    padded = np.pad(mask.astype(np.int32), radius + 1)
    csum = padded.cumsum(0).cumsum(1)
    k = 2 * radius + 1
    rows, cols = mask.shape
    return (
        csum[k : k + rows, k : k + cols]
        - csum[0:rows, k : k + cols]
        - csum[k : k + rows, 0:cols]
        + csum[0:rows, 0:cols]
    )



# --- goal-directed play: one behaviour per instruction (a caption text) ----------------------
def _tool_first(planner: EnvPlanner, v: View, tool: Item) -> int | None:
    """Make ``tool`` when it is missing (a pickaxe before mining), else None."""
    return None if v.has(tool) else planner._make(v, tool)


def _mine(block: Block):
    def goal(planner: EnvPlanner, v: View) -> int | None:
        action = _tool_first(planner, v, Item.WOOD_PICKAXE)
        if action is not None:
            return action
        target = planner._minable_stone(v) if block == Block.STONE else v.map == block
        return act_on(v, target, int(Action.DO))

    return goal


def _collect_sapling(planner: EnvPlanner, v: View) -> int | None:
    """Hit grass until a sapling drops (10% per hit in both games)."""
    return face_free(v, (v.map == Block.GRASS) & (v.mobs == 0), int(Action.DO))


def _place_plant(planner: EnvPlanner, v: View) -> int | None:
    if not v.has(Item.SAPLING):
        return _collect_sapling(planner, v)
    return face_free(v, (v.map == Block.GRASS) & (v.mobs == 0), int(Action.PLACE_PLANT))


def _eat_plant(planner: EnvPlanner, v: View) -> int | None:
    """Eat a ripe plant; wait beside a growing one; plant one if there is none."""
    action = act_on(v, v.map == Block.RIPE_PLANT, int(Action.DO))
    if action is not None:
        return action
    if (v.map == Block.PLANT).any():
        return act_on(v, v.map == Block.PLANT, int(Action.NOOP))
    return _place_plant(planner, v)


def _place(action: Action, item: Item, cost_of):
    """Place (``action``) on grass, first fetching ``cost_of(cfg)`` of ``item`` (wood or stone)."""

    def goal(planner: EnvPlanner, v: View) -> int | None:
        if v.inv[item] < cost_of(planner.cfg):
            fetch = _mine(Block.STONE) if item == Item.STONE else _obtain_wood
            return fetch(planner, v)
        return face_free(v, (v.map == Block.GRASS) & (v.mobs == 0), int(action))

    return goal


def _craft(tool: Item):
    def goal(planner: EnvPlanner, v: View) -> int | None:
        stone_needed = RECIPES[tool][2]
        if stone_needed > v.inv[Item.STONE]:
            action = _tool_first(planner, v, Item.WOOD_PICKAXE)
            if action is not None:
                return action
        return planner._make(v, tool)

    return goal


def _obtain_drink(planner: EnvPlanner, v: View) -> int | None:
    """Drink; with ``drink_in_view``, explore until water is on screen."""
    if planner.cfg.drink_in_view and not v.seen(v.map == Block.WATER):
        return planner._explore(v)
    return planner._drink(v)


def _obtain_wood(planner: EnvPlanner, v: View) -> int | None:
    return act_on(v, v.map == Block.TREE, int(Action.DO))


INSTRUCTIONS = {
    "obtain wood": _obtain_wood,
    "obtain stone": _mine(Block.STONE),
    "obtain coal": _mine(Block.COAL),
    "obtain sapling": _collect_sapling,
    "obtain drink": _obtain_drink,
    "obtain ripe plant": _eat_plant,
    "place plant on grass": _place_plant,
    "place table on grass": _place(Action.PLACE_TABLE, Item.WOOD, lambda c: c.table_wood),
    "place stone on grass": _place(Action.PLACE_STONE, Item.STONE, lambda c: 1),
    "craft wood pickaxe": _craft(Item.WOOD_PICKAXE),
    "craft wood sword": _craft(Item.WOOD_SWORD),
    "craft stone pickaxe": _craft(Item.STONE_PICKAXE),
    "craft stone sword": _craft(Item.STONE_SWORD),
}
"""The captions the goal-directed expert follows, each mapped to its behaviour."""
