"""Generation: bit-exact replay, determinism, resume after a kill, refusal to mix datasets.

Byte-level determinism is checked on Craftax: original crafter picks which mob to despawn
from a set ordered by memory address, so its episodes are not reproducible from the seed.
"""

from __future__ import annotations

import dataclasses
import json
import shutil

import numpy as np
import pytest

from zoo.data.generate import GenerationConfig, ShardGenerator, episode_seed, generate
from zoo.data.manifest import DatasetMismatchError, load_manifest
from zoo.data.reader import iter_chunks, iter_episodes, list_shards
from zoo.envs.schema import STATE_FIELDS

CRAFTER = GenerationConfig(
    expert="random", episodes=3, seed=7, env="crafter", episodes_per_shard=2,
    chunk_length=16, max_steps=40,
)
CRAFTAX = dataclasses.replace(CRAFTER, env="craftax", seed=3, chunk_length=8, max_steps=20)


def _shas(root) -> list[str]:
    return [e["sha256"] for e in load_manifest(root)["shards"]]


def _finished_episodes(root) -> list[int]:
    return [c["meta"]["episode"] for c in iter_chunks(list_shards(root)) if c["meta"]["last"]]


@pytest.fixture(scope="module")
def crafter_dataset(tmp_path_factory):
    root = tmp_path_factory.mktemp("crafterplay")
    generate(CRAFTER, root, num_envs=2, progress=False)
    return root


@pytest.fixture(scope="module")
def craftax_generator():
    return ShardGenerator(CRAFTAX, num_envs=2)


@pytest.fixture(scope="module")
def craftax_dataset(tmp_path_factory, craftax_generator):
    root = tmp_path_factory.mktemp("crafterplay_craftax")
    generate(CRAFTAX, root, progress=False, generator=craftax_generator)
    return root


def test_layout_and_manifest(crafter_dataset):
    manifest = load_manifest(crafter_dataset)
    files = [e["file"] for e in manifest["shards"]]
    assert files == ["crafterplay-000000.tar", "crafterplay-000001.tar"]
    assert [e["episodes"] for e in manifest["shards"]] == [2, 1]
    entry = manifest["shards"][0]
    assert entry["episode_seeds"] == [episode_seed(7, 0), episode_seed(7, 1)]
    assert entry["steps"] == sum(entry["episode_lengths"])
    assert set(entry["versions"]) >= {"crafter-zoo", "crafter", "craftax", "jax", "numpy"}
    assert 0 <= entry["noop"]["ratio_after"] <= entry["noop"]["ratio_before"] <= 1
    assert manifest["config"] == dataclasses.asdict(CRAFTER)
    assert not list(crafter_dataset.glob(".work-*")) and not list(crafter_dataset.glob("*.tmp-*"))


def test_episodes_whole_and_in_order(crafter_dataset):
    episodes = list(iter_episodes(list_shards(crafter_dataset)))
    assert [e["meta"]["episode"] for e in episodes] == [0, 1, 2]
    for ep in episodes:
        n = ep["meta"]["episode_length"]
        assert len(ep["actions"]) == n <= CRAFTER.max_steps + 1
        assert ep["actions"][-1] == -1 and (ep["actions"][:-1] >= 0).all()
        assert ep["frames"].shape == (n, 144, 144, 3) and ep["frames"].dtype == np.uint8
        assert ep["state"]["timestep"].tolist() == list(range(n))
        assert ep["meta"]["seed"] == episode_seed(7, ep["meta"]["episode"])


def test_round_trip_is_bit_exact_against_a_replay(craftax_dataset, craftax_generator):
    """Replaying the stored actions from the stored seed gives the stored frames and states."""
    env = craftax_generator.env
    for episode in iter_episodes(list_shards(craftax_dataset)):
        step = env.reset(np.array([episode["meta"]["seed"], 0]))
        for t, action in enumerate(episode["actions"]):
            np.testing.assert_array_equal(step.frames[0], episode["frames"][t])
            for name in STATE_FIELDS:
                np.testing.assert_array_equal(step.state[name][0], episode["state"][name][t], name)
            if action < 0:
                break
            step = env.step(np.array([action, 0]))
            assert step.reward[0] == episode["rewards"][t]
        assert step.done[0] and episode["meta"]["episode_length"] == t + 1


def test_same_seed_same_bytes_for_any_num_envs(craftax_dataset, tmp_path):
    generate(CRAFTAX, tmp_path, num_envs=1, progress=False)
    assert _shas(tmp_path) == _shas(craftax_dataset)


@pytest.mark.slow
def test_same_bytes_with_worker_processes(craftax_dataset, tmp_path):
    generate(CRAFTAX, tmp_path, workers=2, num_envs=2, progress=False)
    assert _shas(tmp_path) == _shas(craftax_dataset)


def test_worker_processes_write_every_episode_once(tmp_path):
    generate(CRAFTER, tmp_path, workers=2, num_envs=1, progress=False)
    assert _finished_episodes(tmp_path) == [0, 1, 2]


def test_resume_after_kill_gives_the_same_dataset(craftax_dataset, craftax_generator, tmp_path):
    def crash(entry):
        raise KeyboardInterrupt  # the run dies right after its first shard

    with pytest.raises(KeyboardInterrupt):
        generate(CRAFTAX, tmp_path, progress=False, after_shard=crash, generator=craftax_generator)
    assert len(load_manifest(tmp_path)["shards"]) == 1
    # leftovers of the killed run: a half-written shard and an episode work folder
    (tmp_path / "crafterplay-000001.tar.tmp-999").write_bytes(b"partial")
    (tmp_path / ".work-000001-999").mkdir()
    generate(CRAFTAX, tmp_path, progress=False, generator=craftax_generator)
    assert _shas(tmp_path) == _shas(craftax_dataset)
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "crafterplay-000000.tar", "crafterplay-000001.tar", "manifest.json"
    ]
    assert _finished_episodes(tmp_path) == [0, 1, 2]


def test_damaged_shard_is_regenerated(crafter_dataset, tmp_path):
    root = tmp_path / "copy"
    shutil.copytree(crafter_dataset, root)
    first = root / "crafterplay-000000.tar"
    first.write_bytes(first.read_bytes()[:5000])
    unchanged = _shas(root)[1]
    generate(CRAFTER, root, num_envs=2, progress=False)
    assert _finished_episodes(root) == [0, 1, 2]
    assert _shas(root)[1] == unchanged


def test_other_arguments_into_same_folder_are_refused(crafter_dataset, tmp_path):
    root = tmp_path / "copy"
    shutil.copytree(crafter_dataset, root)
    with pytest.raises(DatasetMismatchError, match="seed: 7 there vs 8 now"):
        generate(dataclasses.replace(CRAFTER, seed=8), root, progress=False)
    assert json.loads((root / "manifest.json").read_text())["config"]["seed"] == 7
