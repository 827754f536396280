"""Rendered chunks decode to the same bytes whichever renderer wrote them and whichever reads.

Default suite: chunks of played Craftax states (frames drawn by Craftax's JAX renderer, as
the env drew them before the numba renderer) are coded with one renderer's re-renders and
decoded with the other's; a pixel agent's tiny dataset decodes to the same frames written
in either mode. Slow suite: whole datasets, one written as this project wrote
rendered shards before the numba renderer (``ZOO_RENDERER=jax``: the env draws its frames
inside its jitted step, residuals are taken against JAX re-renders), one written with numba
throughout, each decoded with both renderers: every decode passes the chunk's CRC32 of the
writer's frames and all four give the same frames. There the agent asks for pixels, so the
env's own frames, not re-renders, are what the residuals code.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from zoo.agents.base import RandomAgent
from zoo.data import rerender
from zoo.data.codec import FrameCodec, decode_frames
from zoo.data.generate import GenerationConfig, ShardGenerator, generate
from zoo.data.manifest import load_manifest
from zoo.data.reader import iter_chunks, list_shards

RENDERERS = ("jax", "numba")
CONFIG = GenerationConfig(
    expert="random", episodes=2, seed=5, env="craftax", episodes_per_shard=2,
    chunk_length=16, max_steps=40, frames="rendered",
)


@pytest.fixture(scope="module")
def chunk(craftax_env):
    """(frames by Craftax's JAX renderer, exported state, state_rng) of 24 played steps."""
    import jax

    from zoo.envs.craftax_env import export_state, frame_renderer

    frame = frame_renderer()  # textures load here, not inside the trace
    render = jax.jit(jax.vmap(lambda s: (frame(s), export_state(s))))
    step = craftax_env.reset(np.array([3, 4]))
    states = []
    for action in np.random.default_rng(0).integers(0, 17, 12):
        step = craftax_env.step(np.array([action, 5]))
        states.append(jax.device_get(step.raw))
    states = jax.tree_util.tree_map(lambda *xs: np.concatenate(xs), *states)
    frames, exported = jax.device_get(render(states))
    return frames, exported, states.state_rng


@pytest.mark.parametrize("writer", RENDERERS)
def test_a_chunk_coded_with_one_renderer_decodes_with_the_other(chunk, writer, monkeypatch):
    frames, state, state_rng = chunk
    monkeypatch.setenv("ZOO_RENDERER", writer)
    residual, inputs, crc32 = rerender.encode_rendered(frames, state, state_rng, FrameCodec())
    assert not decode_frames(residual, len(frames)).any()  # the re-render is the frame
    for reader in RENDERERS:
        monkeypatch.setenv("ZOO_RENDERER", reader)
        back = rerender.decode_rendered(residual, inputs, state, len(frames), crc32, writer)
        np.testing.assert_array_equal(back, frames)


class PixelRandomAgent(RandomAgent):
    needs_pixels = True  # the env draws frames, as for a C-VPT learner


def build_agent(config: GenerationConfig, num_envs: int) -> PixelRandomAgent:
    return PixelRandomAgent(num_envs)


@pytest.mark.slow
def test_datasets_written_by_either_renderer_decode_alike(tmp_path, monkeypatch):
    roots = {}
    for renderer in RENDERERS:
        monkeypatch.setenv("ZOO_RENDERER", renderer)
        roots[renderer] = tmp_path / renderer
        generator = ShardGenerator(CONFIG, 2, build_agent)
        assert generator.env.renderer == renderer
        generate(CONFIG, roots[renderer], progress=False, generator=generator)
        shards = load_manifest(roots[renderer])["shards"]
        assert {e["renderer"] for e in shards} == {rerender.renderer_version(renderer)}
    decoded = {}
    for writer in RENDERERS:
        for reader in RENDERERS:
            monkeypatch.setenv("ZOO_RENDERER", reader)
            chunks = iter_chunks(list_shards(roots[writer]))
            decoded[writer, reader] = np.concatenate([c["frames"] for c in chunks])
    first = decoded["jax", "jax"]  # the path every earlier rendered dataset was written by
    assert len(first) == sum(e["steps"] for e in load_manifest(roots["jax"])["shards"])
    for key, frames in decoded.items():
        np.testing.assert_array_equal(frames, first, err_msg=str(key))


def test_a_pixel_agents_rendered_set_decodes_to_its_stored_set(tmp_path, monkeypatch):
    # the frames the env drew go through the recorders' pooled buffers in both modes
    monkeypatch.setenv("ZOO_RENDERER", "numba")
    decoded = {}
    for mode in ("stored", "rendered"):
        config = dataclasses.replace(CONFIG, frames=mode)
        generate(config, tmp_path / mode, progress=False,
                 generator=ShardGenerator(config, 2, build_agent))
        decoded[mode] = np.concatenate(
            [c["frames"] for c in iter_chunks(list_shards(tmp_path / mode))])
    assert len(decoded["stored"]) > CONFIG.chunk_length * 2  # several chunks per episode
    np.testing.assert_array_equal(decoded["rendered"], decoded["stored"])
