"""`zoo goals embed|prior-pairs|relabel-stats`: C-Steve-1's goal data from CrafterPlay and
CrafterCaption (C-CLIP embeddings of every step, prior training pairs, relabelling statistics)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from zoo.argtypes import add_out_flag, add_progress_flag, existing_dir, positive_int, shard_range


def register(subparsers) -> None:
    goals = subparsers.add_parser(
        "goals", help="C-Steve-1 goal data: embed (C-CLIP goals per step), prior-pairs, relabel-stats"
    )
    goals.set_defaults(handler=lambda args: goals.print_help() or 2)
    goals_sub = goals.add_subparsers(dest="goals_command", metavar="GOALS_COMMAND")
    _register_embed(goals_sub)
    _register_prior_pairs(goals_sub)
    _register_relabel_stats(goals_sub)


def _register_relabel_stats(goals_sub) -> None:
    stats = goals_sub.add_parser(
        "relabel-stats",
        help="how often each relabelling mode gives an achievement caption's goal",
        description="Per relabelling mode, the share of steps whose goal is an achievement "
        "caption's clip, and per caption: steps labelled, mean steps ahead, run-up share. "
        "See zoo/goals/relabel_stats.py.",
    )
    stats.add_argument("--embeddings", required=True, type=existing_dir,
                       help="a `zoo goals embed` folder")
    stats.add_argument("--shards", type=positive_int, default=24,
                       help="shards read (from the first)")
    stats.add_argument("--out", type=Path, help="JSON file for the numbers")
    stats.set_defaults(handler=_relabel_stats)


def _relabel_stats(args: argparse.Namespace) -> int:
    from zoo.goals.relabel_stats import print_relabel_stats

    try:
        print_relabel_stats(args.embeddings, args.shards, args.out)
    except (FileNotFoundError, ValueError) as err:
        print(f"zoo goals relabel-stats: {err}", file=sys.stderr)
        return 2
    return 0


def _register_prior_pairs(goals_sub) -> None:
    """`zoo goals prior-pairs`: C-CLIP (video, text) embedding pairs for the CVAE prior."""
    pairs = goals_sub.add_parser(
        "prior-pairs",
        help="embed CrafterCaption clips and captions with C-CLIP: training pairs of the prior",
        description="Write OUT.npz (video, text float32 embeddings; caption ids, episodes) and "
        "OUT.json (checkpoint sha256, source, counts). See zoo/goals/prior_pairs.py.",
    )
    pairs.add_argument("--checkpoint", required=True, help="C-CLIP Lightning checkpoint (.ckpt)")
    pairs.add_argument("--src", required=True, type=existing_dir, help="CrafterCaption folder")
    pairs.add_argument("--split", default="test", help="manifest split (test: held-out episodes)")
    pairs.add_argument("--out", required=True, help="pairs file, ending in .npz")
    pairs.add_argument("--max-pairs", type=positive_int, help="seeded random subset of the clips")
    pairs.add_argument("--paraphrases", action="store_true",
                       help="text of a random caption variant per clip instead of the template")
    pairs.add_argument("--seed", type=int, default=0, help="seed of --max-pairs, --paraphrases")
    pairs.add_argument("--batch-size", type=positive_int, default=64, help="clips per C-CLIP pass")
    pairs.add_argument("--device", default="cpu")
    add_progress_flag(pairs)
    pairs.set_defaults(handler=_prior_pairs)


def _prior_pairs(args) -> int:
    from zoo.goals.prior_pairs import run_prior_pairs

    try:
        return run_prior_pairs(args)
    except (FileNotFoundError, ValueError) as err:
        print(f"zoo goals prior-pairs: {err}", file=sys.stderr)
        return 2


def _register_embed(goals_sub) -> None:
    """`zoo goals embed`: per-step C-CLIP goal embeddings and captions for C-Steve-1."""
    embed = goals_sub.add_parser(
        "embed",
        help="C-CLIP goal embedding and caption of every CrafterPlay step (resumable)",
        description="Write DIR/embed-NNNNNN.tar (one per CrafterPlay shard) and "
        "DIR/manifest.json. Rerun the same command after an interruption to finish. "
        "See zoo/goals/embed.py for the format.",
    )
    embed.add_argument("--checkpoint", required=True, help="C-CLIP Lightning checkpoint (.ckpt)")
    embed.add_argument("--src", required=True, type=existing_dir, help="CrafterPlay folder")
    add_out_flag(embed, "embedding folder")
    embed.add_argument("--batch-size", type=positive_int, default=240,
                       help="frames per image-tower pass (whole groups of 6)")
    embed.add_argument("--device", default="cpu")
    embed.add_argument("--shards", type=shard_range, help="A:B: only CrafterPlay shards A..B-1")
    add_progress_flag(embed)
    embed.set_defaults(handler=_embed)


def _embed(args) -> int:
    from zoo.goals.embed_writer import embed_dataset

    try:
        manifest = embed_dataset(args.checkpoint, args.src, args.out, args.batch_size,
                                 args.device, args.shards, not args.no_progress)
    except (FileNotFoundError, ValueError, RuntimeError) as err:
        print(f"zoo goals embed: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted; rerun the same command to finish the embeddings", file=sys.stderr)
        return 130
    stats = manifest["stats"]
    print(f"{args.out}: {len(manifest['shards'])} shards, {stats['episodes']} episodes, "
          f"{stats['steps']} steps, {stats['captioned_share']:.1%} with a caption")
    return 0
