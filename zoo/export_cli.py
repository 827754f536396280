"""`zoo export CKPT OUT`: a Lightning C-VPT checkpoint to a Lightning-free export folder."""

from __future__ import annotations

import argparse


def _export(args: argparse.Namespace) -> int:
    from zoo.export import export_checkpoint  # torch loads only when exporting

    out = export_checkpoint(args.checkpoint, args.out_dir)
    print(f"exported {args.checkpoint} -> {out}")
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "export",
        help="write a C-VPT .ckpt as model.safetensors + config.json + sha256.txt",
        description="Export a C-VPT Lightning checkpoint so it loads with plain torch "
        "(zoo.export.load_exported, or `zoo eval --agent cvpt --checkpoint OUT`).",
    )
    parser.add_argument("checkpoint", help="Lightning .ckpt written by `zoo fit`")
    parser.add_argument("out_dir", help="folder to write (created if missing)")
    parser.set_defaults(handler=_export)
