"""The ``rendered`` frame mode: residuals against re-renders from the stored state.

Round trips are bit-exact on day, night and sleeping frames and on a deliberately perturbed
re-render; a rendered dataset reads back (reader, datamodule path, `zoo data info`) as the
stored one of the same seed; a reader whose re-render differs from the writer's fails loudly.
One rendered generator is built per module: its env also supplies the Craftax states.
"""

from __future__ import annotations

import dataclasses
import tarfile

import numpy as np
import pytest

from zoo.agents import dataset_agent
from zoo.cli import main
from zoo.data import rerender
from zoo.data.codec import FrameCodec, decode_frames
from zoo.data.generate import GenerationConfig, ShardGenerator, generate
from zoo.data.info import RAW_FRAME_BYTES, dataset_info
from zoo.data.manifest import load_manifest
from zoo.data.reader import decode_sample, iter_episodes, list_shards
from zoo.data.sequences import ShardSources, read_shards
from zoo.envs.schema import STATE_FIELDS

STORED = GenerationConfig(
    expert="random", episodes=3, seed=11, env="craftax", episodes_per_shard=2,
    chunk_length=8, max_steps=20,
)
RENDERED = dataclasses.replace(STORED, frames="rendered")


@pytest.fixture(scope="module")
def generator():
    return ShardGenerator(RENDERED, 2, dataset_agent)


@pytest.fixture(scope="module")
def rendered_data(tmp_path_factory, generator):
    root = tmp_path_factory.mktemp("rendered")
    generate(RENDERED, root, progress=False, generator=generator)
    return root


@pytest.fixture(scope="module")
def stored_data(tmp_path_factory):
    root = tmp_path_factory.mktemp("stored")
    generate(STORED, root, num_envs=2, progress=False, build_agent=dataset_agent)
    return root


@pytest.fixture(scope="module")
def variants(generator):
    """(frames, exported state, state_rng) of 8 Craftax states as the env renders them:
    2 played states, each by day, at night with its own key, at night with another key,
    and asleep at dusk (built from real EnvStates; the renderer reads nothing else).
    Rendered on the CPU, as re-renders are, so a zero residual is expected on any machine."""
    import jax
    import jax.numpy as jnp

    from zoo.envs.craftax_env import export_state, frame_renderer

    env = generator.env
    step = env.reset(np.array([5, 6]))
    for action in (1, 3, 5, 5):
        step = env.step(np.array([action, action]))
    cpu = jax.devices("cpu")[0]
    raw = jax.device_put(step.raw, cpu)

    def vary(light: float, sleeping: bool = False, rng_offset: int = 0):
        return raw.replace(
            light_level=jnp.full_like(raw.light_level, light),
            is_sleeping=jnp.full_like(raw.is_sleeping, sleeping),
            state_rng=raw.state_rng + jnp.uint32(rng_offset),
        )

    parts = [vary(1.0), vary(0.05), vary(0.05, rng_offset=7), vary(0.3, sleeping=True)]
    states = jax.tree_util.tree_map(lambda *xs: jnp.concatenate(xs), *parts)
    render = frame_renderer()  # textures load here, not inside the trace
    with jax.default_device(cpu):
        frames, exported = jax.jit(jax.vmap(lambda s: (render(s), export_state(s))))(states)
    return np.asarray(frames), jax.device_get(exported), np.asarray(states.state_rng)


def test_round_trip_day_night_sleeping(variants):
    frames, state, state_rng = variants
    day, night, night_other_key, asleep = np.split(frames, 4)
    assert not np.array_equal(day, night) and not np.array_equal(day, asleep)
    assert not np.array_equal(night, night_other_key)  # the static comes from state_rng
    residual, inputs, crc32 = rerender.encode_rendered(frames, state, state_rng, FrameCodec())
    assert not decode_frames(residual, len(frames)).any()  # the re-render is the env's frame
    back = rerender.decode_rendered(residual, inputs, state, len(frames), crc32, "writer")
    np.testing.assert_array_equal(back, frames)


def _perturbed(render):
    """A re-render that differs from the env's frame in ~1/3 of its bytes (same every call)."""

    def render_frames(state, state_rng):
        frames = render(state, state_rng)
        noise = np.random.default_rng(0).integers(0, 3, frames.shape, dtype=np.uint8)
        return frames + noise

    return render_frames


