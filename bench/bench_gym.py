"""Gymnasium adapter overhead and the C-CLIP reward's cost per step -> bench/results/gym.json.

What, in one process and one run:
  * adapter overhead: env steps/s of a raw zoo env against the Gymnasium env over it, as a
    user gets it (``gymnasium.make``/``make_vec``, with Gymnasium's own checker wrappers), for
    Craftax-Classic batched (``CraftaxVectorEnv`` over ``CraftaxEnv``, N envs), Craftax-Classic
    single (``CrafterDojoEnv`` over ``CraftaxEnv(1)``) and crafter single (``CrafterDojoEnv``
    over ``CrafterEnv(1)``). The raw loop does what a user of the zoo env must do for the same
    result: step, then reset the finished envs with their next episode's seed
    (``episode_seed``), as ``zoo eval``'s loop does. Both play the same pre-drawn uniform random
    actions with 144-px pixels and the game's own reward (no task).
    ``end_to_end_overhead`` = 1 - adapter steps/s / raw steps/s. On a shared machine the rounds
    of one side spread by tens of percent, far more than the adapter costs, so the adapter's
    own time is measured alone as well: the zoo env under it answers each step with one fixed
    ``Step`` (``layer_us_per_env_step``); its share of the raw env step,
    ``layer_share_of_raw_step``, is what issue 35's goal (<= 5%) is checked on.
  * ``CClipReward``: seconds per env step with the wrapper minus without it, on crafter single
    (``CClipReward``) and on the Craftax vector env (``VectorCClipReward``, one C-CLIP batch of N
    per step), with the shipped weights/cclip_cpu on the CPU.

How: each pair is timed in alternating rounds (raw, adapter, raw, ...; ``--rounds``) of a fixed
number of steps after a warm-up (compile, caches), and the medians are compared, so load from
other jobs on the machine hits both sides alike. About 3 minutes (plus compiles on a fresh cache).

  .venv/bin/python bench/bench_gym.py
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import time
from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path

import gymnasium
import numpy as np
import torch

import zoo.gym  # noqa: F401  (registers the ids)
from zoo.envs import NUM_ACTIONS, make_env
from zoo.envs.base import episode_seed
from zoo.gym.env import CrafterDojoEnv
from zoo.gym.vector import CraftaxVectorEnv
from zoo.gym.wrappers import CClipReward, VectorCClipReward

RESULTS = Path(__file__).parent / "results" / "gym.json"
GOAL = 0.05  # issue 35 §5: the adapter costs <= 5% of the env step it wraps
SEED = 0


def raw_loop(env, actions: np.ndarray) -> Callable[[], int]:
    """A step function over a zoo env that resets finished envs with their next episodes."""
    n = env.num_envs
    episode = np.arange(n)
    seeds = np.array([episode_seed(SEED, int(j)) for j in episode])
    env.reset(seeds)
    t = 0

    def step() -> int:
        nonlocal t
        out = env.step(actions[t % len(actions)])
        t += 1
        if out.done.any():
            for i in np.flatnonzero(out.done):
                episode[i] += n
                seeds[i] = episode_seed(SEED, int(episode[i]))
            env.reset(seeds, out.done)
        return n

    return step


def gym_loop(env, actions: np.ndarray, vector: bool) -> Callable[[], int]:
    """A step function over a Gymnasium env (a single one resets itself when an episode ends)."""
    env.reset(seed=SEED)
    t = 0

    def step() -> int:
        nonlocal t
        a = actions[t % len(actions)]
        t += 1
        if vector:
            env.step(a)
            return len(a)
        _, _, terminated, truncated, _ = env.step(int(a[0]))
        if terminated or truncated:
            env.reset()
        return 1

    return step


def layer_seconds(env, actions: np.ndarray, vector: bool, calls: int = 2000) -> float:
    """Seconds per env step of the Gymnasium layer alone: the zoo env under it answers every step
    with one fixed, unfinished ``Step``, so only the adapter's own work is timed."""
    env.reset(seed=SEED)
    zoo_env = env.unwrapped.batch.env
    fixed = zoo_env.step(actions[0])
    zoo_env.step = lambda _actions: fixed
    step = gym_loop(env, actions, vector)
    return 1 / timed(step, calls)


def timed(step: Callable[[], int], calls: int) -> float:
    """Env steps per second of ``calls`` calls."""
    start, steps = time.perf_counter(), 0
    for _ in range(calls):
        steps += step()
    return steps / (time.perf_counter() - start)


