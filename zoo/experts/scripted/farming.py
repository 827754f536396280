"""Saplings and plants: collect saplings, plant them (on sheltered grass where there is some)
and seal a sheltered plant's one open side with a stone against trampling.

A mixin of ``EnvPlanner``: ``_first_plant`` and ``_plants`` are goals of its priority list.
"""

from __future__ import annotations

import numpy as np

from zoo.envs.constants import Achievement as Ach
from zoo.envs.constants import Action, Block, Item
from zoo.experts.scripted.config import ExpertConfig
from zoo.experts.scripted.navigation import shift
from zoo.experts.scripted.skills import face_free
from zoo.experts.scripted.world import MOVES, STONE_PLACEABLE, WALL, View


class FarmingGoals:
    """Plant goals, with the memory they keep between steps: the plant to guard."""

    cfg: ExpertConfig
    plant_guard: tuple[int, int] | None = None  # a sheltered plant's open side, to seal

    def _first_plant(self, v: View) -> int | None:
        """With ``plants_first``: a sapling and a plant before anything on the tech tree."""
        if not self.cfg.plants_first or v.done(Ach.PLACE_PLANT):
            return None
        return self._plants(v)

    def _plants(self, v: View) -> int | None:
        """Collect saplings and plant them (sheltered if possible); guard the plant."""
        cfg = self.cfg
        grass = (v.map == Block.GRASS) & (v.mobs == 0)
        if self.plant_guard is not None:
            action = self._guard_plant(v)
            if action is not None:
                return action
        planted = int(np.count_nonzero((v.map == Block.PLANT) | (v.map == Block.RIPE_PLANT)))
        if planted >= cfg.plants_wanted and v.done(Ach.COLLECT_SAPLING):
            return None
        if v.has(Item.SAPLING):
            sheltered = self._sheltered_grass(v, grass)
            for spots in (sheltered, grass):
                action = face_free(v, spots, int(Action.PLACE_PLANT), max_dist=cfg.near)
                if action is not None:
                    if action == Action.PLACE_PLANT and sheltered[v.facing]:
                        self.plant_guard = v.pos
                    return action
            return None
        if planted < cfg.plants_wanted or not v.done(Ach.COLLECT_SAPLING):
            return face_free(v, grass, int(Action.DO), max_dist=cfg.near)
        return None

    def _sheltered_grass(self, v: View, grass: np.ndarray) -> np.ndarray:
        """Grass with walls on three sides: once planted, one stone seals it from trampling."""
        wall = (WALL[v.map] | (v.map == Block.WATER)).astype(np.int8)
        sides = ((0, 1), (0, -1), (1, 0), (-1, 0))
        count = sum(shift(wall, dr, dc, True).astype(np.int8) for dr, dc in sides)
        return grass & (count == 3)

    def _guard_plant(self, v: View) -> int | None:
        """Close the one open side of a sheltered plant with a stone."""
        cell = self.plant_guard
        plant_next = any(
            v.block(v.neighbour(cell, m)) in (Block.PLANT, Block.RIPE_PLANT) for m in MOVES
        )
        if not plant_next or not STONE_PLACEABLE[v.block(cell)] or v.mob(cell):
            self.plant_guard = None
            return None
        if not v.has(Item.STONE):
            return None
        target = np.zeros(v.shape, bool)
        target[cell] = True
        stand = np.ones(v.shape, bool)
        stand[cell] = False
        return face_free(v, target, int(Action.PLACE_STONE), stand, max_dist=self.cfg.station_dist)
