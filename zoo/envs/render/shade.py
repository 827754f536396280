"""Per-tile float32 arithmetic of Craftax's renderer, rounded exactly as XLA's CPU code rounds.

Craftax's JAX renderer blends sprites over blocks, lays the night static over the map,
enhances and tints it, blends it with the map by daylight, greys it during sleep, and rounds
half to even into uint8. XLA's CPU backend lets LLVM contract a multiply feeding an add into
one fused multiply-add (one rounding instead of two), and which product it fuses differs from
formula to formula. Each formula here uses ``fma`` exactly where the machine code XLA
compiles for ``craftax_classic.renderer`` does (read from its disassembly, jax 0.10.2) and
separately rounded float32 operations elsewhere (``llvm``).

Tiles are planar, (3, 256) float32. Each step is its own branch-free loop over texels, and
indices are unsigned (numba wraps negative signed indices, a check that stops vectorising),
so every loop compiles to SIMD code, 512 bits wide where the CPU has AVX-512.
"""

from __future__ import annotations

import numba
import numpy as np

from zoo.envs.render.cache import njit_cached
from zoo.envs.render.llvm import fma, wide_vectors
from zoo.envs.render.textures import BLOCK

ONE = np.float32(1.0)
HALF = np.float32(0.5)
TWO = np.float32(2.0)
ZERO = np.float32(0.0)
LUM_R, LUM_G, LUM_B = np.float32(0.299), np.float32(0.587), np.float32(0.114)
KEEP = np.float32(0.4)  # the night's enhance factor: colour kept beside (1 - KEEP) x luminance
GREY = np.float32(0.6)  # 1 - KEEP, as Python computes it before JAX casts it
STATIC_SCALE, STATIC_BASE = np.float32(95.0), np.float32(32.0)
SLEEP_BLUE = np.float32(8.0)  # the sleep tint's blue: half of 16
U3 = np.uint64(3)
U_BLOCK = np.uint64(BLOCK)
U_TEXELS = np.uint64(BLOCK * BLOCK)


@numba.njit(inline="always")
def _lum(r, g, b):
    return fma(b, LUM_B, fma(r, LUM_R, g * LUM_G))


@numba.njit(inline="always")
def _to_uint8(x):
    """Round half to even, clip to 0..255 (after rounding, in integers: cheaper, same)."""
    return np.uint8(min(max(np.int32(np.rint(x)), 0), 255))


@njit_cached()
def blend_player(tile, texture, alpha):
    """map x (1 - a) + texture x a, the first product fused (XLA's choice here)."""
    wide_vectors()
    for ch in range(U3):
        for k in range(U_TEXELS):
            a = alpha[ch, k]
            tile[ch, k] = fma(tile[ch, k], ONE - a, texture[ch, k] * a)


@njit_cached()
def blend_sprite(tile, texture, alpha):
    """(1 - a) x map + texture x a, the second product fused (XLA's choice here)."""
    wide_vectors()
    for ch in range(U3):
        for k in range(U_TEXELS):
            a = alpha[ch, k]
            tile[ch, k] = fma(a, texture[ch, k], (ONE - a) * tile[ch, k])


@numba.njit(inline="always")
def _light(out, k, m0, m1, m2, n0, n1, n2, light, dark, half_tint):
    """Texel k: enhance and tint ``n`` (the map, with static at night), blend with the map
    ``m`` by daylight."""
    grey = _lum(n0, n1, n2) * GREY
    out[0, k] = fma(light, m0, dark * (fma(n0, KEEP, grey) * HALF + half_tint[0]))
    out[1, k] = fma(light, m1, dark * (fma(n1, KEEP, grey) * HALF + half_tint[1]))
    out[2, k] = fma(light, m2, dark * (fma(n2, KEEP, grey) * HALF + half_tint[2]))


@numba.njit(inline="always")
def _light_day(out, tile, light, half_tint):
    wide_vectors()
    dark = ONE - light
    for k in range(U_TEXELS):
        m0, m1, m2 = tile[0, k], tile[1, k], tile[2, k]
        _light(out, k, m0, m1, m2, m0, m1, m2, light, dark, half_tint)


@numba.njit(inline="always")
def _light_night(out, tile, noise, intensity, top, left, light, half_tint):
    """Night: first the static over the map, heavier off-centre (Craftax's night_with_static);
    (top, left): the tile's pixel in the frame's noise and intensity."""
    wide_vectors()
    static = max((HALF - light) * TWO, ZERO)
    dark = ONE - light
    for y in range(U_BLOCK):
        for x in range(U_BLOCK):
            k = y * U_BLOCK + x
            w = static * intensity[top + y, left + x]
            s = fma(noise[top + y, left + x], STATIC_SCALE, STATIC_BASE)
            keep = ONE - w
            m0, m1, m2 = tile[0, k], tile[1, k], tile[2, k]
            n0, n1, n2 = fma(w, s, keep * m0), fma(w, s, keep * m1), fma(w, s, keep * m2)
            _light(out, k, m0, m1, m2, n0, n1, n2, light, dark, half_tint)


@numba.njit(inline="always")
def _sleep_grey(out):
    wide_vectors()
    for k in range(U_TEXELS):
        grey = _lum(out[0, k], out[1, k], out[2, k]) * HALF
        out[0, k] = grey
        out[1, k] = grey
        out[2, k] = grey + SLEEP_BLUE


@numba.njit(inline="always")
def _store(dst, top, left, out, texels):
    """Round the planar tile ``out`` into rows of interleaved bytes,
    ``dst[top:top + 16, 3 * left:3 * (left + 16)]``, through ``texels`` (768 floats)."""
    wide_vectors()
    for k in range(U_TEXELS):
        for ch in range(U3):
            texels[U3 * k + ch] = out[ch, k]
    row = U3 * U_BLOCK
    for y in range(U_BLOCK):
        for i in range(row):
            dst[top + y, U3 * left + i] = _to_uint8(texels[y * row + i])


@numba.njit(inline="always")
def shade(dst, top, left, tile, noise, intensity, light, asleep, half_tint, scratch):
    """Light the planar ``tile`` into ``dst`` (rows of bytes) at pixel (top, left), uint64:
    at night (``noise`` not None: the frame's (112, 144) draws) the static, then enhance,
    tint, the daylight blend and the sleep grey. ``scratch``: (2, 3, 256) float32 work space."""
    wide_vectors()
    if noise is None:
        _light_day(scratch[0], tile, light, half_tint)
    else:
        _light_night(scratch[0], tile, noise, intensity, top, left, light, half_tint)
    if asleep:
        _sleep_grey(scratch[0])
    _store(dst, top, left, scratch[0], scratch[1].reshape(-1))


@numba.njit(inline="always")
def copy_tile(dst, top, left, src):
    """A tile's 16 rows of 48 bytes, ``src`` as (16, 6) uint64 words, into the words
    ``dst[top:top + 16, left:left + 6]`` (uint64 offsets; word copies vectorise best)."""
    wide_vectors()
    for y in range(U_BLOCK):
        for i in range(np.uint64(src.shape[1])):
            dst[top + y, left + i] = src[y, i]
