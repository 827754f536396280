"""Craftax's night static, ``jax.random.uniform(state_rng, (112, 144))``, without JAX.

JAX draws uniform floats from threefry-2x32 bits. With ``jax_threefry_partitionable`` (the
default since JAX 0.5) element i of the shape hashes the 64-bit counter (0, i) under the key
and keeps the xor of both output words; the float is the top 23 bits as a mantissa in [1, 2)
minus 1. Reproduced here bit for bit (``tests/zoo/envs/test_render.py`` checks it against
JAX), several times faster per frame than a jitted JAX batch on the CPU
(``bench/bench_render.py`` times both; docs/results/benchmarks.md).
"""

from __future__ import annotations

import numba
import numpy as np

from zoo.envs.render.cache import njit_cached
from zoo.envs.render.llvm import wide_vectors

_PARITY = np.uint32(0x1BD11BDA)  # threefry's key-schedule constant
_ONE_BITS = np.uint32(0x3F800000)  # float32 1.0: the exponent the mantissa bits go under


@numba.njit(inline="always")
def _rotl(x, r):
    return np.uint32(np.uint32(x << r) | np.uint32(x >> (32 - r)))


@numba.njit(inline="always")
def _four_rounds(x0, x1, r0, r1, r2, r3):
    x0 = np.uint32(x0 + x1)
    x1 = _rotl(x1, r0) ^ x0
    x0 = np.uint32(x0 + x1)
    x1 = _rotl(x1, r1) ^ x0
    x0 = np.uint32(x0 + x1)
    x1 = _rotl(x1, r2) ^ x0
    x0 = np.uint32(x0 + x1)
    x1 = _rotl(x1, r3) ^ x0
    return x0, x1


@njit_cached()
def uniform(k0: np.uint32, k1: np.uint32, out: np.ndarray) -> None:
    """Fill the flat float32 ``out`` (< 2**32 values) with JAX's uniform [0, 1) draws for the
    threefry key (k0, k1), in JAX's order."""
    wide_vectors()
    k2 = np.uint32(k0 ^ k1 ^ _PARITY)
    for i in range(out.size):
        x0 = k0  # the counter's high word is 0
        x1 = np.uint32(np.uint32(i) + k1)
        x0, x1 = _four_rounds(x0, x1, 13, 15, 26, 6)
        x0 = np.uint32(x0 + k1)
        x1 = np.uint32(x1 + k2 + np.uint32(1))
        x0, x1 = _four_rounds(x0, x1, 17, 29, 16, 24)
        x0 = np.uint32(x0 + k2)
        x1 = np.uint32(x1 + k0 + np.uint32(2))
        x0, x1 = _four_rounds(x0, x1, 13, 15, 26, 6)
        x0 = np.uint32(x0 + k0)
        x1 = np.uint32(x1 + k1 + np.uint32(3))
        x0, x1 = _four_rounds(x0, x1, 17, 29, 16, 24)
        x0 = np.uint32(x0 + k1)
        x1 = np.uint32(x1 + k2 + np.uint32(4))
        x0, x1 = _four_rounds(x0, x1, 13, 15, 26, 6)
        x0 = np.uint32(x0 + k2)
        x1 = np.uint32(x1 + k0 + np.uint32(5))
        bits = np.uint32(np.uint32(np.uint32(x0 ^ x1) >> 9) | _ONE_BITS)
        # bits - 1.0 is exact and never below 0 (JAX's max(0, .) is a no-op here)
        out[i] = np.float32(bits.view(np.float32) - np.float32(1.0))
