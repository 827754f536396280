"""The vector envs: declared autoreset modes and what each returns when an episode ends, seeding
by one run seed, masked resets' info as Gymnasium's, ``make_vec``, and the crafter
``AsyncVectorEnv`` agreeing with the native one."""

from __future__ import annotations

from collections.abc import Callable
from functools import partial

import gymnasium
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode, SyncVectorEnv

import zoo.gym
from zoo.envs.base import episode_seed
from zoo.gym.batch import GameBatch
from zoo.gym.env import CrafterDojoEnv
from zoo.gym.vector import CraftaxVectorEnv, CrafterVectorEnv

SEED, LIMIT = 5, 3
NOOPS = np.zeros(2, np.int32)


@pytest.fixture(scope="module")
def craftax_vector():
    """2 Craftax envs, pixels, 3-step episodes: the session fixture's compiled programs."""
    return CraftaxVectorEnv(2, max_steps=LIMIT)


def first_frames(craftax_env, episodes: list[int]) -> np.ndarray:
    """Episodes' first frames from the raw zoo env (``zoo eval``'s seeding)."""
    return craftax_env.reset(np.array([episode_seed(SEED, j) for j in episodes])).frames


def play_to_limit(env, mode: AutoresetMode):
    env.metadata["autoreset_mode"] = mode
    obs, info = env.reset(seed=SEED)
    for _ in range(LIMIT - 1):
        env.step(NOOPS)
    return obs, info, env.step(NOOPS)


def test_next_step_autoreset(craftax_vector, craftax_env):
    obs, _, (_, _, terminated, truncated, info) = play_to_limit(
        craftax_vector, AutoresetMode.NEXT_STEP
    )
    assert truncated.all() and not terminated.any() and info["episode_index"].tolist() == [0, 1]
    assert np.array_equal(obs, first_frames(craftax_env, [0, 1]))
    obs, reward, terminated, truncated, info = craftax_vector.step(NOOPS)
    assert info["episode_index"].tolist() == [2, 3] and (reward == 0).all()
    assert not (terminated | truncated).any()
    assert np.array_equal(obs, first_frames(craftax_env, [2, 3]))
    assert not info["achievements"].any()


def paying_every_step(batch: GameBatch) -> Callable:
    """``batch.step`` of a game paying reward 1 on every step, its step limit also terminating:
    what a NEXT_STEP reset step must not pass on from the ended episode."""
    step = batch.step

    def paying(actions: np.ndarray) -> tuple:
        obs, reward, terminated, truncated, info = step(actions)
        return obs, np.ones_like(reward), terminated | truncated, truncated, info

    return paying


def test_next_step_autoreset_zeroes_the_reward(craftax_vector, craftax_env, monkeypatch):
    """Gymnasium's NEXT_STEP: "the sub-environment is reset on the step after its episode ends"
    (https://gymnasium.farama.org/main/api/vector/autoreset/), a step SyncVectorEnv returns with
    reward 0 and terminated = truncated = False. Were the game to pay on that step, the reward
    would be credited to the new episode's first observation."""
    monkeypatch.setattr(craftax_vector.batch, "step", paying_every_step(craftax_vector.batch))
    _, _, (_, reward, terminated, truncated, _) = play_to_limit(
        craftax_vector, AutoresetMode.NEXT_STEP
    )
    assert (reward == 1).all() and terminated.all() and truncated.all()
    obs, reward, terminated, truncated, _ = craftax_vector.step(NOOPS)
    assert reward.tolist() == [0.0, 0.0]
    assert not terminated.any() and not truncated.any()
    assert np.array_equal(obs, first_frames(craftax_env, [2, 3]))


def test_same_step_autoreset(craftax_vector, craftax_env):
    _, _, (obs, _, _, truncated, info) = play_to_limit(craftax_vector, AutoresetMode.SAME_STEP)
    assert truncated.all() and info["_final_obs"].all() and info["_final_info"].all()
    assert info["episode_index"].tolist() == [2, 3]
    assert info["final_info"]["episode_index"].tolist() == [0, 1]
    assert np.array_equal(obs, first_frames(craftax_env, [2, 3]))
    assert not np.array_equal(info["final_obs"][0], obs[0])


def test_disabled_autoreset_needs_a_masked_reset(craftax_vector, craftax_env):
    _, _, (obs, *_) = play_to_limit(craftax_vector, AutoresetMode.DISABLED)
    with pytest.raises(ValueError, match="reset them"):
        craftax_vector.step(NOOPS)
    kept = obs[1].copy()
    obs, info = craftax_vector.reset(options={"reset_mask": np.array([True, False])})
    assert info["episode_index"][0] == 2
    assert np.array_equal(obs[0], first_frames(craftax_env, [2, 3])[0])
    assert np.array_equal(obs[1], kept)
    with pytest.raises(ValueError, match=r"envs \[1\] ended"):
        craftax_vector.step(NOOPS)


