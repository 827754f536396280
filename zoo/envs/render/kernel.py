"""The numba kernel: Craftax-Classic frames from batched exported states, bit for bit.

A frame is the 7x9 block tiles around the player, the player and the mobs blended over
their tiles (player, then zombies, cows, skeletons and arrows, each kind in slot order, as
Craftax scans them), the light (``shade``) and the inventory panel below. Only the tiles a
sprite touches are composited, in float32 work space; then every tile is lit into the uint8
frame, one 16x16 tile at a time (its work space stays in the L1 cache; lighting the whole map
in one pass is slower). By day a plain tile's pixels depend only on its block and the
frame's light and sleep, so each block seen is lit once and copied; at night the static
differs per pixel, so every tile is lit with its share of ``noise.uniform``'s draws. The
panel's arithmetic is all integers and comes precomputed per cell (``textures``).
"""

from __future__ import annotations

import numba
import numpy as np

from zoo.envs.render.cache import njit_cached
from zoo.envs.render.llvm import wide_vectors
from zoo.envs.render.noise import uniform
from zoo.envs.render.shade import blend_player, blend_sprite, copy_tile, shade
from zoo.envs.render.textures import BLOCK, DIGITS, MAP_PX, NUM_BLOCKS, VIEW

TEXELS = BLOCK * BLOCK
TOP, LEFT = VIEW[0] // 2, VIEW[1] // 2  # the player's tile in the view
PLAYER_ASLEEP = 4  # index of the sleeping player's texture
ARROW = 3  # first arrow sprite; zombie 0, cow 1, skeleton 2
HALF = np.float32(0.5)  # light below this is night: the static shows
WORDS = np.uint64(3 * BLOCK // 8)  # a tile row's 48 bytes as uint64 words


@numba.njit(inline="always")
def _wrap_clip(i, n):
    """JAX's index of a length-n axis by a traced int: negatives wrap once, then clamp."""
    i = i + n if i < 0 else i
    return min(max(i, 0), n - 1)


@numba.njit(inline="always")
def _on_screen(positions, status, m, row, col):
    """(tile row, tile col, drawn) of mob slot m: masked and inside the view."""
    i, j = np.int64(positions[m, 0]) - row + TOP, np.int64(positions[m, 1]) - col + LEFT
    return i, j, status[m, 0] != 0 and 0 <= i < VIEW[0] and 0 <= j < VIEW[1]


@njit_cached()
def _mark_mobs(marked, positions, status, row, col):
    for m in range(positions.shape[0]):
        i, j, drawn = _on_screen(positions, status, m, row, col)
        if drawn:
            marked[i, j] = True


@njit_cached()
def _draw_mobs(tiles, slots, sprites, alphas, row, col, positions, status, arrow_dir, kind):
    for m in range(positions.shape[0]):
        i, j, drawn = _on_screen(positions, status, m, row, col)
        if not drawn:
            continue
        sprite = kind
        if kind == ARROW:  # flipped when heading down or right, transposed when sideways
            flip = arrow_dir[m, 0] > 0 or arrow_dir[m, 1] > 0
            sprite = ARROW + np.int64(flip) + 2 * np.int64(arrow_dir[m, 1] != 0)
        blend_sprite(tiles[slots[i, j]], sprites[sprite], alphas[sprite])


@njit_cached()
def _view(ids, map_, row, col):
    """Block ids of the 7x9 tiles around (row, col); outside the map Craftax pads with
    OUT_OF_BOUNDS (1); ids past the last block draw black (NUM_BLOCKS)."""
    rows, cols = map_.shape
    for i in range(VIEW[0]):
        for j in range(VIEW[1]):
            r, c = row - TOP + i, col - LEFT + j
            ids[i, j] = 1
            if 0 <= r < rows and 0 <= c < cols:
                ids[i, j] = min(np.int64(map_[r, c]), NUM_BLOCKS)


@njit_cached()
def _draw_inventory(words, cells, origin, counts):
    """The panel below the map; words: the frame as (144, 54) uint64, cells: (16, 2, 10,
    16, 6) uint64 (each cell's 16 rows of 48 bytes)."""
    wide_vectors()
    words[MAP_PX[0]:] = 0
    for k in range(counts.shape[0]):
        v = np.int64(counts[k])
        cell = cells[k, np.int64(v > 0), _wrap_clip(v, DIGITS)]
        top, col = np.uint64(MAP_PX[0] + origin[k, 0]), np.uint64(origin[k, 1] // BLOCK)
        copy_tile(words, top, WORDS * col, cell)


@njit_cached(nogil=True)  # nogil: generation re-renders on its encoder thread
def render_batch(out, blocks, player, player_alpha, sprites, sprite_alpha, intensity,
                 half_tint, cells, cell_origin, maps, player_pos, player_dir, sleeping,
                 light, counts, zombies_pos, zombies_status, cows_pos, cows_status,
                 skeletons_pos, skeletons_status, arrows_pos, arrows_status, arrows_dir,
                 state_rng):
    """Render ``out[i]`` (144x144x3 uint8) from env i's exported state and ``state_rng``;
    ``counts`` is player_vitals followed by inventory. The atlas comes from ``textures``."""
    wide_vectors()
    mobs = ((zombies_pos, zombies_status), (cows_pos, cows_status),
            (skeletons_pos, skeletons_status), (arrows_pos, arrows_status))
    ids = np.empty(VIEW, np.int64)
    marked = np.empty(VIEW, np.bool_)
    slots = np.empty(VIEW, np.int64)  # work tile of each view tile a sprite touches, else -1
    tiles = np.empty((VIEW[0] * VIEW[1], 3, TEXELS), np.float32)
    shaded = np.empty((NUM_BLOCKS + 1, BLOCK, 3 * BLOCK), np.uint8)  # by day, per block id
    shaded_words = shaded.view(np.uint64)
    cell_words = cells.view(np.uint64)
    done = np.empty(NUM_BLOCKS + 1, np.bool_)
    noise = np.empty(MAP_PX, np.float32)
    scratch = np.empty((2, 3, TEXELS), np.float32)
    for f in range(out.shape[0]):
        frame = out[f].reshape((out.shape[1], 3 * out.shape[2]))
        words = frame.view(np.uint64)
        row, col = np.int64(player_pos[f, 0]), np.int64(player_pos[f, 1])
        _view(ids, maps[f], row, col)
        marked[:] = False
        marked[TOP, LEFT] = True
        for kind in range(4):
            _mark_mobs(marked, mobs[kind][0][f], mobs[kind][1][f], row, col)
        n = 0
        for i in range(VIEW[0]):
            for j in range(VIEW[1]):
                slots[i, j] = -1
                if marked[i, j]:
                    slots[i, j] = n
                    tiles[n] = blocks[ids[i, j]]
                    n += 1
        face = PLAYER_ASLEEP if sleeping[f] else _wrap_clip(np.int64(player_dir[f]) - 1, 5)
        blend_player(tiles[slots[TOP, LEFT]], player[face], player_alpha[face])
        for kind in range(4):
            _draw_mobs(tiles, slots, sprites, sprite_alpha, row, col, mobs[kind][0][f],
                       mobs[kind][1][f], arrows_dir[f], min(kind, ARROW))
        night = light[f] < HALF
        if night:
            uniform(state_rng[f, 0], state_rng[f, 1], noise.reshape(-1))
        done[:] = False
        for i in range(VIEW[0]):
            for j in range(VIEW[1]):
                top, left, b = np.uint64(i * BLOCK), np.uint64(j * BLOCK), ids[i, j]
                tile = blocks[b] if slots[i, j] < 0 else tiles[slots[i, j]]
                if night:
                    shade(frame, top, left, tile, noise, intensity, light[f], sleeping[f],
                          half_tint, scratch)
                elif slots[i, j] >= 0:
                    shade(frame, top, left, tile, None, None, light[f], sleeping[f],
                          half_tint, scratch)
                else:  # a plain block by day: lit once per frame, then copied
                    if not done[b]:
                        shade(shaded[b], np.uint64(0), np.uint64(0), tile, None, None,
                              light[f], sleeping[f], half_tint, scratch)
                        done[b] = True
                    copy_tile(words, top, WORDS * np.uint64(j), shaded_words[b])
        _draw_inventory(words, cell_words, cell_origin, counts[f])
