"""Staying alive: fight what is adjacent, dodge arrows, keep drink and food up, and spend
nights and hurt spells sealed in a pocket (zombies hit a sleeper for 7).

A mixin of ``EnvPlanner``: the goals here come first in its priority list.
"""

from __future__ import annotations

import numpy as np

from zoo.envs.constants import DIRECTION_OFFSETS, Action, Block, Item, Mob
from zoo.experts.scripted.config import ExpertConfig
from zoo.experts.scripted.navigation import UNREACHABLE, next_to
from zoo.experts.scripted.shelter import Pocket, enclosed, find_pocket, pocket_intact, seal_step
from zoo.experts.scripted.skills import act_on, craft, crafting_spots, goal_distance
from zoo.experts.scripted.world import MOVES, PLACEABLE, WALL, View


class SurvivalGoals:
    """Threat, needs and shelter goals, with the memory they keep between steps."""

    def __init__(self, config: ExpertConfig) -> None:
        self.cfg = config
        self.pocket: Pocket | None = None
        self.resting = False  # hurt: hide in a pocket until health is back
        self.refill: str | None = None  # "drink" / "food" while topping up to full
        self.is_night = False

    # --- threats ---------------------------------------------------------------------------
    def _fight_adjacent(self, v: View) -> int | None:
        """Hit an adjacent zombie/skeleton, keeping to the one already faced."""
        if v.mob(v.facing) in (Mob.ZOMBIE, Mob.SKELETON):
            return int(Action.DO)
        for move in MOVES:
            if v.mob(v.neighbour(v.pos, move)) in (Mob.ZOMBIE, Mob.SKELETON):
                return int(move)
        return None

    def _arm(self, v: View) -> int | None:
        """Zombie about and no sword: craft one on the spot if the wood allows."""
        armed = v.has(Item.WOOD_SWORD) or v.has(Item.STONE_SWORD) or v.has(Item.IRON_SWORD)
        if armed or not self._hostile_within(v, self.cfg.flee_dist + 2):
            return None
        spots = crafting_spots(v, Block.TABLE)
        if v.has(Item.WOOD) and goal_distance(v, spots & v.free) <= 3:
            return craft(v, spots, int(Action.MAKE_WOOD_SWORD))
        facing_ok = PLACEABLE[v.block(v.facing)] and not v.mob(v.facing)
        if v.has(Item.WOOD, self.cfg.table_wood + 1) and facing_ok:
            return int(Action.PLACE_TABLE)
        return None

    def _flee_unarmed(self, v: View) -> int | None:
        """Without a sword a zombie takes five hits: walk away instead (a zombie only strikes
        when it starts its turn next to the player, so one that keeps chasing never does)."""
        if v.has(Item.WOOD_SWORD) or v.has(Item.STONE_SWORD) or v.has(Item.IRON_SWORD):
            return None
        zombies = [c for c in v.mob_cells(Mob.ZOMBIE) if v.manhattan(c) <= self.cfg.flee_dist]
        if not zombies:
            return None

        def gap(cell):
            return min(abs(cell[0] - z[0]) + abs(cell[1] - z[1]) for z in zombies)

        best, best_gap = None, gap(v.pos)
        for move in MOVES:
            cell = v.neighbour(v.pos, move)
            if v.is_free(cell) and gap(cell) > best_gap:
                best, best_gap = int(move), gap(cell)
        return best

    def _dodge_arrows(self, v: View) -> int | None:
        """Step out of the line of an arrow flying at the player (or wall it off)."""
        incoming = [d for a, d in v.arrows if self._arrow_hits(v, a, d, v.pos)]
        if not incoming:
            return None
        d_row, d_col = incoming[0]
        for move in MOVES:
            m_row, m_col = DIRECTION_OFFSETS[move]
            if (m_row, m_col) in ((d_row, d_col), (-d_row, -d_col)):
                continue
            cell = v.neighbour(v.pos, move)
            if v.is_free(cell) and not any(self._arrow_hits(v, a, d, cell) for a, d in v.arrows):
                return int(move)
        toward = (v.pos[0] - d_row, v.pos[1] - d_col)
        if v.facing == toward and v.is_free(toward) and v.has(Item.STONE):
            return int(Action.PLACE_STONE)
        return None

    @staticmethod
    def _arrow_hits(
        v: View, arrow: tuple[int, int], heading: tuple[int, int], cell: tuple[int, int]
    ) -> bool:
        """Whether an arrow flying straight reaches ``cell`` within a few steps, unblocked."""
        if heading == (0, 0):
            return False
        for k in range(1, 6):
            at = (arrow[0] + k * heading[0], arrow[1] + k * heading[1])
            if at == cell:
                return True
            if not v.in_bounds(at) or WALL[v.block(at)]:
                return False
        return False

    def _engage_zombie(self, v: View) -> int | None:
        """Meet a zombie that is about to arrive: turning away only gives it free hits."""
        zombies = v.mobs == Mob.ZOMBIE
        if not zombies.any():
            return None
        close = [c for c in v.mob_cells(Mob.ZOMBIE) if v.manhattan(c) <= self.cfg.zombie_engage]
        if not close or enclosed(v):
            return None
        return act_on(v, zombies, int(Action.DO), self.cfg.zombie_engage)

    # --- sleep -----------------------------------------------------------------------------
    def _night(self, v: View) -> bool:
        """Night from dusk (light below ``night_light``) until full day (``dawn_light``):
        mobs spawned in the dark linger round the pocket until the light is back."""
        if v.light < self.cfg.night_light:
            self.is_night = True
        elif v.light >= self.cfg.dawn_light:
            self.is_night = False
        return self.is_night

    def _sleep(self, v: View) -> int | None:
        """Spend nights, low-energy and low-health spells sealed in a pocket, asleep if tired."""
        cfg = self.cfg
        if v.health <= cfg.rest_health:
            self.resting = True
        elif v.health >= cfg.rested_health:
            self.resting = False
        # A hurt player heals only while fed and watered: by day, top those up first.
        needy = v.drink <= cfg.drink_low or v.food <= cfg.food_low
        hide = self.resting and not needy
        shelter = v.energy <= cfg.energy_low or self._night(v) or hide
        if enclosed(v):
            if v.energy < 9 and (shelter or self.pocket is not None):
                return int(Action.SLEEP)
            if hide or (self._night(v) and cfg.rest_until_day):
                return int(Action.NOOP)
            self.pocket = None
            return None
        if not shelter:
            self.pocket = None
            return None
        if self.pocket is not None and not pocket_intact(v, self.pocket):
            self.pocket = None
        if self.pocket is None:
            self.pocket = find_pocket(v, cfg.shelter_dist)
        if self.pocket is not None:
            action = seal_step(v, self.pocket)
            if action is not None:
                return action
            self.pocket = None
        if v.energy == 0 and not self._hostile_within(v, 8):
            return int(Action.SLEEP)
        return None

    def _hostile_within(self, v: View, radius: int) -> bool:
        rows, cols = np.nonzero((v.mobs == Mob.ZOMBIE) | (v.mobs == Mob.SKELETON))
        if rows.size == 0:
            return False
        return bool((np.abs(rows - v.pos[0]) + np.abs(cols - v.pos[1])).min() <= radius)

    # --- needs -----------------------------------------------------------------------------
    def _dusk_supplies(self, v: View) -> int | None:
        """Drink and eat up before the night: leaving the pocket in the dark is deadly."""
        cfg = self.cfg
        if v.light >= cfg.dusk_light or enclosed(v):
            return None
        if v.drink < cfg.dusk_drink:
            self.refill = "drink"
        elif v.food < cfg.dusk_food:
            self.refill = "food"
        else:
            return None
        return self._critical_needs(v)

    def _urgent_needs(self, v: View) -> int | None:
        """Start refilling drink or food below the comfort threshold (by day)."""
        if v.drink <= self.cfg.drink_low:
            self.refill = "drink"
        elif v.food <= self.cfg.food_low:
            self.refill = "food"
        else:
            return None
        return self._critical_needs(v)

    def _critical_needs(self, v: View) -> int | None:
        """Finish a refill once begun; start one even at night when nearly out."""
        cfg = self.cfg
        if self.refill is None:
            if v.drink <= cfg.critical:
                self.refill = "drink"
            elif v.food <= cfg.critical:
                self.refill = "food"
        if self.refill == "drink" and v.drink < 9:
            action = self._drink(v)
        elif self.refill == "food" and v.food < cfg.food_full:
            action = self._eat(v)
        else:
            action = None
        if action is None:
            self.refill = None
        return action

    def _drink(self, v: View, max_dist: int = int(UNREACHABLE)) -> int | None:
        return act_on(v, v.map == Block.WATER, int(Action.DO), max_dist)

    def _eat(self, v: View, max_dist: int = int(UNREACHABLE)) -> int | None:
        """Go for the nearer of a ripe plant and a cow."""
        plants, cows = v.map == Block.RIPE_PLANT, v.mobs == Mob.COW
        if goal_distance(v, next_to(plants)) > goal_distance(v, next_to(cows)):
            plants, cows = cows, plants
        action = act_on(v, plants, int(Action.DO), max_dist)
        if action is not None:
            return action
        return act_on(v, cows, int(Action.DO), max_dist)
