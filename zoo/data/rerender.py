"""Craftax-Classic frames re-rendered from stored states: the ``rendered`` frame mode.

A Craftax frame is a pure function of the EnvState fields craftax's pixel renderer reads:
``map``, ``player_position``, ``player_direction``, ``is_sleeping``, the four vitals, the
``inventory``, position and mask of zombies, cows, skeletons and arrows, ``arrow_directions``,
``light_level`` and ``state_rng`` (the night static is ``jax.random.uniform(state_rng)``).
The zoo's exported state holds all of them but ``state_rng``, which a rendered chunk stores
beside it (8 bytes a step). Every other EnvState field is filled with zeros: the renderer
never reads them.

A rendered chunk stores each frame as the residual (frame - re-render) mod 256, coded like
frames. Where the re-render reproduces the frame the residual is zero and costs almost
nothing; where it does not (the env rendered on a GPU, another XLA fusion rounded a pixel the
other way) the residual holds the difference, so decoding is bit-exact whenever the reader's
re-render equals the writer's. Each chunk carries the CRC32 of its frames: a reader whose
re-render differs (another craftax or JAX version, another CPU) fails with an error naming
both renderer versions instead of returning wrong pixels.

Re-renders use the renderer ``zoo.envs.render.choose_renderer`` picks for the CPU: the numba
kernel (default), bit-exact with Craftax's JAX renderer on the CPU backend, so a chunk written
with either decodes with the other; or that JAX renderer, 16 frames per jitted call on the CPU
backend. A chunk whose residual is zero (the usual case) is coded and recognised without
coding or decoding its zeros. JAX is imported inside functions: DataLoader workers are spawned
and pay for it only when they meet a rendered chunk.
"""

from __future__ import annotations

from functools import lru_cache
from importlib import metadata

import numpy as np

from zoo.data.codec import FrameCodec, decode_arrays, decode_frames, encode_arrays, encode_frames
from zoo.envs import render
from zoo.envs.constants import Item
from zoo.envs.render import checksum
from zoo.envs.schema import FRAME_SHAPE, State

RENDER_BATCH = 16
"""Frames per re-render call: a block still in the cache when its residual and CRC32 are
taken; for JAX also one compiled shape for every chunk length (the tail is padded; larger
batches render slower: the intermediates leave the cache)."""


def renderer_version(renderer: str | None = None) -> str:
    """What decides a re-render's pixels, for the manifest and chunk meta: craftax's version
    and the renderer's (``renderer`` None: the one chosen for the CPU)."""
    craftax = f"craftax {metadata.version('craftax')}"
    if render.choose_renderer(renderer) == "numba":
        return f"{craftax}, zoo numba renderer {render.NUMBA_RENDERER_VERSION}"
    return f"{craftax}, jax {metadata.version('jax')}"


_ZERO_CODED: set[bytes] = set()
"""Coded residuals seen to be all zeros: every chunk of one length and codec codes its zeros to
the same ~500 bytes, so after the first such chunk a set lookup replaces decoding them."""
_MAX_ZERO_CODED = 4096


@lru_cache(maxsize=64)
def _coded_zeros(n: int, codec: FrameCodec) -> bytes:
    """The coded residual of n frames the re-render reproduces: what ``encode_frames`` makes
    of n zero frames, computed once per chunk length."""
    return encode_frames(np.zeros((n, *FRAME_SHAPE), np.uint8), codec)


def _decode_residual(residual: bytes, n: int) -> np.ndarray | None:
    """The residual frames, or None where they are all zero (the common case)."""
    if residual in _ZERO_CODED:
        return None
    frames = decode_frames(residual, n)
    if frames.any():
        return frames
    if len(_ZERO_CODED) < _MAX_ZERO_CODED:
        _ZERO_CODED.add(residual)
    return None


def rebuild_env_state(state: dict, state_rng, template):
    """One Craftax EnvState from one step of the exported state (jax arrays) and its
    ``state_rng``; fields the renderer does not read keep ``template``'s zeros."""
    import jax.numpy as jnp

    def cast(value, like):
        return jnp.asarray(value).astype(like.dtype)

    def mobs(name: str, like):
        count = like.mask.shape[0]  # the schema pads Craftax's mob slots to its maxima
        return like.replace(
            position=cast(state[f"{name}_pos"][:count], like.position),
            mask=state[f"{name}_status"][:count, 0] != 0,
        )

    vitals = state["player_vitals"]
    inventory = template.inventory
    items = {}
    for item in Item:  # the exported inventory's slots, named as Craftax's Inventory fields
        name = item.name.lower()
        items[name] = cast(state["inventory"][int(item)], getattr(inventory, name))
    directions = template.arrow_directions
    return template.replace(
        map=cast(state["map"], template.map),
        player_position=cast(state["player_pos"], template.player_position),
        player_direction=cast(state["player_dir"], template.player_direction),
        player_health=cast(vitals[0], template.player_health),
        player_food=cast(vitals[1], template.player_food),
        player_drink=cast(vitals[2], template.player_drink),
        player_energy=cast(vitals[3], template.player_energy),
        is_sleeping=cast(state["player_sleeping"], template.is_sleeping),
        inventory=inventory.replace(**items),
        zombies=mobs("zombies", template.zombies),
        cows=mobs("cows", template.cows),
        skeletons=mobs("skeletons", template.skeletons),
        arrows=mobs("arrows", template.arrows),
        arrow_directions=cast(state["arrows_dir"][: directions.shape[0]], directions),
        light_level=cast(state["light_level"], template.light_level),
        state_rng=cast(state_rng, template.state_rng),
    )


