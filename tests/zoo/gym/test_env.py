"""The single env: registered ids, Gymnasium's ``check_env``, observation spaces, end signals.

``check_env`` on crafter ids is fast; every id (Craftax-Classic's compile its single-env
programs, about a minute on a fresh cache) is the slow test.
"""

from __future__ import annotations

import warnings

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import zoo.gym
from zoo.envs.tasks import TASKS
from zoo.gym.batch import downsample, symbolic_dim
from zoo.gym.env import CrafterDojoEnv
from zoo.gym.vector import CraftaxVectorEnv


def test_every_game_and_task_is_registered():
    assert len(zoo.gym.ENV_IDS) == 2 * (1 + len(TASKS)) == 22
    assert {"CrafterDojo/Craftax-v0", "CrafterDojo/Crafter-v0",
            "CrafterDojo/Craftax-T4-v0", "CrafterDojo/Crafter-collect_sapling-v0"} <= set(
        zoo.gym.ENV_IDS)
    for env_id in zoo.gym.ENV_IDS:
        spec = gymnasium.spec(env_id)
        assert spec.vector_entry_point == "zoo.gym.vector:make_vector_env"
        assert env_id == zoo.gym.env_id(spec.kwargs["game"], spec.kwargs["task"])


def checked(env_id: str) -> None:
    """``check_env`` on the unwrapped env, with any warning it raises turned into a failure."""
    env = gymnasium.make(env_id, render_mode="rgb_array")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(env.unwrapped)
    env.close()


@pytest.mark.parametrize("env_id", ["CrafterDojo/Crafter-v0", "CrafterDojo/Crafter-T1-v0",
                                    "CrafterDojo/Crafter-make_stone_sword-v0"])
def test_check_env_passes(env_id):
    checked(env_id)


@pytest.mark.slow
@pytest.mark.parametrize("env_id", zoo.gym.ENV_IDS)
def test_check_env_passes_on_every_id(env_id):
    checked(env_id)


def test_72_px_frames_are_2x2_means_of_the_rendered_frame():
    env = gymnasium.make("CrafterDojo/Crafter-v0", size=72, render_mode="rgb_array")
    obs, _ = env.reset(seed=3)
    assert env.observation_space.shape == obs.shape == (72, 72, 3)
    full = env.render().astype(np.int32)
    blocks = full.reshape(72, 2, 72, 2, 3).sum(axis=(1, 3))
    np.testing.assert_array_equal(obs, (blocks + 2) // 4)
    assert np.array_equal(downsample(env.render()[None])[0], obs)


def test_time_limit_truncates_and_death_terminates():
    env = CrafterDojoEnv("crafter", max_steps=4)
    env.reset(seed=0)
    ends = [env.step(0)[2:4] for _ in range(4)]
    assert ends == [(False, False)] * 3 + [(False, True)]
    env.reset()
    env.batch.env.raw_state[0]._player.health = 0
    assert env.step(0)[2:4] == (True, False)


def test_symbolic_observation_is_refused_for_crafter():
    with pytest.raises(ValueError, match="Craftax-Classic's"):
        CrafterDojoEnv("crafter", symbolic=True)
    with pytest.raises(ValueError, match="size must be one of"):
        CrafterDojoEnv("crafter", size=100)


@pytest.mark.slow
def test_craftax_pixels_and_symbolic_make_a_dict():
    env = CraftaxVectorEnv(2, size=72, symbolic=True)
    obs, _ = env.reset(seed=0)
    assert set(obs) == {"pixels", "symbolic"} and obs["symbolic"].shape == (2, symbolic_dim())
    assert obs in env.observation_space
    single = CrafterDojoEnv("craftax", size=None, symbolic=True)
    assert single.observation_space.shape == (1345,)
    np.testing.assert_array_equal(single.reset(seed=0)[0], obs["symbolic"][0])
