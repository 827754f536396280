"""argparse value types shared by the ``zoo`` subcommands, so every bad number reads alike, and
the ``--out`` folder flag they share."""

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
