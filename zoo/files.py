"""The two file operations every writer in the zoo needs, written once.

``sha256_file`` is the checksum that manifests, export folders and pipeline records store.
``atomic_path`` / ``atomic_write_text`` write to a temp name beside the target and rename it
over the target only when complete: a killed job never leaves half a manifest, shard or
checkpoint that a reader or a resumed run would trust. Temp names end in ``.tmp-<pid>``, which
the writers' cleanups glob for.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
from collections.abc import Iterator
from pathlib import Path


def sha256_file(path: str | Path) -> str:
    """Hex sha256 of a file, read in 1 MiB blocks."""
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """A temp path beside ``path`` to write to; renamed onto ``path`` when the block ends
    without an error, removed when it raises."""
    path = Path(path)
    tmp = path.with_name(f"{path.name}.tmp-{os.getpid()}")
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def atomic_write_text(path: str | Path, text: str) -> None:
    """``Path.write_text`` that readers never see half done."""
    with atomic_path(path) as tmp:
        tmp.write_text(text)
