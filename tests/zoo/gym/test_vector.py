"""The vector envs: declared autoreset modes and what each returns when an episode ends, seeding
by one run seed, ``make_vec``, and the crafter ``AsyncVectorEnv`` agreeing with the native one."""

from __future__ import annotations

import gymnasium
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import zoo.gym
from zoo.envs.base import episode_seed
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
    assert info["episode_index"].tolist() == [2, 1]
    assert np.array_equal(obs[0], first_frames(craftax_env, [2, 3])[0])
    assert np.array_equal(obs[1], kept)
    with pytest.raises(ValueError, match=r"envs \[1\] ended"):
        craftax_vector.step(NOOPS)


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


def test_crafter_async_env_seeds_slots_like_the_native_one(craftax_vector):
    """``CrafterVectorEnv`` (worker processes) seeded s: slot i plays episodes i, i + 2, ...,
    the NEXT_STEP autoreset returns the next one, and info has the native env's keys."""
    craftax_vector.metadata["autoreset_mode"] = AutoresetMode.NEXT_STEP
    _, native_info = craftax_vector.reset(seed=SEED)
    env = CrafterVectorEnv(2, max_steps=LIMIT, context="spawn")
    try:
        assert env.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP
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
    finally:
        env.close()
