"""Env steps per second of PPO-RNN training (rollout + updates) on this machine's JAX backend.

    .venv/bin/python bench/bench_ppo.py --num-envs 64 --layer-size 128 --blocks 3

Starts from configs/expert_ppo.yaml with the sizes given, compiles one block of updates
(not timed), times ``--blocks`` more and writes bench/results/ppo_train_<backend>.json.
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import jax

from zoo.envs.craftax_env import enable_compilation_cache
from zoo.experts.ppo import PPOConfig
from zoo.experts.ppo.train import build_trainer

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--num-envs", type=int, default=64)
    parser.add_argument("--layer-size", type=int, default=128)
    parser.add_argument("--num-steps", type=int, default=64)
    parser.add_argument("--updates-per-block", type=int, default=2)
    parser.add_argument("--blocks", type=int, default=3)
    args = parser.parse_args()

    enable_compilation_cache()
    config = PPOConfig.from_yaml(ROOT / "configs" / "expert_ppo.yaml").replace(
        num_envs=args.num_envs,
        layer_size=args.layer_size,
        num_steps=args.num_steps,
        updates_per_block=args.updates_per_block,
        checkpoint_every_updates=args.updates_per_block,
    )
    trainer = build_trainer(config)
    runner = trainer.init(jax.random.PRNGKey(0))
    began = time.perf_counter()
    runner, _ = trainer.update_block(runner, config.updates_per_block)
    jax.block_until_ready(runner)
    compile_s = time.perf_counter() - began

    began = time.perf_counter()
    for _ in range(args.blocks):
        runner, _ = trainer.update_block(runner, config.updates_per_block)
    jax.block_until_ready(runner)
    seconds = time.perf_counter() - began
    steps = args.blocks * config.updates_per_block * config.batch_size

    backend = jax.default_backend()
    result = {
        "what": "PPO-RNN training env-steps/s (rollout + updates), Craftax-Classic-Symbolic",
        "backend": backend,
        "device": str(jax.devices()[0]),
        "machine": platform.processor() or platform.machine(),
        "num_envs": config.num_envs,
        "num_steps": config.num_steps,
        "layer_size": config.layer_size,
        "env_steps": steps,
        "seconds": seconds,
        "env_steps_per_s": steps / seconds,
        "first_block_s_incl_compile": compile_s,
    }
    out = ROOT / "bench" / "results" / f"ppo_train_{backend}.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
