"""Craftax-Classic's 16-px textures as the flat numpy arrays the CPU renderer gathers from.

Every texel and alpha comes from craftax's own texture cache (``load_all_textures``), the
arrays its JAX renderer reads, so both renderers start from the same float32 values. Only the
centre tile of the full-map player textures is kept (their alpha is 0 elsewhere). Tiles are
stored planar, (3, 256) per tile, so the kernel's loops over texels vectorise. The inventory
panel, whose arithmetic is all small integers, is precomputed as one uint8 cell (16 rows of
48 interleaved bytes) per (cell, icon shown, digit).
"""

from __future__ import annotations

from functools import lru_cache
from typing import NamedTuple

import numpy as np

from zoo.envs.constants import VIEW, Block, Item

BLOCK = 16
MAP_PX = (VIEW[0] * BLOCK, VIEW[1] * BLOCK)
NUM_BLOCKS = len(Block)  # ids at or past this draw nothing (JAX adds no texture for them)
DIGITS = 10
ICON = slice(1, 13)  # where a 12-px inventory icon sits in its 16-px cell
DIGIT = slice(6, 15)  # where a 9-px count digit sits

# Inventory cells in the order of the state's counts: player_vitals (4) then inventory (12);
# (texture key or smaller block, column, row) as craftax's renderer places them.
_VITAL_CELLS = (("health_texture", 0, 0), ("hunger_texture", 1, 0),
                ("thirst_texture", 2, 0), ("energy_texture", 3, 0))
_ITEM_CELLS = {
    Item.WOOD: (Block.WOOD, 5, 0), Item.STONE: (Block.STONE, 6, 0),
    Item.COAL: (Block.COAL, 7, 0), Item.IRON: (Block.IRON, 8, 0),
    Item.DIAMOND: (Block.DIAMOND, 0, 1), Item.SAPLING: ("sapling_texture", 4, 0),
    Item.WOOD_PICKAXE: ("wood_pickaxe_texture", 1, 1),
    Item.STONE_PICKAXE: ("stone_pickaxe_texture", 2, 1),
    Item.IRON_PICKAXE: ("iron_pickaxe_texture", 3, 1),
    Item.WOOD_SWORD: ("wood_sword_texture", 4, 1),
    Item.STONE_SWORD: ("stone_sword_texture", 5, 1),
    Item.IRON_SWORD: ("iron_sword_texture", 6, 1),
}


class Atlas(NamedTuple):
    """The renderer's inputs that do not depend on the state (float32 unless noted)."""

    blocks: np.ndarray  # (NUM_BLOCKS + 1, 3, 256); the last is black, for unknown ids
    player: np.ndarray  # (5, 3, 256): left, right, up, down, asleep
    player_alpha: np.ndarray  # (5, 3, 256)
    sprites: np.ndarray  # (7, 3, 256): zombie, cow, skeleton, arrow in 4 orientations
    sprite_alpha: np.ndarray  # (7, 3, 256)
    static_intensity: np.ndarray  # (112, 144): the night static's weight, grows off-centre
    half_tint: np.ndarray  # (3,): half the night tint colour
    cells: np.ndarray  # (16, 2, 10, 16, 48) uint8: inventory cell, icon shown, digit
    cell_origin: np.ndarray  # (16, 2) int64: each cell's top-left pixel in the panel


def _arrows(texture: np.ndarray, alpha: np.ndarray) -> tuple[list, list]:
    """The arrow sprite by heading, indexed flip + 2 * transpose as craftax selects them:
    flipped (rows) when it moves down or right, transposed when it moves sideways."""
    textures, alphas = [], []
    for transpose in (False, True):
        for flip in (False, True):
            t, a = (x[::-1] if flip else x for x in (texture, alpha))
            t, a = (x.transpose(1, 0, 2) if transpose else x for x in (t, a))
            textures.append(t)
            alphas.append(a)
    return textures, alphas


def _cells(tex: dict) -> tuple[np.ndarray, np.ndarray]:
    """Every inventory cell as craftax draws it: the icon (or nothing at 0), then the digit
    drawn over it with its 0/1 alpha. Integer arithmetic, so exact in any order."""
    specs = list(_VITAL_CELLS) + [_ITEM_CELLS[item] for item in Item]
    digits = np.asarray(tex["number_textures"], np.int64)
    digit_alpha = np.asarray(tex["number_textures_alpha"], np.int64)
    cells = np.zeros((len(specs), 2, DIGITS, BLOCK, BLOCK, 3), np.int64)
    origin = np.zeros((len(specs), 2), np.int64)
    for k, (icon, col, row) in enumerate(specs):
        origin[k] = row * BLOCK, col * BLOCK
        icon = tex["smaller_block_textures"][icon] if isinstance(icon, Block) else tex[icon]
        cells[k, 1, :, ICON, ICON] = np.asarray(icon, np.int64)
        cells[k, :, :, DIGIT, DIGIT] = cells[k, :, :, DIGIT, DIGIT] * (1 - digit_alpha) + digits
    if cells.min() < 0 or cells.max() > 255:
        raise ValueError("craftax's inventory textures left the uint8 range")
    return cells.astype(np.uint8).reshape(*cells.shape[:3], BLOCK, 3 * BLOCK), origin


def _planar(tiles) -> np.ndarray:
    """(n, 16, 16, 3) tiles as contiguous float32 (n, 3, 256)."""
    tiles = np.asarray(tiles, np.float32)
    return np.ascontiguousarray(tiles.reshape(len(tiles), BLOCK * BLOCK, 3).transpose(0, 2, 1))


@lru_cache(maxsize=1)
def load_atlas() -> Atlas:
    """Read craftax's texture cache once per process (craftax builds it on first use, slowly)."""
    from craftax.craftax_classic.constants import load_all_textures

    tex = {k: v if isinstance(v, list) else np.asarray(v) for k, v in
           load_all_textures()[BLOCK].items()}
    centre = (slice(3 * BLOCK, 4 * BLOCK), slice(4 * BLOCK, 5 * BLOCK))
    blocks = np.zeros((NUM_BLOCKS + 1, BLOCK, BLOCK, 3), np.float32)
    blocks[:NUM_BLOCKS] = tex["block_textures"]
    arrows, arrow_alphas = _arrows(tex["arrow_texture"], tex["arrow_texture_alpha"])
    sprites = [tex[f"{m}_texture"] for m in ("zombie", "cow", "skeleton")] + arrows
    alphas = [tex[f"{m}_texture_alpha"] for m in ("zombie", "cow", "skeleton")] + arrow_alphas
    intensity = tex["night_noise_intensity_texture"]
    if not (intensity == intensity[..., :1]).all():
        raise ValueError("craftax's night static intensity differs between colour channels")
    cells, origin = _cells(tex)
    return Atlas(
        blocks=_planar(blocks),
        player=_planar(tex["full_map_player_textures"][:, centre[0], centre[1]]),
        player_alpha=_planar(tex["full_map_player_textures_alpha"][:, centre[0], centre[1]]),
        sprites=_planar(sprites),
        sprite_alpha=_planar(alphas),
        static_intensity=np.ascontiguousarray(intensity[..., 0], np.float32),
        half_tint=np.float32(0.5) * np.asarray(tex["night_texture"][0, 0], np.float32),
        cells=cells,
        cell_origin=origin,
    )