@lru_cache(maxsize=1)
def _batch_renderer():
    """(jitted vmap of rebuild + render, the CPU device); built once per process."""
    import jax
    import jax.numpy as jnp
    from craftax.craftax_classic.envs.craftax_state import EnvParams, StaticEnvParams
    from craftax.craftax_classic.world_gen import generate_world

    # before any JAX backend starts: it keeps a worker that renders on the CPU from
    # preallocating GPU memory
    from zoo.envs.craftax_env import enable_compilation_cache, frame_renderer

    enable_compilation_cache()
    shapes = jax.eval_shape(
        lambda key: generate_world(key, EnvParams(), StaticEnvParams()), jax.random.PRNGKey(0)
    )
    template = jax.tree_util.tree_map(lambda s: jnp.zeros(s.shape, s.dtype), shapes)
    frame = frame_renderer()

    def render_one(state, state_rng):
        return frame(rebuild_env_state(state, state_rng, template))

    return jax.jit(jax.vmap(render_one)), jax.devices("cpu")[0]


def render_frames(
    state: State, state_rng: np.ndarray, renderer: str | None = None,
    out: np.ndarray | None = None,
) -> np.ndarray:
    """Re-render (n, 144, 144, 3) uint8 frames from n steps of exported state and their
    (n, 2) uint32 ``state_rng`` on the CPU (``renderer`` None: ``choose_renderer``'s), into
    ``out`` if given (C-contiguous uint8 of that shape)."""
    if render.choose_renderer(renderer) == "numba":
        return render.render_frames(state, state_rng, out)
    return _render_jax(state, state_rng, out)


def _render_jax(state: State, state_rng: np.ndarray, out: np.ndarray | None) -> np.ndarray:
    """Craftax's JAX renderer, RENDER_BATCH frames per call on the CPU backend."""
    import jax

    render_batch, cpu = _batch_renderer()
    n = len(state_rng)
    if out is None:
        out = np.empty((n, *FRAME_SHAPE), np.uint8)
    inputs = {k: np.asarray(state[k]) for k in render.STATE_INPUTS}
    for start in range(0, n, RENDER_BATCH):
        stop = min(start + RENDER_BATCH, n)
        pad = [(0, RENDER_BATCH - (stop - start))]
        block = [
            {k: np.pad(v[start:stop], pad + [(0, 0)] * (v.ndim - 1)) for k, v in inputs.items()},
            np.pad(state_rng[start:stop], pad + [(0, 0)]),
        ]
        out[start:stop] = jax.device_get(render_batch(*jax.device_put(block, cpu)))[: stop - start]
    return out


def _rerender_blocks(state: State, state_rng: np.ndarray):
    """(block, its re-rendered frames) over a chunk, RENDER_BATCH frames at a time: each
    block is still in the cache when its residual and CRC32 are taken."""
    inputs = {k: state[k] for k in render.STATE_INPUTS}
    for start in range(0, len(state_rng), RENDER_BATCH):
        block = slice(start, start + RENDER_BATCH)
        yield block, render_frames({k: v[block] for k, v in inputs.items()}, state_rng[block])


def encode_rendered(
    frames: np.ndarray | None, state: State, state_rng: np.ndarray, codec: FrameCodec
) -> tuple[bytes, bytes, int]:
    """A chunk's residual frames, its renderer inputs beyond the state and its frames' CRC32.

    ``frames`` None: the env drew no frames (a state-only expert played), so the frames are
    the re-renders themselves and the residual is zero: generation renders each frame once.
    """
    rendered = None if frames is None else np.empty_like(frames)
    same, crc = True, 0
    for block, part in _rerender_blocks(state, state_rng):
        if frames is not None:
            rendered[block] = part
            same = same and np.array_equal(frames[block], part)
            part = frames[block]
        crc = checksum.crc32(part, crc)
    if same:
        coded = _coded_zeros(len(state_rng), codec)
    else:
        coded = encode_frames(frames - rendered, codec)  # uint8 wraps: mod 256
    inputs = encode_arrays({"state_rng": np.asarray(state_rng, np.uint32)}, codec)
    return coded, inputs, crc


def decode_rendered(
    residual: bytes, inputs: bytes, state: State, n: int, crc32: int, renderer: str
) -> np.ndarray:
    """Inverse of ``encode_rendered`` for ``n`` frames; ``renderer`` is the writer's version."""
    state_rng = decode_arrays(inputs, "render inputs").get("state_rng")
    if state_rng is None or state_rng.shape != (n, 2) or state_rng.dtype != np.uint32:
        got = "nothing" if state_rng is None else f"{state_rng.dtype} {state_rng.shape}"
        raise ValueError(f"render inputs: 'state_rng' is {got}, expected uint32 ({n}, 2)")
    nonzero = _decode_residual(residual, n)
    frames = np.empty((n, *FRAME_SHAPE), np.uint8)
    crc = 0
    for block, part in _rerender_blocks(state, state_rng):
        if nonzero is not None:
            part += nonzero[block]
        frames[block] = part
        crc = checksum.crc32(part, crc)
    if crc != crc32:
        raise ValueError(
            f"frames re-rendered here differ from the writer's (CRC32 mismatch; written with "
            f"{renderer}, read with {renderer_version()} on the CPU): decode these shards "
            "where they were written, or regenerate them with --frames stored"
        )
    return frames
