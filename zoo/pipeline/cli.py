"""``zoo pipeline --config configs/pipeline_quickstart.yaml --out DIR`` (or a DAgger config)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

DESCRIPTION = """\
Run the whole suite, each stage as the ordinary `zoo` command (printed before it runs):
generate CrafterPlay with the scripted expert, caption it (CrafterCaption), train C-VPT and
C-CLIP, score the C-VPT and the scripted expert in Craftax-Classic and crafter, score C-CLIP's
retrieval, and, when the config's `steve: true`, embed goals, train C-Steve-1 and its prior and
score one instruction task. Writes OUT/report.md, a self-contained OUT/report.html and
OUT/pipeline.json (stages, commands, timings, status).

Rerun the same command to continue after an interruption: a stage whose output is recorded in
pipeline.json, made by the same command from the same inputs (their sha256s) and verified
(shard sha256s, checkpoints that load, reports that parse) is skipped. An output that fails
verification is moved aside to FOLDER.bad-N, an outdated one to FOLDER.old-N, and the stage
runs again; the stages that read it run again when its new bytes differ.

configs/pipeline_quickstart.yaml runs in minutes on a CPU; configs/pipeline_paper.yaml is the
paper-scale recipe for GPUs. See docs/pipeline.md.

A config with `kind: dagger` (configs/pipeline_dagger.yaml) runs DAgger rounds for C-VPT
instead, from a C-VPT you trained first: per round, roll out the last round's weights with the
scripted expert labelling every state (`zoo data dagger`), train from them on the expert data
plus every round's labels (`zoo fit`), score the new weights (`zoo eval`); a retrained round
reruns every round after it. See docs/dagger.md.
"""


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "pipeline",
        help="the whole suite (or DAgger rounds) in one command: data, training, evaluation, "
        "one report",
        description=DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--config", required=True, type=Path,
                   help="pipeline YAML (configs/pipeline_quickstart.yaml, pipeline_paper.yaml, "
                   "pipeline_dagger.yaml)")
    p.add_argument("--out", required=True, type=Path, help="folder of every output and the report")
    p.add_argument("--dry-run", action="store_true",
                   help="a suite config at its model sizes and sequence shapes on a few episodes "
                   "on the CPU, each fit 2 steps, then `zoo scale`, to check a config before GPU "
                   "time is spent on it; docs/pipeline.md lists what it changes")
    p.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from zoo.pipeline.config import PipelineConfig, load_pipeline_config

    try:
        config = paper = load_pipeline_config(args.config)
        if args.dry_run:
            if not isinstance(config, PipelineConfig):
                raise ValueError(f"{args.config}: --dry-run takes a suite config, not "
                                 "`kind: dagger`")
            from zoo.pipeline.dry_run import dry_config

            config = dry_config(config, args.out)
    except (ValueError, FileNotFoundError) as err:
        print(f"zoo pipeline: {err}", file=sys.stderr)
        return 2
    if args.out.exists() and not args.out.is_dir():
        print(f"zoo pipeline: --out {args.out} is a file; give a folder", file=sys.stderr)
        return 2
    from zoo.pipeline.report import write_reports
    from zoo.pipeline.runner import run_pipeline

    doc = run_pipeline(config, args.config, args.out, paper if args.dry_run else None)
    md, page = write_reports(args.out, doc)
    for record in doc["stages"]:
        seconds = record.get("seconds")
        print(f"{record['name']:28s} {record['status']:8s} "
              f"{'' if seconds is None else f'{seconds:8.1f} s'}")
    print(f"{'total':28s} {'ok' if doc['ok'] else 'FAILED':8s} {doc['seconds']:8.1f} s")
    print(f"report: {md}, {page}; record: {args.out / 'pipeline.json'}")
    return 0 if doc["ok"] else 1
