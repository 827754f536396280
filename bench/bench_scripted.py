"""Speed of the scripted expert alone (env-steps planned per second) beside the env's own step.

Plays the expert in a state-only env for a number of steps (finished episodes restart with
fresh seeds) and times ``expert.act`` and ``env.step`` separately; writes
bench/results/scripted.json.

    python bench/bench_scripted.py --env craftax --num-envs 8 --steps 1000
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import numpy as np

from zoo.envs import make_env
from zoo.experts.scripted import ScriptedExpert


def run(env_name: str, num_envs: int, steps: int, seed: int) -> dict:
    env = make_env(env_name, num_envs, pixels=False)
    expert = ScriptedExpert(num_envs)
    seeds = seed + np.arange(num_envs)
    next_seed = int(seeds.max()) + 1
    step = env.reset(seeds)
    expert.reset(seeds)
    expert.act(step)  # numba compile / load from cache
    step = env.step(np.zeros(num_envs, np.int32))  # jit warm-up
    t_expert = t_env = 0.0
    for _ in range(steps):
        t0 = time.perf_counter()
        actions = expert.act(step)
        t1 = time.perf_counter()
        step = env.step(actions)
        t2 = time.perf_counter()
        t_expert += t1 - t0
        t_env += t2 - t1
        if step.done.any():
            for i in np.flatnonzero(step.done):
                seeds[i] = next_seed
                next_seed += 1
            step = env.reset(seeds, step.done)
            expert.reset(seeds, step.done)
    env_steps = steps * num_envs
    return {
        "env": env_name,
        "num_envs": num_envs,
        "steps": steps,
        "expert_steps_per_s": env_steps / t_expert,
        "expert_ms_per_env_step": 1000 * t_expert / env_steps,
        "env_steps_per_s": env_steps / t_env,
        "machine": platform.processor() or platform.machine(),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="craftax", choices=("craftax", "crafter"))
    parser.add_argument("--num-envs", type=int, default=8)
    parser.add_argument("--steps", type=int, default=1000, help="batched steps to time")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default=str(Path(__file__).parent / "results" / "scripted.json"))
    args = parser.parse_args()
    result = run(args.env, args.num_envs, args.steps, args.seed)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
