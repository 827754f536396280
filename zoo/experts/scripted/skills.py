"""Small reusable behaviours: reach a cell, act on a block or mob, face a free tile, craft.

Each returns the next action, or None when it cannot make progress (nothing reachable),
so the goal logic can fall through to the next goal.
"""

from __future__ import annotations

import numpy as np

from zoo.envs.constants import DIRECTION_OFFSETS
from zoo.experts.scripted.navigation import UNREACHABLE, near, nearest, next_to, shift
from zoo.experts.scripted.world import MOVES, View


def go_to(view: View, goal: np.ndarray, max_dist: int = int(UNREACHABLE)) -> int | None:
    """Step towards the cheapest cell of ``goal`` (None when there already or none in reach)."""
    if goal[view.pos]:
        return None
    best = nearest(view.dist, goal)
    if best is None or best[2] > max_dist:
        return None
    return view.step_to((best[0], best[1]))


def goal_distance(view: View, goal: np.ndarray) -> int:
    """Path cost to the cheapest ``goal`` cell (UNREACHABLE if none)."""
    best = nearest(view.dist, goal)
    return int(UNREACHABLE) if best is None else best[2]


def act_on(
    view: View, target: np.ndarray, action: int, max_dist: int = int(UNREACHABLE)
) -> int | None:
    """Stand next to a solid ``target`` tile (block or mob), face it and do ``action``.

    Targets must be cells the player cannot walk into (solid blocks, mobs): turning towards
    them is done by moving, which only turns the player when the cell is blocked.
    """
    adjacent = [m for m in MOVES if _get(target, view.neighbour(view.pos, m))]
    if adjacent:
        if view.dir in adjacent:
            return action
        return int(adjacent[0])
    return go_to(view, next_to(target), max_dist)


def face_free(
    view: View,
    valid: np.ndarray,
    action: int,
    stand: np.ndarray | None = None,
    max_dist: int = int(UNREACHABLE),
) -> int | None:
    """Face a walkable tile of ``valid`` (from a cell of ``stand``) and do ``action`` on it.

    Facing a free tile needs the last move to have gone that way, so the plan is: reach the
    cell behind the standing cell, then step onto the standing cell towards the target.
    """
    stand = view.free if stand is None else stand & view.free
    if _get(valid, view.facing) and stand[view.pos]:
        return action
    approach = np.zeros_like(valid)
    per_move = []
    for move in MOVES:
        d_row, d_col = DIRECTION_OFFSETS[move]
        # approach cell Q: Q free, Q + d a free standing cell, Q + 2d valid.
        ok = view.free & shift(stand, d_row, d_col) & shift(valid, 2 * d_row, 2 * d_col)
        per_move.append((move, ok))
        approach |= ok
    for move, ok in per_move:
        if ok[view.pos]:
            return int(move)
    return go_to(view, approach, max_dist)


def craft(
    view: View, spots: np.ndarray, action: int, max_dist: int = int(UNREACHABLE)
) -> int | None:
    """Go to a crafting spot (see ``crafting_spots``) and craft there."""
    spots = spots & view.free
    if spots[view.pos]:
        return action
    return go_to(view, spots, max_dist)


def crafting_spots(view: View, *blocks: int) -> np.ndarray:
    """Cells with every one of ``blocks`` in their 3x3 neighbourhood."""
    spot = np.ones(view.shape, bool)
    for block in blocks:
        spot &= near(view.map == block)
    return spot


def explore_step(view: View, target: tuple[int, int] | None) -> int | None:
    """Walk towards an exploration target."""
    if target is None or target == view.pos or not view.reachable(target):
        return None
    return view.step_to(target)


def pick_explore_target(
    view: View, rng: np.random.Generator, min_dist: int
) -> tuple[int, int] | None:
    """A random reachable cell at least ``min_dist`` away (closer ones if none that far)."""
    reach = (view.dist < UNREACHABLE) & view.free
    far = reach & (view.dist >= min_dist)
    pool = far if far.any() else reach
    rows, cols = np.nonzero(pool)
    if rows.size == 0:
        return None
    k = int(rng.integers(rows.size))
    return int(rows[k]), int(cols[k])


def _get(mask: np.ndarray, cell: tuple[int, int]) -> bool:
    rows, cols = mask.shape
    return 0 <= cell[0] < rows and 0 <= cell[1] < cols and bool(mask[cell])
