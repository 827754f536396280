"""A sealed two-cell pocket to sleep in, so zombies and arrows cannot reach the sleeper.

The player only faces a free tile by stepping towards it, so one cell can never be sealed
from inside (the side it came in by stays open). Two cells can: walk A -> S1 -> S2, close the
far end, step back to S1 (now facing A) and close A. The pocket's side walls must already be
solid, which tunnels dug into stone give for free; S1 and S2 may be stone that gets mined.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from zoo.envs.constants import DIRECTION_OFFSETS, Action, Block, Item
from zoo.experts.scripted.navigation import UNREACHABLE, shift
from zoo.experts.scripted.world import MOVES, OPPOSITE, STONE_PLACEABLE, WALL, View


@dataclass
class Pocket:
    """Pocket cells S1 (where the player sleeps) and S2 = S1 + d, entered from A = S1 - d."""

    s1: tuple[int, int]
    move: int  # d as a move action
    been_deep: bool = False

    def cell(self, k: int) -> tuple[int, int]:
        d_row, d_col = DIRECTION_OFFSETS[self.move]
        return self.s1[0] + k * d_row, self.s1[1] + k * d_col

    @property
    def entry(self) -> tuple[int, int]:
        return self.cell(-1)

    @property
    def s2(self) -> tuple[int, int]:
        return self.cell(1)


def enclosed(view: View, max_cells: int = 2) -> bool:
    """Whether the walkable region around the player is at most ``max_cells`` and mob-free."""
    seen = {view.pos}
    frontier = [view.pos]
    while frontier:
        cell = frontier.pop()
        for move in MOVES:
            nxt = view.neighbour(cell, move)
            if nxt in seen or not view.in_bounds(nxt):
                continue
            block = view.block(nxt)
            if WALL[block] or block == Block.WATER:
                continue
            if view.mob(nxt) or block == Block.LAVA:
                return False
            seen.add(nxt)
            if len(seen) > max_cells:
                return False
            frontier.append(nxt)
    return True


def find_pocket(view: View, max_dist: int) -> Pocket | None:
    """The pocket whose entry is cheapest to reach, or None (needs stone and a pickaxe)."""
    if not (view.has(Item.WOOD_PICKAXE) and view.has(Item.STONE)):
        return None
    wall = WALL[view.map]
    stone = view.map == Block.STONE
    enterable = view.free | (stone & (view.mobs == 0))
    placeable = STONE_PLACEABLE[view.map] & (view.mobs == 0)
    best = None
    for move in MOVES:
        d_row, d_col = DIRECTION_OFFSETS[move]
        p_row, p_col = d_col, d_row  # a perpendicular offset

        def at(mask, k, j=0, fill=False, d_row=d_row, d_col=d_col, p_row=p_row, p_col=p_col):
            return shift(mask, k * d_row + j * p_row, k * d_col + j * p_col, fill)

        ok = enterable & at(enterable, 1) & at(view.free, -1)
        for k in (0, 1):
            ok &= at(wall, k, 1, True) & at(wall, k, -1, True)
        far_end_open = at(placeable, 2) & ~at(wall, 2, 0, True)
        ok &= at(wall, 2, 0, True) | (far_end_open & view.has(Item.STONE, 2))
        if not ok.any():
            continue
        entry_dist = np.where(ok, at(view.dist, -1, 0, UNREACHABLE), UNREACHABLE)
        idx = int(np.argmin(entry_dist))
        d = int(entry_dist.flat[idx])
        if d <= max_dist and (best is None or d < best[0]):
            best = (d, Pocket((idx // view.shape[1], idx % view.shape[1]), int(move)))
    return None if best is None else best[1]


def pocket_intact(view: View, pocket: Pocket) -> bool:
    """The plan still works: the pocket cells are enterable and the sides still walls."""
    d_row, d_col = DIRECTION_OFFSETS[pocket.move]
    for k in (0, 1):
        cell = pocket.cell(k)
        for side in ((cell[0] + d_col, cell[1] + d_row), (cell[0] - d_col, cell[1] - d_row)):
            if not WALL[view.block(side)]:
                return False
        if cell != view.pos and not (view.is_free(cell) or view.block(cell) == Block.STONE):
            return False
    return True


def seal_step(view: View, pocket: Pocket) -> int | None:
    """The next action of walking into the pocket and closing it (None when off-plan)."""
    move, back = pocket.move, int(OPPOSITE[pocket.move])
    s1, s2, entry, far = pocket.s1, pocket.s2, pocket.entry, pocket.cell(2)
    if view.pos == s2:
        pocket.been_deep = True
        if not WALL[view.block(far)] and view.dir == move and view.has(Item.STONE):
            return int(Action.PLACE_STONE)
        return back if view.is_free(s1) else None
    if view.pos == s1:
        if not pocket.been_deep:
            return view.enter(s2) if view.block(s2) != Block.LAVA else None
        if view.dir == back:
            if view.mob(entry):
                return int(Action.DO)
            if STONE_PLACEABLE[view.block(entry)] and view.has(Item.STONE):
                return int(Action.PLACE_STONE)
            return None
        return move if view.is_free(s2) else None
    if view.pos == entry:
        return view.enter(s1)
    if view.dist[entry] >= UNREACHABLE:
        return None
    return view.step_to(entry)
