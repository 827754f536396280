"""argparse value types shared by the ``zoo`` subcommands, so every bad number reads alike, and
the flags they share that are not about agents or episodes: ``--out``, ``--no-progress``,
``--wandb`` and a config-driven trainer's ``--seed`` / ``--resume``."""

from __future__ import annotations

import argparse
from pathlib import Path


def _int(text: str, lowest: int, what: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
    if value < lowest:
        raise argparse.ArgumentTypeError(f"expected {what}, got {value}")
    return value


def positive_int(text: str) -> int:
    """An integer >= 1 (episodes, workers, steps)."""
    return _int(text, 1, "a positive integer")


def non_negative_int(text: str) -> int:
    """An integer >= 0 (seeds)."""
    return _int(text, 0, "an integer >= 0")


def existing_dir(text: str) -> Path:
    """A folder that exists (a dataset to read)."""
    path = Path(text)
    if not path.is_dir():
        raise argparse.ArgumentTypeError(f"{text} is not a folder")
    return path


def out_dir(text: str) -> Path:
    """A folder to write, made if missing; an existing file is refused."""
    path = Path(text)
    if path.exists() and not path.is_dir():
        raise argparse.ArgumentTypeError(f"{text} exists and is not a folder")
    return path


def add_out_flag(parser: argparse.ArgumentParser, what: str, default: str | None = None) -> None:
    """``--out``, the folder a command writes (``out_dir``: made if missing, a file refused);
    required unless ``default`` says where it goes without one."""
    parser.add_argument("--out", type=out_dir, required=default is None, metavar="DIR",
                        help=what if default is None else f"{what} (default {default})")


def add_progress_flag(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def add_wandb_flag(parser: argparse.ArgumentParser, what: str = "metrics") -> None:
    parser.add_argument("--wandb", action="store_true",
                        help=f"also log the {what} to W&B (offline unless WANDB_MODE is set)")


def add_run_flags(parser: argparse.ArgumentParser, total: str) -> None:
    """The flags of a trainer whose settings are a YAML config: ``--seed`` overrides the
    config's, ``--resume`` continues the newest checkpoint in ``--out`` up to ``total`` (the
    config field that ends the run), ``--wandb`` logs the curves."""
    parser.add_argument("--seed", type=non_negative_int, help="override the config's seed")
    parser.add_argument("--resume", action="store_true",
                        help=f"continue from the newest checkpoint in --out up to the config's "
                        f"{total}")
    add_wandb_flag(parser, "training curves")


def shard_range(text: str) -> tuple[int, int]:
    """``A:B``: CrafterPlay shard indices A..B-1 (either side may be left out)."""
    start, sep, stop = text.partition(":")
    try:
        if not sep:
            raise ValueError
        low, high = int(start or 0), int(stop) if stop else 1 << 31
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected A:B shard indices, got {text!r}") from None
    if low < 0 or high <= low:
        raise argparse.ArgumentTypeError(f"expected 0 <= A < B in A:B, got {text!r}")
    return low, high
