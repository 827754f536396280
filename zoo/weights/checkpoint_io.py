"""Read a ``torch.save`` file safely, with one error that names the file and what is wrong.

Every checkpoint read in ``zoo`` goes through ``read_torch_file``: it loads with
``weights_only=True`` (tensors and plain values only) because unpickling anything else from a
file runs code from it. torch's own errors for a bad file advise loading with
``weights_only=False``; that advice must never reach a user, so a failure becomes a
``CheckpointError`` saying what the file is and what was expected instead.
"""

from __future__ import annotations

import re
from pathlib import Path

import torch

ZOO_CHECKPOINT = "a `zoo fit` checkpoint (.ckpt) or a `zoo export` folder"
ZIP_MAGIC = b"PK\x03\x04"


class CheckpointError(ValueError):
    """A file given as a checkpoint is not one we can read: a user error, reported in one line."""


def read_torch_file(path: str | Path, expected: str = ZOO_CHECKPOINT, mmap: bool = False) -> dict:
    """The dict ``torch.save`` wrote at ``path``, loaded on the CPU with ``weights_only=True``.

    ``expected`` says what the caller wanted, for the error; ``mmap`` maps tensors instead of
    reading them (for reading a few numbers out of a large checkpoint).
    """
    path = Path(path)
    if path.is_dir():
        raise CheckpointError(f"{path} is a folder, not a file; expected {expected}")
    if not path.is_file():
        raise FileNotFoundError(f"checkpoint {path} does not exist")
    try:
        loaded = torch.load(path, map_location="cpu", weights_only=True, mmap=mmap)
    except Exception as err:  # noqa: BLE001 - torch.load raises many kinds on bad bytes
        why = _why_unreadable(path, err)
        raise CheckpointError(f"{path}: {why}; expected {expected}") from None
    if not isinstance(loaded, dict):
        raise CheckpointError(
            f"{path}: holds a {type(loaded).__name__}, not a checkpoint dict; expected {expected}"
        )
    return loaded


def _why_unreadable(path: Path, err: Exception) -> str:
    """The problem in a few words, from the file itself; torch's message only names a refused
    class (the rest of it is internal detail or the unsafe advice)."""
    if path.stat().st_size == 0:
        return "not a readable checkpoint (empty file)"
    with path.open("rb") as file:
        if file.read(len(ZIP_MAGIC)) != ZIP_MAGIC:  # what every torch.save since torch 1.6 writes
            return "not a readable checkpoint (not a torch zip archive)"
    refused = re.search(r"Unsupported global: GLOBAL (\S+)", str(err))
    if refused:
        return (f"holds a pickled Python object ({refused.group(1)}) that a weights-only load "
                "refuses, since unpickling it would run code from the file")
    return "not a readable checkpoint (truncated or corrupt torch zip archive)"
