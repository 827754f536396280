"""The map tiles a player sees: what a pixel agent (and any planner that must not know more
than it) can act on."""

from __future__ import annotations

import numpy as np

from zoo.envs.constants import VIEW


def local_tiles(
    tiles: np.ndarray, pos: tuple[int, int], rows: int = VIEW[0] // 2, cols: int = VIEW[1] // 2
) -> np.ndarray:
    """The cells of a map-shaped array within ``rows`` above and below and ``cols`` left and
    right of ``pos`` (the 7 x 9 view by default), cut off at the map's edge."""
    row, col = pos
    return tiles[max(0, row - rows):row + rows + 1, max(0, col - cols):col + cols + 1]