def test_unseeded_reset_gives_each_slot_its_own_episode(craftax_env):
    """An unseeded first reset draws one run seed and starts the slots at its distinct episodes 0
    and 1: slots replaying one episode would collect one env's experience N times. Each slot's
    frame is its own seed's (two worlds' first views can be alike, so frames are not compared
    with each other)."""
    obs, info = CraftaxVectorEnv(2, max_steps=LIMIT).reset()
    assert info["episode_index"].tolist() == [0, 1]
    assert info["episode_seed"][0] != info["episode_seed"][1]
    assert np.array_equal(obs, craftax_env.reset(info["episode_seed"]).frames)


def test_seeded_reset_starts_slot_i_at_zoo_eval_episode_i():
    """``reset(seed=s)`` of a new env seeds slot i as ``zoo eval --seed s`` seeds its episode i
    (``episode_seed(s, i)``, zoo.eval.rollout), and a later unseeded reset goes on with the run's
    episodes 2 and 3 instead of drawing a new run."""
    env = CraftaxVectorEnv(2, max_steps=LIMIT)
    _, info = env.reset(seed=SEED)
    assert info["episode_seed"].tolist() == [episode_seed(SEED, i) for i in (0, 1)]
    _, info = env.reset()
    assert info["episode_seed"].tolist() == [episode_seed(SEED, j) for j in (2, 3)]


def assert_same_info(info: dict, expected: dict) -> None:
    """The same keys, each array equal in dtype and values (a mask is a value too)."""
    assert sorted(info) == sorted(expected)
    for key, value in expected.items():
        assert info[key].dtype == value.dtype and np.array_equal(info[key], value), key


def test_masked_reset_info_marks_only_the_reset_envs(craftax_vector):
    """A masked reset's info is Gymnasium's (``VectorEnv._add_info``): ``_key`` True only for the
    envs reset and zeros in the other rows, the dict SyncVectorEnv gives over single envs playing
    the same run, so no one takes a running env's info for a new episode's. A full reset marks
    all."""
    make = [partial(CrafterDojoEnv, "crafter", max_steps=LIMIT, episode_offset=i,
                    episode_stride=2) for i in range(2)]
    reference = SyncVectorEnv(make)
    try:
        _, info = craftax_vector.reset(seed=SEED)
        assert info["_episode_index"].all()
        assert_same_info(info, reference.reset(seed=[SEED, SEED])[1])
        mask = np.array([False, True])
        _, info = craftax_vector.reset(options={"reset_mask": mask})
        assert info["_episode_index"].tolist() == [False, True]
        assert_same_info(info, reference.reset(options={"reset_mask": mask})[1])
    finally:
        reference.close()


def test_a_seed_list_is_refused(craftax_vector):
    with pytest.raises(TypeError, match="one int"):
        craftax_vector.reset(seed=[1, 2])


def test_make_vec_gives_the_native_env_with_its_mode():
    env = gymnasium.make_vec(zoo.gym.env_id("craftax", "T2"), num_envs=2,
                             autoreset_mode="SameStep")
    assert isinstance(env.unwrapped, CraftaxVectorEnv)
    assert env.metadata["autoreset_mode"] == AutoresetMode.SAME_STEP
    assert env.unwrapped.batch.task.name == "T2"
    assert env.observation_space.shape == (2, 144, 144, 3)


def test_crafter_async_env_seeds_slots_like_the_native_one(craftax_vector, crafter_env):
    """``CrafterVectorEnv`` (worker processes) unseeded gives each slot its own episode; seeded s,
    slot i plays episodes i, i + 2, ..., the NEXT_STEP autoreset returns the next one, and info
    (of a masked reset too) is the native env's."""
    craftax_vector.metadata["autoreset_mode"] = AutoresetMode.NEXT_STEP
    _, native_info = craftax_vector.reset(seed=SEED)
    mask = np.array([False, True])
    _, native_masked = craftax_vector.reset(options={"reset_mask": mask})
    env = CrafterVectorEnv(2, max_steps=LIMIT, context="spawn")
    try:
        assert env.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP
        unseeded, info = env.reset()
        assert info["episode_seed"][0] != info["episode_seed"][1]
        assert np.array_equal(unseeded, crafter_env.reset(info["episode_seed"]).frames)
        obs, info = env.reset(seed=SEED)
        assert sorted(info) == sorted(native_info)
        assert info["episode_seed"].tolist() == [episode_seed(SEED, j) for j in (0, 1)]
        for _ in range(LIMIT):
            _, _, _, truncated, info = env.step(NOOPS)
        assert truncated.all()
        _, reward, _, _, info = env.step(NOOPS)
        assert info["episode_index"].tolist() == [2, 3] and (reward == 0).all()
        again, _ = env.reset(seed=SEED)
        assert np.array_equal(again, obs)
        assert_same_info(env.reset(options={"reset_mask": mask})[1], native_masked)
    finally:
        env.close()