def test_residual_restores_a_perturbed_rerender(variants, monkeypatch):
    frames, state, state_rng = variants
    monkeypatch.setattr(rerender, "render_frames", _perturbed(rerender.render_frames))
    residual, inputs, crc32 = rerender.encode_rendered(frames, state, state_rng, FrameCodec())
    assert decode_frames(residual, len(frames)).any()
    back = rerender.decode_rendered(residual, inputs, state, len(frames), crc32, "writer")
    np.testing.assert_array_equal(back, frames)


def test_a_reader_whose_rerender_differs_fails(variants, monkeypatch):
    frames, state, state_rng = variants
    residual, inputs, crc32 = rerender.encode_rendered(frames, state, state_rng, FrameCodec())
    monkeypatch.setattr(rerender, "render_frames", _perturbed(rerender.render_frames))
    with pytest.raises(ValueError, match=r"differ from the writer's .*written with craftax 0\.0"):
        rerender.decode_rendered(residual, inputs, state, len(frames), crc32, "craftax 0.0")


def test_rendered_dataset_reads_as_the_stored_one(rendered_data, stored_data):
    rendered = list(iter_episodes(list_shards(rendered_data)))
    stored = list(iter_episodes(list_shards(stored_data)))
    assert [e["meta"]["episode"] for e in rendered] == [0, 1, 2]
    assert len(rendered) == len(stored)
    for ours, theirs in zip(rendered, stored):
        np.testing.assert_array_equal(ours["frames"], theirs["frames"])
        for key in ("actions", "rewards", "noop", "noop_run"):
            np.testing.assert_array_equal(ours[key], theirs[key], key)
        for name in STATE_FIELDS:
            np.testing.assert_array_equal(ours["state"][name], theirs["state"][name], name)
        assert ours["meta"]["renderer"] == rerender.renderer_version()
        assert "renderer" not in theirs["meta"]
    # the datamodules' path (zoo.data.sequences.read_shards) reads it too
    chunks = read_shards(ShardSources(rendered_data), skip_corrupt=False)
    np.testing.assert_array_equal(next(chunks)["frames"], stored[0]["frames"][:8])


def test_manifest_and_info_record_the_mode(rendered_data, stored_data, capsys):
    manifest = load_manifest(rendered_data)
    assert manifest["config"]["frames"] == "rendered"
    assert {e["renderer"] for e in manifest["shards"]} == {rerender.renderer_version()}
    assert load_manifest(stored_data)["config"]["frames"] == "stored"
    assert all("renderer" not in e for e in load_manifest(stored_data)["shards"])
    info, stored = dataset_info(rendered_data), dataset_info(stored_data)
    assert (info["frames_mode"], stored["frames_mode"]) == ("rendered", "stored")
    assert info["frames"] == stored["frames"]
    # residuals of zeros plus 8 B of state_rng a step; 8-step chunks pay the zstd/npy headers
    assert info["frame_bytes_per_frame"] < RAW_FRAME_BYTES / 100 < stored["frame_bytes_per_frame"]
    assert main(["data", "info", str(rendered_data)]) == 0
    assert f"(rendered; re-rendered with {rerender.renderer_version()})" in capsys.readouterr().out


def test_a_rendered_sample_without_its_render_inputs(rendered_data):
    url = list_shards(rendered_data)[0]
    with tarfile.open(url) as tar:
        members = [m for m in tar.getmembers() if m.name.startswith("e0000000_000000.")]
        sample = {m.name.split(".", 1)[1]: tar.extractfile(m).read() for m in members}
    assert sorted(sample) == ["meta.json", "render.zst", "residual.zst", "state.zst", "steps.zst"]
    assert decode_sample(sample)["frames"].shape == (8, 144, 144, 3)
    del sample["render.zst"]
    with pytest.raises(ValueError, match=r"missing fields \['render.zst'\]"):
        decode_sample({**sample, "__url__": url, "__key__": "e0000000_000000"})


def test_config_frames_field():
    assert GenerationConfig(**{**dataclasses.asdict(STORED), "frames": "stored"}) == STORED
    with pytest.raises(ValueError, match="frames='rendered' needs env='craftax'.*'crafter'"):
        dataclasses.replace(RENDERED, env="crafter")
    with pytest.raises(ValueError, match="frames must be 'stored' or 'rendered', got 'png'"):
        dataclasses.replace(STORED, frames="png")


def test_cli_rendered_needs_craftax(tmp_path, capsys):
    args = ["data", "generate", "--expert", "random", "--episodes", "1", "--seed", "0",
            "--env", "crafter", "--frames", "rendered", "--out", str(tmp_path / "x")]
    with pytest.raises(SystemExit) as exit_info:
        main(args)
    assert exit_info.value.code == 2
    assert "--frames rendered needs --env craftax" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()
