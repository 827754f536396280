"""Shortest paths on the 64x64 map for the scripted expert.

One Dijkstra from the player per step answers every "where is the nearest X" question at
once, so goals can change every step without re-planning costs. Cell costs are small
integers (1 to walk, more to mine or bridge through), the search is compiled with numba
(cheap enough to run every step) and ties break in a fixed neighbour order, so plans are
deterministic.
"""

from __future__ import annotations

import numba
import numpy as np

UNREACHABLE = np.int32(1 << 30)
NO_PARENT = -1
_RING = 16  # buckets of Dial's queue: a power of two above the largest step cost
MAX_COST = _RING - 1

# Neighbour order (left, right, up, down) = the move actions 1..4.
_D_ROW = np.array([0, 0, -1, 1], np.int64)
_D_COL = np.array([-1, 1, 0, 0], np.int64)


_BUCKETS: dict[int, np.ndarray] = {}


def distance_field(cost: np.ndarray, start_row: int, start_col: int):
    """Cheapest cost to enter every cell from the start, and each cell's predecessor.

    ``cost[r, c]`` is what entering cell (r, c) costs, below ``MAX_COST``; values <= 0 mark
    impassable cells. Dial's bucket queue (costs are small integers) keeps this linear in
    the map size. Returns ``(dist, parent)``: int32 arrays, ``UNREACHABLE`` / ``NO_PARENT``
    where no path.
    """
    if cost.max() > MAX_COST:
        raise ValueError(f"step costs must be below {MAX_COST + 1}, got {cost.max()}")
    n = cost.size
    buckets = _BUCKETS.get(n)
    if buckets is None:
        # A cell sits at most once in a bucket: pending distances span fewer than _RING values.
        buckets = _BUCKETS[n] = np.empty((_RING, n), np.int32)
    return _dial(np.ascontiguousarray(cost), int(start_row), int(start_col), buckets)


@numba.njit(cache=True)
def _dial(cost: np.ndarray, start_row: int, start_col: int, buckets: np.ndarray):
    rows, cols = cost.shape
    n = rows * cols
    dist = np.full(n, UNREACHABLE, np.int32)
    parent = np.full(n, NO_PARENT, np.int32)
    flat_cost = cost.ravel()
    counts = np.zeros(_RING, np.int64)
    start = start_row * cols + start_col
    dist[start] = 0
    buckets[0, 0] = start
    counts[0] = 1
    pending = 1
    current = 0
    while pending > 0:
        b = current & (_RING - 1)
        i = 0
        while i < counts[b]:
            idx = buckets[b, i]
            i += 1
            pending -= 1
            if dist[idx] != current:
                continue
            r, c = idx // cols, idx % cols
            for k in range(4):
                nr, nc = r + _D_ROW[k], c + _D_COL[k]
                if nr < 0 or nr >= rows or nc < 0 or nc >= cols:
                    continue
                nidx = nr * cols + nc
                w = flat_cost[nidx]
                if w <= 0:
                    continue
                nd = current + w
                if nd < dist[nidx]:
                    dist[nidx] = nd
                    parent[nidx] = idx
                    nb = nd & (_RING - 1)
                    buckets[nb, counts[nb]] = nidx
                    counts[nb] += 1
                    pending += 1
        counts[b] = 0
        current += 1
    return dist.reshape(rows, cols), parent.reshape(rows, cols)


@numba.njit(cache=True)
def first_step(parent: np.ndarray, start_row: int, start_col: int, goal_row: int, goal_col: int):
    """The first cell after the start on the stored path to the goal ((-1, -1) if none)."""
    cols = parent.shape[1]
    start = start_row * cols + start_col
    idx = goal_row * cols + goal_col
    if idx == start:
        return -1, -1
    for _ in range(parent.size):
        prev = parent[idx // cols, idx % cols]
        if prev == NO_PARENT:
            return -1, -1
        if prev == start:
            return idx // cols, idx % cols
        idx = prev
    return -1, -1


def nearest(dist: np.ndarray, goal: np.ndarray) -> tuple[int, int, int] | None:
    """(row, col, distance) of the cheapest goal cell, or None when no goal cell is reachable."""
    masked = np.where(goal, dist, UNREACHABLE)
    idx = int(np.argmin(masked))
    best = int(masked.flat[idx])
    if best >= UNREACHABLE:
        return None
    return idx // dist.shape[1], idx % dist.shape[1], best


def shift(mask: np.ndarray, d_row: int, d_col: int, fill: bool = False) -> np.ndarray:
    """``out[r, c] = mask[r + d_row, c + d_col]`` (cells beyond the edge read ``fill``)."""
    out = np.full_like(mask, fill)
    rows, cols = mask.shape
    src_r = slice(max(d_row, 0), rows + min(d_row, 0))
    dst_r = slice(max(-d_row, 0), rows + min(-d_row, 0))
    src_c = slice(max(d_col, 0), cols + min(d_col, 0))
    dst_c = slice(max(-d_col, 0), cols + min(-d_col, 0))
    out[dst_r, dst_c] = mask[src_r, src_c]
    return out


def next_to(mask: np.ndarray) -> np.ndarray:
    """Cells with a 4-neighbour in ``mask``."""
    return shift(mask, 0, -1) | shift(mask, 0, 1) | shift(mask, -1, 0) | shift(mask, 1, 0)


def near(mask: np.ndarray) -> np.ndarray:
    """Cells whose 3x3 neighbourhood (itself included) holds a ``mask`` cell: crafting range."""
    out = mask.copy()
    for d_row in (-1, 0, 1):
        for d_col in (-1, 0, 1):
            if d_row or d_col:
                out |= shift(mask, d_row, d_col)
    return out
