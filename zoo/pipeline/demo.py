"""``zoo demo``: the main job at laptop scale, so a first run shows every piece working.

It generates a few CrafterPlay episodes with the scripted expert, summarises them, and writes
the expert's evaluation report (Crafter Score, success rates, plot, GIF). Each step is the
ordinary CLI command, printed before it runs, so the demo doubles as a recipe.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from zoo.envs.flags import add_episodes_flag, add_game_flag, add_max_steps_flag, add_seed_flag


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "demo",
        help="small end-to-end run: scripted expert -> CrafterPlay shards -> evaluation report",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--out", type=Path, default=Path("runs/demo"), help="output folder")
    add_game_flag(p, default="craftax")
    add_episodes_flag(p, default=4, what="episodes to generate and score")
    add_max_steps_flag(p, default=1000)
    add_seed_flag(p)  # the data's and the evaluation's
    p.set_defaults(handler=run_demo)


def run_demo(args: argparse.Namespace) -> int:
    from zoo.cli import main

    if args.out.exists() and not args.out.is_dir():
        print(f"zoo demo: error: --out {args.out} is a file; give a folder")
        return 2
    common = ["--env", args.env, "--episodes", str(args.episodes), "--seed", str(args.seed),
              "--max-steps", str(args.max_steps)]
    data = args.out / "crafterplay"
    steps = [
        ["data", "generate", "--expert", "scripted", "--out", str(data),
         "--episodes-per-shard", "2", *common],
        ["data", "info", str(data)],
        ["eval", "--agent", "scripted", "--out", str(args.out / "eval"), "--overwrite", *common],
    ]
    if args.env == "craftax":
        print("The first run waits before the bars move: JAX compiles Craftax's step and "
              "renderer (and builds its texture cache once); later runs reuse the compile cache.",
              flush=True)
    for argv in steps:
        print("\n$ zoo " + " ".join(argv), flush=True)
        code = main(argv)
        if code:
            return code
    print(f"\nDone: data in {data}, report in {args.out / 'eval'} "
          "(report.json, achievements.png, episode.gif).")
    return 0
