"""RL agents' speed on this machine -> bench/results/rl.json.

For each agent of ``zoo rl`` (configs/rl/<agent>_t2.yaml, the shipped CPU weights), runs
``train_rl`` for a few updates on the same batch of envs (``--num-envs``, Craftax-Classic
with pixels) and reports env steps per second over the whole update (rollout + PPO epochs)
and the share of time in the env, in the networks while acting (PPO-Steve: its planner and
frozen C-Steve-1), and in the PPO update. Agents run one after another in one process; the
first update (JIT compile, texture cache) is dropped.

  nice -n 10 .venv/bin/python bench/bench_rl.py
"""

from __future__ import annotations

import argparse
import csv
import json
import platform
import statistics
import tempfile
from pathlib import Path

import torch

from zoo.rl.config import RLConfig
from zoo.rl.train import train_rl

ROOT = Path(__file__).resolve().parents[1]
RESULTS = Path(__file__).parent / "results" / "rl.json"
AGENTS = ("ppo_rnn", "cvpt_rl", "ppo_steve")


def measure(agent: str, num_envs: int, updates: int) -> dict:
    config = RLConfig.from_yaml(ROOT / "configs" / "rl" / f"{agent}_t2.yaml")
    config = config.replace(num_envs=num_envs, num_minibatches=min(4, num_envs))
    paths = {k: str(ROOT / getattr(config, k)) for k in ("checkpoint", "cclip", "prior")
             if getattr(config, k)}
    config = config.replace(**paths, total_env_steps=config.env_steps_per_update * (updates + 1))
    with tempfile.TemporaryDirectory() as tmp:
        last = train_rl(config, tmp, progress=False)
        with (Path(tmp) / "metrics.csv").open() as f:
            rows = list(csv.DictReader(f))[1:]
    trainable, total = last["trainable_parameters"], last["total_parameters"]
    median = {k: statistics.median(float(r[k]) for r in rows)
              for k in ("env_steps_per_s", "env_share", "model_share", "update_share")}
    return {
        "config": f"configs/rl/{agent}_t2.yaml",
        "num_envs": num_envs,
        "agent_steps_per_update": config.num_steps,
        "env_steps_per_update": config.env_steps_per_update,
        "updates_measured": len(rows),
        "trainable_parameters": trainable,
        "total_parameters": total,
        **median,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--num-envs", type=int, default=16)
    parser.add_argument("--updates", type=int, default=3)
    args = parser.parse_args()
    results = {agent: measure(agent, args.num_envs, args.updates) for agent in AGENTS}
    base = results["ppo_rnn"]["env_steps_per_s"]
    for row in results.values():
        row["speed_vs_ppo_rnn"] = row["env_steps_per_s"] / base
    rnn = results["ppo_rnn"]["trainable_parameters"]
    results["cvpt_rl"]["trainable_vs_ppo_rnn"] = results["cvpt_rl"]["trainable_parameters"] / rnn
    out = {
        "machine": {"processor": platform.processor() or platform.machine(),
                    "torch_threads": torch.get_num_threads()},
        "results": results,
    }
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps(out, indent=2) + "\n")
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
