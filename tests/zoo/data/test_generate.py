"""Generation: bit-exact replay, determinism, resume after a kill, refusal to mix datasets,
worker processes that fail.

Runs with worker processes use crafter (made reproducible from the seed in zoo.envs) and the
random expert: a spawned worker then imports neither JAX nor Craftax and starts in about a
second, where a Craftax worker would spend ~20 s compiling.
"""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

from zoo.agents import dataset_agent
from zoo.data.generate import GenerationConfig, ShardGenerator, generate
from zoo.data.manifest import DatasetMismatchError, load_manifest
from zoo.data.pool import WorkerError
from zoo.data.reader import iter_chunks, iter_episodes, list_shards
from zoo.data.shard_generator import _env_draws_frames
from zoo.envs.base import episode_seed
from zoo.envs.schema import STATE_FIELDS

CRAFTER = GenerationConfig(
    expert="random", episodes=3, seed=7, env="crafter", episodes_per_shard=2,
    chunk_length=16, max_steps=40,
)
CRAFTAX = dataclasses.replace(CRAFTER, env="craftax", seed=3, chunk_length=8, max_steps=20)
# three shards, so two workers each take a second one once their first is done
THREE_SHARDS = dataclasses.replace(CRAFTER, episodes=5)


def _shas(root) -> list[str]:
    return [e["sha256"] for e in load_manifest(root)["shards"]]


def _finished_episodes(root) -> list[int]:
    return [c["meta"]["episode"] for c in iter_chunks(list_shards(root)) if c["meta"]["last"]]


def _entries(root) -> list[dict]:
    """Manifest entries in shard order (workers finish shards in any order)."""
    return sorted(load_manifest(root)["shards"], key=lambda e: e["index"])


def _assert_same_dataset(root: Path, reference: Path) -> None:
    """Same files (no leftovers), same shard bytes, same manifest entries."""
    names = sorted(p.name for p in reference.iterdir())
    assert sorted(p.name for p in root.iterdir()) == names
    for name in names:
        if name.endswith(".tar"):
            assert (root / name).read_bytes() == (reference / name).read_bytes(), name
    assert _entries(root) == _entries(reference)


def _assert_kept_shards_are_intact(root: Path, reference: Path, failed: int) -> None:
    """After a failed run: at least one finished shard is in the manifest, none is the failed
    one, and each is byte-identical to the uninterrupted run's."""
    kept = _entries(root)
    assert kept and failed not in [e["index"] for e in kept]
    for entry in kept:
        name = entry["file"]
        assert (root / name).read_bytes() == (reference / name).read_bytes(), name


@contextmanager
def _deadline(seconds: int) -> Iterator[None]:
    """Turn a hang of the main thread into a TimeoutError (SIGALRM)."""

    def expire(signum, frame):
        raise TimeoutError(f"still running after {seconds} s: the run hangs")

    previous = signal.signal(signal.SIGALRM, expire)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


def _poll(found: Callable[[], list], seconds: float, running: Callable[[], bool]) -> list:
    """Poll ``found`` every 2 ms until it returns something, ``running`` turns False or time
    is up (both fail the test)."""
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline and running():
        if hits := found():
            return hits
        time.sleep(0.002)
    pytest.fail("the run ended, or never got there, before the moment to kill it")


@pytest.fixture(scope="module")
def crafter_dataset(tmp_path_factory):
    root = tmp_path_factory.mktemp("crafterplay")
    generate(CRAFTER, root, num_envs=2, progress=False, build_agent=dataset_agent)
    return root


@pytest.fixture(scope="module")
def craftax_generator():
    return ShardGenerator(CRAFTAX, 2, dataset_agent)


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
    """Replaying the stored actions from the stored seed gives the stored frames and states.
    The random expert reads no pixels, so its env drew none: the stored frames were drawn
    from the states on the encoder thread, and must equal those of an env that draws them."""
    from zoo.envs import make_env

    assert not craftax_generator.pixels
    env = make_env("craftax", 2, pixels=True, max_steps=CRAFTAX.max_steps)
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


