"""The rule machinery: what a rule sees (a `Window` on one episode at step t) and the registry.

A rule is one function ``rule(window) -> list[str]`` returning the captions that fire at step
t, registered with `register_rule` next to its definition (rules_achievement.py,
rules_movement.py, rules_construction.py, rules_combat.py). Adding a rule is one function and
its decorator; `all_rules` imports the four modules so the registry is complete.

Step t means: the agent saw state t, took action t, and state t+1 is the outcome. A firing
rule labels the clip o_{t-4..t+1}, so t needs `RuleParams.history` states before it and one
after; `scan_episode` visits exactly those t.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from zoo.envs.constants import DIRECTION_OFFSETS, Action, Block
from zoo.envs.schema import STATE_FIELDS

CATEGORIES = ("achievement", "movement", "construction", "combat")
RULE_MODULES = (
    "zoo.captions.rules_achievement",
    "zoo.captions.rules_movement",
    "zoo.captions.rules_construction",
    "zoo.captions.rules_combat",
)
NO_MOB = 1 << 20  # distance to a mob type absent from the state
WALKABLE = frozenset({int(Block.GRASS), int(Block.SAND), int(Block.PATH)})  # mobs walk here
MOB_FIELDS = {"cow": "cows", "zombie": "zombies", "skeleton": "skeletons", "arrow": "arrows"}
HOSTILE_MOBS = ("zombie", "skeleton")
PLACE_ACTIONS = {
    int(Action.PLACE_STONE): ("stone", int(Block.STONE)),
    int(Action.PLACE_TABLE): ("table", int(Block.TABLE)),
    int(Action.PLACE_FURNACE): ("furnace", int(Block.FURNACE)),
    int(Action.PLACE_PLANT): ("plant", int(Block.PLANT)),
}
PLACEABLE_ITEMS = tuple(item for item, _ in PLACE_ACTIONS.values())


@dataclass(frozen=True)
class RuleParams:
    """Thresholds of the rules, in grid tiles (Manhattan) and steps; see docs/captions.md."""

    history: int = 4
    """Steps of context before t in a clip (the paper's o_{t-4..t+1})."""
    move_min_displacement: int = 2
    """Move: net tiles travelled in the named direction over the clip."""
    approach_radius: int = 2
    """Approach: the mob is at most this far at t+1."""
    approach_min_gain: int = 2
    """Approach: the distance shrank by at least this over the clip."""
    flee_radius: int = 4
    """Flee: the hostile mob was at most this far at the clip's start."""
    flee_min_gain: int = 2
    """Flee: the distance grew by at least this over the clip."""
    arrow_radius: int = 4
    """Flee from / block an arrow: only arrows at most this far, flying at the player, count."""
    explore_min_moves: int = 4
    """Explore: steps of the clip on which the player changed tile."""
    explore_min_displacement: int = 3
    """Explore: net tiles travelled over the clip."""
    explore_memory: int = 64
    """Explore: the tile reached at t+1 was not visited in this many previous steps."""
    shelter_threat_radius: int = 6
    """Shelter: with 3 of 4 sides closed, a hostile mob this near (or night) makes it a shelter."""
    night_light: float = 0.35
    """Shelter: light level below which it counts as night."""
    path_memory: int = 16
    """Path: the tile walked onto was water/lava within this many previous steps."""
    block_radius: int = 4
    """Block Attack: the zombie/skeleton is at most this far at t."""


@dataclass(frozen=True)
class Rule:
    """A registered rule: its name, category, caption template, allowed fillings, checker."""

    name: str
    category: str
    template: str
    fills: tuple[dict[str, str], ...]
    check: Callable[[Window], list[str]]

    def captions(self) -> list[str]:
        """Every caption this rule can produce, in declaration order."""
        return [self.template.format(**fill) for fill in self.fills]


_REGISTRY: dict[str, Rule] = {}


def register_rule(
    name: str, category: str, template: str, fills: list[dict[str, str]] | None = None
) -> Callable[[Callable[[Window], list[str]]], Callable[[Window], list[str]]]:
    """Decorator adding a rule function to the registry (its one registry entry)."""
    if category not in CATEGORIES:
        raise ValueError(f"rule {name!r}: category {category!r} not in {CATEGORIES}")
    if name in _REGISTRY:
        raise ValueError(f"rule {name!r} is registered twice")

    def add(fn: Callable[[Window], list[str]]) -> Callable[[Window], list[str]]:
        _REGISTRY[name] = Rule(name, category, template, tuple(fills or [{}]), fn)
        return fn

    return add


def all_rules() -> dict[str, Rule]:
    """The registry, name -> Rule, in the paper's table order (category, then rule)."""
    for module in RULE_MODULES:
        importlib.import_module(module)
    return dict(_REGISTRY)


def direction_offset(direction: int) -> tuple[int, int]:
    return DIRECTION_OFFSETS.get(int(direction), (0, 0))


class EpisodeView:
    """An episode's actions and states with the per-step quantities several rules share.

    Args:
        actions: (T,) action ids; action t was taken in state t (-1 for the final state).
        state: schema field -> (T, ...) arrays (zoo.envs.schema.STATE_FIELDS).
    """

    def __init__(self, actions: np.ndarray, state: dict[str, np.ndarray]) -> None:
        self.actions = np.asarray(actions, np.int64)
        self.state = state
        self.length = len(self.actions)
        for name in STATE_FIELDS:
            if name not in state:
                raise ValueError(f"episode state lacks field {name!r}")
            if len(state[name]) != self.length:
                raise ValueError(
                    f"episode state field {name!r} has {len(state[name])} steps, "
                    f"expected {self.length} (one per action)"
                )
        self.pos = np.asarray(state["player_pos"], np.int64)
        self.map = state["map"]
        self.size = self.map.shape[1:]

    @cached_property
    def moved(self) -> np.ndarray:
        """(T,) bool: the player changed tile between t and t+1 (False at the last step)."""
        out = np.zeros(self.length, bool)
        out[:-1] = np.any(self.pos[1:] != self.pos[:-1], axis=1)
        return out

    def mobs(self, mob: str, t: int) -> np.ndarray:
        """(k, 2) positions of the live mobs of one kind at step t."""
        key = MOB_FIELDS[mob]
        live = self.state[f"{key}_status"][t, :, 0] > 0
        return np.asarray(self.state[f"{key}_pos"][t][live], np.int64)

    @cached_property
    def _nearest(self) -> dict[str, np.ndarray]:
        out = {}
        for mob, key in MOB_FIELDS.items():
            pos = np.asarray(self.state[f"{key}_pos"], np.int64)
            live = np.asarray(self.state[f"{key}_status"][..., 0]) > 0
            dist = np.abs(pos - self.pos[:, None, :]).sum(-1)
            out[mob] = np.where(live, dist, NO_MOB).min(axis=1, initial=NO_MOB)
        return out

    def nearest(self, mob: str) -> np.ndarray:
        """(T,) Manhattan distance from the player to the nearest live mob of that kind."""
        return self._nearest[mob]

    def tile(self, t: int, rc: np.ndarray | tuple[int, int]) -> int:
        """Block id at (row, col) in state t; OUT_OF_BOUNDS outside the map."""
        r, c = int(rc[0]), int(rc[1])
        if 0 <= r < self.size[0] and 0 <= c < self.size[1]:
            return int(self.map[t, r, c])
        return int(Block.OUT_OF_BOUNDS)


@dataclass(frozen=True)
class Placement:
    """A block the action at t put down: which item, where, on what."""

    item: str
    tile: tuple[int, int]
    material: int


@dataclass(frozen=True)
class Window:
    """What a rule sees: the episode around step t (states t-history..t+1, actions up to t)."""

    episode: EpisodeView
    t: int
    params: RuleParams = field(default_factory=RuleParams)

    @property
    def action(self) -> int:
        return int(self.episode.actions[self.t])

    @property
    def start(self) -> int:
        """First step of the clip (t - history)."""
        return self.t - self.params.history

    def state(self, name: str, dt: int = 0) -> np.ndarray:
        """State field ``name`` at step t + dt."""
        return self.episode.state[name][self.t + dt]

    def pos(self, dt: int = 0) -> np.ndarray:
        return self.episode.pos[self.t + dt]

    def asleep(self, dt: int = 0) -> bool:
        return bool(self.episode.state["player_sleeping"][self.t + dt])

    def facing_tile(self) -> np.ndarray:
        """The tile the player faces at t: the target of DO and place actions."""
        return self.pos() + np.array(direction_offset(self.state("player_dir")))

    def nearest(self, mob: str, dt: int = 0) -> int:
        return int(self.episode.nearest(mob)[self.t + dt])

    def placement(self) -> Placement | None:
        """The block placed by action t, if the action was a place action that took effect."""
        placed = PLACE_ACTIONS.get(self.action)
        if placed is None or self.asleep():
            return None
        item, block = placed
        target = self.facing_tile()
        before, after = self.episode.tile(self.t, target), self.episode.tile(self.t + 1, target)
        if before == block or after != block:
            return None
        return Placement(item, (int(target[0]), int(target[1])), before)

    def blocked_sides(self, dt: int = 1) -> int:
        """How many of the player's 4 neighbours at t+dt no mob can walk into."""
        here = self.pos(dt)
        return sum(
            self.episode.tile(self.t + dt, here + np.array(off)) not in WALKABLE
            for off in DIRECTION_OFFSETS.values()
        )

    def incoming_arrows(self, dt: int = 0) -> Iterator[np.ndarray]:
        """Positions at t+dt of arrows flying straight at the player, within arrow_radius."""
        status, arrows = self.state("arrows_status", dt), self.state("arrows_pos", dt)
        heading, player = self.state("arrows_dir", dt), self.pos(dt)
        for i in np.flatnonzero(status[:, 0] > 0):
            offset = player - arrows[i].astype(np.int64)
            step = heading[i].astype(np.int64)
            dist = int(np.abs(offset).sum())
            if dist == 0 or dist > self.params.arrow_radius or not step.any():
                continue
            # flying at the player: the offset is a positive multiple of the heading
            if np.array_equal(np.sign(offset), step) and (offset[0] == 0 or offset[1] == 0):
                yield arrows[i].astype(np.int64)


def scan_episode(
    episode: EpisodeView, rules: dict[str, Rule] | None = None, params: RuleParams | None = None
) -> Iterator[tuple[int, str, str]]:
    """Yield (t, rule name, caption) for every rule firing at every step with a full clip."""
    rules = all_rules() if rules is None else rules
    params = params or RuleParams()
    for t in range(params.history, episode.length - 1):
        if episode.actions[t] < 0:
            break
        window = Window(episode, t, params)
        for name, rule in rules.items():
            for caption in rule.check(window):
                yield t, name, caption
