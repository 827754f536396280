"""`zoo expert train`: train the PPO-RNN expert on Craftax-Classic-Symbolic (JAX; GPU for scale)."""

from __future__ import annotations

import argparse
from pathlib import Path

from zoo.argtypes import add_out_flag, add_run_flags


def register(subparsers: argparse._SubParsersAction) -> None:
    expert = subparsers.add_parser("expert", help="train the PPO-RNN expert (Craftax, JAX)")
    verbs = expert.add_subparsers(dest="expert_command", metavar="VERB", required=True)
    train = verbs.add_parser(
        "train",
        help="train (or resume) a PPO-RNN expert",
        description=(
            "Train the paper's PPO-RNN expert on Craftax-Classic-Symbolic. Writes "
            "metrics.jsonl, config.yaml and checkpoints/update_*/ to --out; "
            "The agent named 'ppo' with --checkpoint OUT plays the newest checkpoint."
        ),
    )
    train.add_argument(
        "--config", required=True, help="YAML with every PPOConfig field (configs/expert_ppo.yaml)"
    )
    add_out_flag(train, "run folder", default="runs/expert_ppo/<config name>")
    train.add_argument(
        "--total-timesteps", type=lambda s: int(float(s)), help="override total_timesteps (1e9 ok)"
    )
    add_run_flags(train, "total_timesteps")
    train.set_defaults(handler=run_train)


def run_train(args: argparse.Namespace) -> int:
    from zoo.experts.ppo import PPOConfig, train_ppo

    config = PPOConfig.from_yaml(args.config)
    overrides = {"total_timesteps": args.total_timesteps, "seed": args.seed}
    config = config.replace(**{k: v for k, v in overrides.items() if v is not None})
    out = Path(args.out) if args.out else Path("runs") / "expert_ppo" / Path(args.config).stem
    train_ppo(config, out, resume=args.resume, use_wandb=args.wandb)
    return 0