def test_stored_shards_are_the_same_bytes_whoever_draws_the_frames(
    craftax_dataset, craftax_generator, tmp_path, monkeypatch
):
    """With the numba renderer the encoder draws a state-only expert's frames from the
    states; with JAX's the env draws them inside its jitted step (cheaper there). Same bytes."""
    monkeypatch.setenv("ZOO_RENDERER", "jax")
    generator = ShardGenerator(CRAFTAX, 2, dataset_agent)
    assert generator.pixels and generator.env.renderer == "jax"
    assert not craftax_generator.pixels
    generate(CRAFTAX, tmp_path, progress=False, generator=generator)
    assert _shas(tmp_path) == _shas(craftax_dataset)


@pytest.mark.parametrize(
    ("env", "frames", "renderer", "needs_pixels", "drawn"),
    [
        ("craftax", "stored", "numba", False, False),  # drawn on the encoder, from the states
        ("craftax", "stored", "jax", False, True),  # inside the env's jitted step
        ("craftax", "rendered", "jax", False, False),  # the re-render that codes a chunk
        ("craftax", "stored", "numba", True, True),  # the agent looks at them
        ("crafter", "stored", "numba", False, True),  # not a function of the exported state
    ],
)
def test_who_draws_the_frames(env, frames, renderer, needs_pixels, drawn, monkeypatch):
    monkeypatch.setenv("ZOO_RENDERER", renderer)
    config = dataclasses.replace(CRAFTER, env=env, frames=frames)
    agent = type("Agent", (), {"needs_pixels": needs_pixels})()
    assert _env_draws_frames(config, agent) is drawn


def test_same_seed_same_bytes_for_any_num_envs(craftax_dataset, tmp_path):
    generate(CRAFTAX, tmp_path, num_envs=1, progress=False, build_agent=dataset_agent)
    assert _shas(tmp_path) == _shas(craftax_dataset)


@pytest.mark.slow
def test_same_bytes_with_worker_processes(craftax_dataset, tmp_path):
    generate(CRAFTAX, tmp_path, workers=2, num_envs=2, progress=False, build_agent=dataset_agent)
    assert _shas(tmp_path) == _shas(craftax_dataset)


@pytest.fixture(scope="module")
def three_shards_dataset(tmp_path_factory):
    """The uninterrupted single-process run the worker tests compare against."""
    root = tmp_path_factory.mktemp("crafterplay_three")
    generate(THREE_SHARDS, root, num_envs=2, progress=False, build_agent=dataset_agent)
    return root


def test_same_bytes_with_worker_processes_on_crafter(three_shards_dataset, tmp_path):
    generate(THREE_SHARDS, tmp_path, workers=2, num_envs=1, progress=False, build_agent=dataset_agent)
    _assert_same_dataset(tmp_path, three_shards_dataset)
    assert _finished_episodes(tmp_path) == [0, 1, 2, 3, 4]


def test_resume_after_the_command_is_killed_mid_shard(crafter_dataset, tmp_path):
    """SIGKILL to a `zoo data generate --workers 2` run (parent and workers) while a worker
    has part of a shard on disk; rerunning the same command gives the uninterrupted bytes."""
    root = tmp_path / "killed"
    command = [
        sys.executable, "-m", "zoo.cli", "data", "generate", "--expert", CRAFTER.expert,
        "--env", CRAFTER.env, "--episodes", str(CRAFTER.episodes), "--seed", str(CRAFTER.seed),
        "--episodes-per-shard", str(CRAFTER.episodes_per_shard),
        "--chunk-length", str(CRAFTER.chunk_length), "--max-steps", str(CRAFTER.max_steps),
        "--workers", "2", "--num-envs", "1", "--no-progress", "--out", str(root),
    ]
    run = subprocess.Popen(command, start_new_session=True, stdout=subprocess.DEVNULL)
    try:
        # a compressed chunk or finished episode in a work folder, or a shard being assembled
        _poll(lambda: [*root.glob(".work-*/*"), *root.glob("*.tar.tmp-*")], 60,
              lambda: run.poll() is None)
    finally:
        os.killpg(run.pid, signal.SIGKILL)  # no process of the group runs user code after this
        run.wait()
    assert [*root.glob(".work-*"), *root.glob("*.tar.tmp-*")]
    rerun = subprocess.run(command, capture_output=True, text=True, timeout=120)
    assert rerun.returncode == 0, rerun.stderr
    _assert_same_dataset(root, crafter_dataset)


