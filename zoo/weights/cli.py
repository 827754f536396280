"""`zoo export --checkpoint CKPT --out DIR`: any model's Lightning checkpoint to an export folder.

The kind (C-VPT, C-CLIP, CVAE prior, C-Steve-1) comes from the checkpoint's hyper-parameters.
For C-Steve-1, `--cfg-scale`/`--temperature` record the settings its scores were measured at, so
`zoo play`, `zoo eval` and `CSteve1Policy.load` play at them unless told otherwise, and
`--cclip`/`--prior` the goal models that read its text instructions, so it needs no other flag.
An export folder given as the checkpoint is written again (keeping what it records unless told).
The older positional form `zoo export CKPT DIR` still works (docs and scripts use it).
"""

from __future__ import annotations

import argparse
import sys

from zoo.weights.guidance import PAPER_CFG_SCALE

DTYPE_CHOICES = ("float32", "float16", "bfloat16")


def _export(args: argparse.Namespace) -> int:
    checkpoint, out = args.checkpoint, args.out
    if args.paths:
        if checkpoint or out or len(args.paths) != 2:
            return _fail("give CKPT OUT positionally or as --checkpoint/--out, not both")
        checkpoint, out = args.paths
    if not (checkpoint and out):
        return _fail("needs a checkpoint and an output folder: --checkpoint CKPT --out DIR")

    from zoo.weights.export import (  # torch loads only when exporting
        export_checkpoint,
        exported_kind,
        inference_settings,
        recorded_goal_models,
    )

    given = {"cfg_scale": args.cfg_scale, "temperature": args.temperature}
    if (args.cclip is None) != (args.prior is None):
        return _fail("give --cclip and --prior together")
    goal_models = None if args.cclip is None else {"cclip": args.cclip, "prior": args.prior}
    try:
        path = export_checkpoint(
            checkpoint, out, args.dtype, {k: v for k, v in given.items() if v is not None},
            goal_models, args.copy_goal_models,
        )
    except (FileNotFoundError, ValueError) as err:
        return _fail(str(err))
    kind = exported_kind(path)
    settings = "".join(f", {k} {v:g}" for k, v in inference_settings(path, kind).items())
    goals = recorded_goal_models(path)
    reads = f"; reads text through {goals['cclip']} and {goals['prior']}" if goals else ""
    print(f"exported {kind} {checkpoint} -> {path} ({args.dtype}{settings}){reads}")
    return 0


def _fail(message: str) -> int:
    print(f"zoo export: error: {message}", file=sys.stderr)
    return 2


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "export",
        help="write a .ckpt of any model as model.safetensors + config.json + sha256.txt",
        description="Export a Lightning checkpoint of C-VPT, C-CLIP, the CVAE prior or "
        "C-Steve-1 so it loads with plain torch (zoo.weights.load_model, "
        "or `zoo eval --checkpoint OUT` for the agents).",
    )
    parser.add_argument("--checkpoint",
                        help="Lightning .ckpt written by `zoo fit`, or an export folder")
    parser.add_argument("--out", help="folder to write (created if missing)")
    parser.add_argument(
        "--dtype", choices=DTYPE_CHOICES, default="float32",
        help="how weights are stored; loading always gives float32 (default: %(default)s)",
    )
    parser.add_argument(
        "--cfg-scale", type=float, metavar="X",
        help="C-Steve-1: the classifier-free guidance scale its scores were measured at, "
        f"recorded in config.json as what it plays at (default: the paper's {PAPER_CFG_SCALE})",
    )
    parser.add_argument(
        "--temperature", type=float, metavar="T",
        help="C-Steve-1: the sampling temperature its scores were measured at, recorded the "
        "same way (default 1; 0: the most likely action)",
    )
    parser.add_argument(
        "--cclip", metavar="DIR",
        help="C-Steve-1: the C-CLIP export it was trained with; recorded (path and sha256) so "
        "the export reads text instructions with no other flag",
    )
    parser.add_argument("--prior", metavar="DIR",
                        help="C-Steve-1: the CVAE prior export, recorded the same way")
    parser.add_argument(
        "--copy-goal-models", action="store_true",
        help="copy --cclip and --prior into the export folder, so it can be moved on its own",
    )
    parser.add_argument(
        "paths", nargs="*", metavar="CKPT OUT", help="the same two paths, positionally"
    )
    parser.set_defaults(handler=_export)