def compare(name: str, a: Callable[[], int], b: Callable[[], int], calls: int, rounds: int,
            warmup: int) -> dict:
    """Alternating rounds of two step functions; their median steps/s."""
    for _ in range(warmup):
        a(), b()
    runs: dict[str, list[float]] = {"a": [], "b": []}
    for _ in range(rounds):
        runs["a"].append(timed(a, calls))
        runs["b"].append(timed(b, calls))
    med = {k: statistics.median(v) for k, v in runs.items()}
    print(f"{name}: {med['a']:.0f} vs {med['b']:.0f} env steps/s", flush=True)
    return {"steps_per_s": med, "rounds": runs, "calls_per_round": calls}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--num-envs", type=int, default=64, help="batched Craftax envs")
    parser.add_argument("--cclip-num-envs", type=int, default=16, help="batched C-CLIP reward")
    parser.add_argument("--rounds", type=int, default=9)
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args()
    torch.set_num_threads(1)
    started = datetime.now(UTC)
    rng = np.random.default_rng(0)
    n = args.num_envs
    acts = {k: rng.integers(NUM_ACTIONS, size=(4096, k)).astype(np.int32)
            for k in (1, n, args.cclip_num_envs)}

    overhead = {}
    setups = (
        ("craftax_batched", lambda: make_env("craftax", n),
         lambda: gymnasium.make_vec("CrafterDojo/Craftax-v0", n), acts[n], 40),
        ("craftax_single", lambda: make_env("craftax", 1),
         lambda: gymnasium.make("CrafterDojo/Craftax-v0"), acts[1], 1000),
        ("crafter_single", lambda: make_env("crafter", 1),
         lambda: gymnasium.make("CrafterDojo/Crafter-v0"), acts[1], 300),
    )
    for name, make_raw, make_gym, actions, calls in setups:
        vector = actions.shape[1] > 1
        gym_env = make_gym()
        result = compare(name, raw_loop(make_raw(), actions), gym_loop(gym_env, actions, vector),
                         calls, args.rounds, warmup=5)
        sps = result.pop("steps_per_s")
        layer = layer_seconds(gym_env, actions, vector)
        result.update(
            raw_steps_per_s=sps["a"], adapter_steps_per_s=sps["b"],
            end_to_end_overhead=1 - sps["b"] / sps["a"],
            layer_us_per_env_step=1e6 * layer, layer_share_of_raw_step=layer * sps["a"],
        )
        result["meets_goal"] = result["layer_share_of_raw_step"] <= GOAL
        overhead[name] = result

    k = args.cclip_num_envs
    cclip = {}
    for name, plain, shaped, calls, batch in (
        ("crafter_single", lambda: CrafterDojoEnv("crafter"),
         lambda: CClipReward(CrafterDojoEnv("crafter"), "obtain drink"), 100, 1),
        (f"craftax_vector_{k}", lambda: CraftaxVectorEnv(k),
         lambda: VectorCClipReward(CraftaxVectorEnv(k), "obtain drink"), 20, k),
    ):
        vector = batch > 1
        result = compare(f"cclip {name}", gym_loop(plain(), acts[batch], vector),
                         gym_loop(shaped(), acts[batch], vector), calls, args.rounds, warmup=3)
        sps = result.pop("steps_per_s")
        cost = 1 / sps["b"] - 1 / sps["a"]
        result.update(plain_steps_per_s=sps["a"], cclip_steps_per_s=sps["b"],
                      cclip_ms_per_env_step=1000 * cost, envs=batch)
        cclip[name] = result

    report = {
        "what": "Gymnasium adapter (zoo.gym) overhead over the raw zoo envs, and CClipReward's "
                "cost per env step",
        "issue": "35 §5: the adapter costs <= 5% of the env step it wraps; the C-CLIP reward's "
                 "cost per step is stated",
        "started_at": started.isoformat(timespec="seconds"),
        "finished_at": datetime.now(UTC).isoformat(timespec="seconds"),
        "machine": {"processor": platform.machine(), "cpus": os.cpu_count(),
                    "python": platform.python_version(), "torch": torch.__version__,
                    "torch_threads": torch.get_num_threads(),
                    "load_average_1_5_15": os.getloadavg()},
        "settings": {"pixels": 144, "craftax_num_envs": n, "cclip_num_envs": k,
                     "rounds": args.rounds, "cclip": "weights/cclip_cpu",
                     "actions": "uniform random, pre-drawn", "seed": SEED},
        "overhead": overhead,
        "cclip_reward": cclip,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(report, indent=2) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