def test_a_worker_that_raises_fails_the_run_naming_its_shard(three_shards_dataset, tmp_path):
    (tmp_path / "crafterplay-000002.tar").mkdir()  # shard 2's final rename fails in its worker
    with _deadline(60), pytest.raises(WorkerError, match="shard 2: worker process") as failed:
        generate(THREE_SHARDS, tmp_path, workers=2, num_envs=1, progress=False, build_agent=dataset_agent)
    assert "IsADirectoryError" in str(failed.value)  # the worker's traceback
    _assert_kept_shards_are_intact(tmp_path, three_shards_dataset, failed=2)
    (tmp_path / "crafterplay-000002.tar").rmdir()
    generate(THREE_SHARDS, tmp_path, workers=2, num_envs=1, progress=False, build_agent=dataset_agent)
    _assert_same_dataset(tmp_path, three_shards_dataset)


def test_a_killed_worker_fails_the_run_and_a_rerun_finishes_it(three_shards_dataset, tmp_path):
    """A worker SIGKILLed mid-shard (as by the OOM killer) must end the run, not hang it."""
    killed: list[int] = []

    def kill_shard_2_worker() -> None:
        work = _poll(lambda: list(tmp_path.glob(".work-000002-*")), 60, lambda: True)
        killed.append(int(work[0].name.rsplit("-", 1)[1]))
        os.kill(killed[0], signal.SIGKILL)

    killer = threading.Thread(target=kill_shard_2_worker, daemon=True)
    killer.start()
    with _deadline(60), pytest.raises(WorkerError) as failed:
        generate(THREE_SHARDS, tmp_path, workers=2, num_envs=1, progress=False, build_agent=dataset_agent)
    killer.join()
    assert f"shard 2: worker process {killed[0]} died (exit code -9)" in str(failed.value)
    _assert_kept_shards_are_intact(tmp_path, three_shards_dataset, failed=2)
    generate(THREE_SHARDS, tmp_path, workers=2, num_envs=1, progress=False, build_agent=dataset_agent)
    _assert_same_dataset(tmp_path, three_shards_dataset)


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


def test_a_rerun_removes_the_leftovers_of_a_killed_run(crafter_dataset, tmp_path):
    """The run dies after its first shard, leaving a half-written shard and an episode work
    folder; the rerun finishes the other shard and leaves exactly the uninterrupted files."""

    def crash(entry):
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        generate(CRAFTER, tmp_path, num_envs=2, progress=False, after_shard=crash,
                 build_agent=dataset_agent)
    assert [e["index"] for e in load_manifest(tmp_path)["shards"]] == [0]
    (tmp_path / "crafterplay-000001.tar.tmp-999").write_bytes(b"partial")
    (tmp_path / ".work-000001-999").mkdir()
    (tmp_path / ".work-000001-999" / "episode-000002.part").write_bytes(b"partial")
    generate(CRAFTER, tmp_path, num_envs=2, progress=False, build_agent=dataset_agent)
    _assert_same_dataset(tmp_path, crafter_dataset)


def test_damaged_shard_is_regenerated(crafter_dataset, tmp_path):
    root = tmp_path / "copy"
    shutil.copytree(crafter_dataset, root)
    first = root / "crafterplay-000000.tar"
    first.write_bytes(first.read_bytes()[:5000])
    unchanged = _shas(root)[1]
    generate(CRAFTER, root, num_envs=2, progress=False, build_agent=dataset_agent)
    assert _finished_episodes(root) == [0, 1, 2]
    assert _shas(root)[1] == unchanged


def test_other_arguments_into_same_folder_are_refused(crafter_dataset, tmp_path):
    root = tmp_path / "copy"
    shutil.copytree(crafter_dataset, root)
    with pytest.raises(DatasetMismatchError, match="seed: 7 there vs 8 now"):
        generate(dataclasses.replace(CRAFTER, seed=8), root, progress=False, build_agent=dataset_agent)
    assert json.loads((root / "manifest.json").read_text())["config"]["seed"] == 7


def test_expert_options_are_part_of_equality_not_of_the_hash():
    scripted = dataclasses.replace(CRAFTER, expert="scripted")
    options = dataclasses.replace(scripted, expert_options={"plants_first": True})
    assert options != scripted and hash(options) == hash(scripted)
    assert dataclasses.replace(scripted, expert_options={}) == scripted  # {} means the defaults
    with pytest.raises(ValueError, match="scripted expert only"):
        dataclasses.replace(CRAFTER, expert_options={"plants_first": True})
