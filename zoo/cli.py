"""The `zoo` command: data, eval and export tools; fit|validate|test|predict go to LightningCLI.

Subcommands live next to what they drive (``zoo/<part>/cli.py`` exposes ``register``), so
this file only wires them. Lightning is imported only for the training verbs.
"""

from __future__ import annotations

import argparse
import importlib
import os
import select
import sys

TRAIN_VERBS = ("fit", "validate", "test", "predict")

# (module, function) pairs; each function adds its subcommands to the parser it is given.
TOP_LEVEL = (
    ("zoo.data.cli", "register"),
    ("zoo.goals.cli", "register"),
    ("zoo.eval.cli", "register"),
    ("zoo.eval.curves", "register"),
    ("zoo.eval.compare", "register"),
    ("zoo.captions.cli", "register"),
    ("zoo.experts.cli", "register"),
    ("zoo.weights.cli", "register"),
    ("zoo.pipeline.demo", "register"),
    ("zoo.eval.play", "register"),
    ("zoo.rl.cli", "register"),
    ("zoo.pipeline", "register"),
    ("lit_models.scale.cli", "register"),
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="zoo",
        description=(
            "crafter-zoo: the CrafterDojo suite for Crafter. Generate expert data "
            "(zoo data generate), score agents in Craftax-Classic or crafter (zoo eval; task "
            "suites with zoo eval --task; results tables with zoo tables), train models with LightningCLI (zoo fit --config "
            "configs/cvpt_smoke.yaml), watch C-Steve-1 follow an instruction (zoo play), train "
            "the RL agents on the long-horizon tasks (zoo rl train --config "
            "configs/rl/cvpt_rl_t2.yaml), or run it all with one report (zoo pipeline --config "
            "configs/pipeline_quickstart.yaml)."
        ),
        epilog="Training verbs: " + ", ".join(TRAIN_VERBS) + " (see `zoo fit --help`).",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for module, func in TOP_LEVEL:
        try:
            mod = importlib.import_module(module)
        except ModuleNotFoundError as err:
            if not err.name or not (module + ".").startswith(err.name + "."):
                raise  # a real missing dependency, not an absent optional part
            continue
        getattr(mod, func)(sub)
    for verb in TRAIN_VERBS:
        extra = "; writes <run>/predictions/*.npz" if verb == "predict" else ""
        sub.add_parser(
            verb, help=f"LightningCLI {verb} (--config configs/<model>.yaml){extra}", add_help=False
        )
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run ``zoo ARGV``; a reader that stopped reading (``zoo captions list | head``) ends it
    quietly with code 1 instead of a BrokenPipeError traceback, for every command."""
    try:
        code = _run(sys.argv[1:] if argv is None else argv)
        sys.stdout.flush()  # output still buffered meets the closed pipe here
    except BrokenPipeError:
        if not _stdout_reader_gone():
            raise  # another pipe (a DataLoader worker, a socket) broke: a real error
        # the Python docs' recipe (signal module, "Note on SIGPIPE"): stdout goes to devnull so
        # the interpreter's flush at exit does not raise again
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 1
    return code


def _stdout_reader_gone() -> bool:
    """Whether stdout is a pipe whose reading end is closed (poll reports an error on it)."""
    try:
        fd = sys.stdout.fileno()
    except (AttributeError, OSError, ValueError):
        return False
    if not hasattr(select, "poll"):  # Windows: no way to tell, so not assumed
        return False
    poller = select.poll()
    poller.register(fd, select.POLLOUT)
    return any(events & select.POLLERR for _, events in poller.poll(0))


def _run(argv: list[str]) -> int:
    if argv and argv[0] in TRAIN_VERBS:
        # Before torch loads OpenMP: its threads sleep at a barrier instead of spinning, so
        # they do not take the cores the DataLoader workers need (docs/results/cvpt.md has
        # the A/B). A set policy is kept.
        os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
        from lit_models.cli import DataNotFoundError, run_lightning_cli
        from zoo.weights.checkpoint_io import CheckpointError

        try:
            run_lightning_cli(argv)
        except (DataNotFoundError, CheckpointError) as err:
            print(f"zoo {argv[0]}: {err}", file=sys.stderr)
            return 2
        return 0
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "handler", None):
        parser.print_help()
        return 0 if not argv else 2
    return int(args.handler(args) or 0)


if __name__ == "__main__":
    sys.exit(main())
