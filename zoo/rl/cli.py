"""`zoo rl`: train the reference RL agents (PPO-RNN, C-VPT-RL, PPO-Steve) on the task suites,
and plot their success curves."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from zoo.argtypes import add_out_flag, add_progress_flag, add_run_flags


def register(subparsers: argparse._SubParsersAction) -> None:
    rl = subparsers.add_parser(
        "rl", help="train and plot the RL agents (PPO-RNN, C-VPT-RL, PPO-Steve) on T1-T4"
    )
    verbs = rl.add_subparsers(dest="rl_command", metavar="VERB", required=True)
    train = verbs.add_parser(
        "train",
        help="train (or resume) one agent on one task",
        description=(
            "PPO on a task of zoo.envs.tasks with the sparse, ordered sub-task reward. Writes "
            "config.yaml, metrics.csv (one row per update: success rate, env steps/s, losses) "
            "and checkpoints/ to --out. Configs: configs/rl/<agent>_<task>.yaml."
        ),
    )
    train.add_argument("--config", required=True, help="YAML with every RLConfig field")
    add_out_flag(train, "run folder", default="runs/rl/<config name>/seed<S>")
    train.add_argument(
        "--total-env-steps", type=lambda s: int(float(s)), help="override total_env_steps"
    )
    add_run_flags(train, "total_env_steps")
    add_progress_flag(train)
    train.set_defaults(handler=run_train)
    plot = verbs.add_parser(
        "plot",
        help="success rate vs env steps, mean ± std over seeds, one panel per task",
        description=(
            "Reads each run's metrics.csv; runs with the same task and agent are seeds of one "
            "curve. --baseline LABEL=report.json adds a fixed agent's `zoo eval --task` "
            "success rate as a dashed line. Writes the PNG and a JSON table beside it."
        ),
    )
    plot.add_argument("runs", nargs="+", help="run directories of `zoo rl train`")
    plot.add_argument("--out", required=True, help="PNG to write")
    plot.add_argument(
        "--baseline", action="append", default=[], metavar="LABEL=REPORT",
        help="a `zoo eval --task` report.json drawn as a line (repeatable)",
    )
    plot.set_defaults(handler=run_plot)


def run_train(args: argparse.Namespace) -> int:
    from zoo.rl.config import RLConfig
    from zoo.rl.train import list_checkpoints, train_rl

    overrides = {"seed": args.seed, "total_env_steps": args.total_env_steps}
    try:
        config = RLConfig.from_yaml(args.config)
        config = config.replace(**{k: v for k, v in overrides.items() if v is not None})
    except (ValueError, FileNotFoundError) as err:
        print(f"zoo rl train: {err}", file=sys.stderr)
        return 2
    out = Path(args.out or Path("runs") / "rl" / Path(args.config).stem / f"seed{config.seed}")
    if list_checkpoints(out) and not args.resume:
        print(f"zoo rl train: {out} already holds checkpoints; pass --resume to continue it "
              "or choose another --out", file=sys.stderr)
        return 2
    train_rl(config, out, resume=args.resume, use_wandb=args.wandb,
             progress=not args.no_progress)
    return 0


def run_plot(args: argparse.Namespace) -> int:
    from zoo.rl.plot import plot_runs

    baselines = []
    for item in args.baseline:
        label, sep, path = item.partition("=")
        if not sep or not label or not path:
            raise SystemExit(f"zoo rl plot: --baseline expects LABEL=report.json, got {item!r}")
        baselines.append((label, Path(path)))
    table = plot_runs(args.runs, args.out, baselines)
    table_path = Path(args.out).with_suffix(".json")
    table_path.write_text(json.dumps(table, indent=2) + "\n")
    print(f"wrote {args.out} and {table_path}")
    return 0
