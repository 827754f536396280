"""Craftax-Classic frames on the CPU, and the one setting that picks who renders them.

Craftax's JAX renderer adds 17 full-frame block textures one after another and scans mobs
sequentially, which is slow on a CPU. ``render_frames`` draws the same frames, bit for bit,
from the zoo's exported state plus ``state_rng`` with a numba kernel (a texture gather, a
few sprites, one shading pass, a precomputed inventory panel), much faster
(docs/results/benchmarks.md).

The renderer is chosen once for everything that makes a Craftax frame (the env's pixels,
generation, decoding ``--frames rendered`` shards): a function's ``renderer`` argument, else
the ``ZOO_RENDERER`` environment variable ("numba" or "jax"), else numba, or jax where JAX
itself runs on a GPU (there the frame comes out of the env's jitted step for free).
"""

from __future__ import annotations

import os

import numpy as np

from zoo.envs.schema import FRAME_SHAPE, STATE_FIELDS, State

RENDERERS = ("numba", "jax")
RENDERER_ENV = "ZOO_RENDERER"
NUMBA_RENDERER_VERSION = 1
"""Bumped whenever the kernel's pixels could change (recorded in rendered shards). numba's
compiled cache needs no bump: its entries are keyed on all the kernel's sources (``cache``)."""
STATE_INPUTS = (
    "map", "player_pos", "player_dir", "player_vitals", "player_sleeping", "inventory",
    "light_level", "arrows_dir",
    *(f"{mob}_{part}" for mob in ("zombies", "cows", "skeletons", "arrows")
      for part in ("pos", "status")),
)
"""Exported state fields a frame depends on (with ``state_rng``)."""


def choose_renderer(renderer: str | None = None, on_gpu: bool = False) -> str:
    """The renderer to use: ``renderer`` if given, else $ZOO_RENDERER, else "numba" ("jax"
    when ``on_gpu``: JAX renders on a GPU)."""
    name = renderer or os.environ.get(RENDERER_ENV) or ("jax" if on_gpu else "numba")
    if name not in RENDERERS:
        source = "renderer" if renderer else RENDERER_ENV
        raise ValueError(f"{source} must be one of {RENDERERS}, got {name!r}")
    return name


def render_frames(
    state: State, state_rng: np.ndarray, out: np.ndarray | None = None
) -> np.ndarray:
    """(n, 144, 144, 3) uint8 frames of n exported states (``zoo.envs.schema``, batched) and
    their (n, 2) uint32 ``state_rng``, as Craftax-Classic's renderer draws them; into ``out``
    if given (a C-contiguous uint8 array of that shape, e.g. a recycled buffer)."""
    from zoo.envs.render.kernel import render_batch
    from zoo.envs.render.textures import load_atlas

    s = {k: np.ascontiguousarray(state[k], STATE_FIELDS[k].dtype) for k in STATE_INPUTS}
    state_rng = np.ascontiguousarray(state_rng, np.uint32)
    n = len(state_rng)
    if state_rng.shape != (n, 2):
        raise ValueError(f"state_rng must be (n, 2) uint32, got shape {state_rng.shape}")
    for k, v in s.items():  # the kernel does not check bounds: shapes must be the schema's
        if v.shape != (n, *STATE_FIELDS[k].shape):
            raise ValueError(f"state field {k!r} has shape {v.shape}, expected "
                             f"{(n, *STATE_FIELDS[k].shape)} for {n} frames")
    counts = np.concatenate([s["player_vitals"].astype(np.int16), s["inventory"]], axis=1)
    if out is None:
        out = np.empty((n, *FRAME_SHAPE), np.uint8)
    elif out.dtype != np.uint8 or out.shape != (n, *FRAME_SHAPE) or not out.flags.c_contiguous:
        raise ValueError(f"out must be C-contiguous uint8 {(n, *FRAME_SHAPE)}, got "
                         f"{out.dtype} {out.shape}")
    render_batch(
        out, *load_atlas(), s["map"], s["player_pos"], s["player_dir"], s["player_sleeping"],
        s["light_level"], counts, s["zombies_pos"], s["zombies_status"], s["cows_pos"],
        s["cows_status"], s["skeletons_pos"], s["skeletons_status"], s["arrows_pos"],
        s["arrows_status"], s["arrows_dir"], state_rng,
    )
    return out
