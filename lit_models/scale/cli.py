"""`zoo scale --out DIR`: what the paper's scale will cost, projected from CPU measurements.

Only argparse at import time (``zoo --help`` imports this to list the command); the
measurement imports torch, Lightning and JAX when the command runs.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from lit_models.scale.stages import QUICK_STAGES, STAGES

DESCRIPTION = """\
Measure each paper training stage on this CPU (parameters; forward+backward FLOPs counted
with torch.utils.flop_counter on the module's real loss; bytes saved for backward at two batch
sizes; one timed fp32 optimizer step against the CPU's measured fp32 matmul peak) and project
it to the paper's scale: peak memory per device at the config's per-device batch and whether it
fits an RTX 4090 (24 GB), A6000 (48 GB) and H100 (80 GB), GPU-hours at 30% and 15% MFU beside
the paper's reported hours, DataLoader workers per GPU in both frame modes, and disk for the
paper's 180M frames. Writes DIR/scale.json (every number, marked measured, assumed or
projected; per stage: measured, projected.memory_at_batch, .fit, .gpu_hours, .paper,
.loading, .cpu_check) and DIR/scale.md (the same to read). --quick skips the warm-up steps
and measures 2 stages, for tests and dry runs. Stages (configs/<stage>.yaml):
""" + ", ".join(STAGES) + "."


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "scale", help="project the paper-scale cost of each training stage (memory, GPU-hours, "
        "loader workers, disk) from CPU measurements", description=DESCRIPTION,
    )  # fmt: skip
    parser.add_argument("--out", required=True, type=Path, metavar="DIR",
                        help="folder for scale.md and scale.json (created)")  # fmt: skip
    parser.add_argument("--configs", type=Path, default=Path("configs"),
                        help="folder holding the stages' YAMLs (default: configs)")  # fmt: skip
    parser.add_argument("--stages", nargs="+", choices=list(STAGES), metavar="STAGE",
                        help="measure only these stages (default: all; with --quick: "
                        + " ".join(QUICK_STAGES) + ")")  # fmt: skip
    parser.add_argument("--bench", type=Path, default=Path("bench/results"),
                        help="folder of the measured loader rates and bytes per frame "
                        "(frames.json, cclip.json; default: bench/results)")  # fmt: skip
    parser.add_argument("--quick", action="store_true",
                        help="time each step without a warm-up step before it, and measure only "
                        + " ".join(QUICK_STAGES) + " unless --stages says (tests, pipeline dry "
                        "runs; shapes stay the paper's)")  # fmt: skip
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from lit_models.scale.report import scale

    result = scale(args.out, args.configs, args.stages, args.bench, args.quick)
    print(f"zoo scale: wrote {args.out / 'scale.md'} and scale.json "
          f"({len(result['stages'])} stages, {result['meta']['seconds']:.0f} s)")  # fmt: skip
    return 0
