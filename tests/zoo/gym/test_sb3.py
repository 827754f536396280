"""stable-baselines3 (the ``rl`` extra, installed by scripts/setup.sh) runs on the adapter: its own
env checker passes and PPO trains a few hundred steps. Imported plainly: a missing SB3 fails
here instead of skipping unseen."""

from __future__ import annotations

import gymnasium
from stable_baselines3 import PPO
from stable_baselines3.common.env_checker import check_env

import zoo.gym  # noqa: F401  (registers the ids)


def test_sb3_checks_and_trains_ppo_on_a_task():
    env = gymnasium.make("CrafterDojo/Crafter-collect_sapling-v0", size=72)
    check_env(env, warn=False)
    model = PPO("CnnPolicy", env, n_steps=128, batch_size=64, n_epochs=1, seed=0, device="cpu")
    model.learn(256)
    assert model.num_timesteps == 256
    action, _ = model.predict(env.reset(seed=0)[0])
    assert env.action_space.contains(int(action))
