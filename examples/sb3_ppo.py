"""stable-baselines3's PPO on a CrafterDojo task through the Gymnasium adapter, then scored.

Trains on ``--env-id`` (a registered ``CrafterDojo/...`` task) from Craftax-Classic's symbolic
observation (an MLP learns from it in minutes on a CPU; pixels need a CNN and hours), optionally
with ``CClipReward`` shaping (the env then also renders 144-px frames for C-CLIP, and the policy
still sees only the symbolic vector). Then plays the trained policy and uniform random actions
on the same held-out episodes (run seed ``--eval-seed``) without shaping, and writes the success
rates with Wilson 95% intervals to ``OUT/result.json`` (training episodes: SB3 monitor CSVs there).

    pip install -e .[rl]
    python examples/sb3_ppo.py --env-id CrafterDojo/Craftax-make_stone_pickaxe-v0 --steps 30000
    python examples/sb3_ppo.py --env-id CrafterDojo/Craftax-make_stone_pickaxe-v0 --steps 30000 \
        --cclip "craft stone pickaxe"   # docs/gym.md has the results
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import gymnasium
import numpy as np
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.env_util import make_vec_env

import zoo.gym  # noqa: F401  (registers the CrafterDojo ids)
from zoo.eval.task_eval import wilson_interval
from zoo.gym.wrappers import CClipReward


def make_env(env_id: str, instruction: str | None) -> gymnasium.Env:
    """The task env observing the symbolic vector, shaped by C-CLIP if ``instruction``."""
    if instruction is None:
        return gymnasium.make(env_id, size=None, symbolic=True)
    env = CClipReward(gymnasium.make(env_id, size=144, symbolic=True), instruction)
    space = env.observation_space["symbolic"]
    return gymnasium.wrappers.TransformObservation(env, lambda obs: obs["symbolic"], space)


def success_rate(env: gymnasium.Env, act, episodes: int, seed: int) -> dict:
    """Play ``act(obs) -> action`` for episodes 0..episodes-1 of run ``seed``."""
    wins = 0
    for j in range(episodes):
        obs, _ = env.reset(seed=seed, options={"episode": j})
        done = False
        while not done:
            obs, _, terminated, truncated, info = env.step(act(obs))
            done = terminated or truncated
        wins += bool(info["success"])
    low, high = wilson_interval(wins, episodes)
    return {"successes": wins, "episodes": episodes, "success_percent": 100 * wins / episodes,
            "wilson95_percent": [100 * low, 100 * high]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--env-id", default="CrafterDojo/Craftax-make_stone_pickaxe-v0")
    parser.add_argument("--steps", type=int, default=30_000, help="env steps of training")
    parser.add_argument("--cclip", metavar="INSTRUCTION", help="add CClipReward for this text")
    parser.add_argument("--num-envs", type=int, default=8)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--eval-episodes", type=int, default=100)
    parser.add_argument("--eval-seed", type=int, default=10_000, help="held-out run seed")
    parser.add_argument("--out", type=Path, default=Path("runs/sb3"))
    args = parser.parse_args()
    torch.set_num_threads(1)

    args.out.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    envs = make_vec_env(make_env, args.num_envs, args.seed, monitor_dir=str(args.out),
                        env_kwargs={"env_id": args.env_id, "instruction": args.cclip},
                        monitor_kwargs={"info_keywords": ("success",)})
    model = PPO("MlpPolicy", envs, n_steps=256, batch_size=256, learning_rate=3e-4,
                ent_coef=0.01, seed=args.seed, device="cpu", verbose=0)
    model.learn(args.steps)
    train_s = time.perf_counter() - started

    rng = np.random.default_rng(args.eval_seed)
    held_out = make_env(args.env_id, None)
    result = {
        "env_id": args.env_id, "cclip_instruction": args.cclip,
        "env_steps": model.num_timesteps,  # --steps rounded up to whole rollouts
        "num_envs": args.num_envs, "seed": args.seed, "train_minutes": train_s / 60,
        "train_env_steps_per_s": model.num_timesteps / train_s,
        "ppo": success_rate(held_out, lambda o: int(model.predict(o)[0]),
                            args.eval_episodes, args.eval_seed),
        "random": success_rate(held_out, lambda o: int(rng.integers(17)),
                               args.eval_episodes, args.eval_seed),
    }
    (args.out / "result.json").write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
