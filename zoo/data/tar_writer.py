"""Tar bytes written the way CrafterPlay needs them: fixed headers, hashed while written, synced
in pieces, renamed into place only when whole; and a shard assembled from its episodes'
fragments in episode order while the episodes are still being played.
"""

from __future__ import annotations

import hashlib
import os
import tarfile
from collections import deque
from collections.abc import Iterable, Iterator
from pathlib import Path

_BLOCK = tarfile.BLOCKSIZE


def tar_member(name: str, data: bytes) -> bytes:
    """One regular-file tar member with a fixed header, padded to the 512-byte block."""
    info = tarfile.TarInfo(name)
    info.size, info.mtime, info.mode = len(data), 0, 0o644
    info.uid = info.gid = 0
    info.uname = info.gname = ""
    header = info.tobuf(tarfile.USTAR_FORMAT, "utf-8", "strict")
    return header + data + b"\0" * (-len(data) % _BLOCK)


def tar_trailer(size: int) -> bytes:
    """End-of-archive blocks, padded to tar's 10 KiB record as tarfile writes it."""
    end = size + 2 * _BLOCK
    return b"\0" * (2 * _BLOCK + (-end % tarfile.RECORDSIZE))


class TarWriter:
    """Tar member bytes written to a temp name beside ``path`` and hashed as they go;
    ``close`` adds the end-of-archive trailer, syncs and renames (a killed writer leaves no
    half file), ``discard`` removes the temp file. Written data is synced every
    ``sync_every`` bytes, so the final sync does not wait on a whole shard's disk writes."""

    def __init__(self, path: Path, sync_every: int = 32 << 20) -> None:
        self.path, self.sync_every = Path(path), sync_every
        self._tmp = self.path.with_name(f"{self.path.name}.tmp-{os.getpid()}")
        self._out = open(self._tmp, "wb")
        self._digest = hashlib.sha256()
        self._size = self._unsynced = 0

    def write(self, block: bytes) -> None:
        self._out.write(block)
        self._digest.update(block)
        self._size += len(block)
        self._unsynced += len(block)
        if self._unsynced >= self.sync_every:
            self._out.flush()
            os.fdatasync(self._out.fileno())
            self._unsynced = 0

    def close(self) -> str:
        """Finish the file; its sha256."""
        trailer = tar_trailer(self._size)
        self._out.write(trailer)
        self._digest.update(trailer)
        self._out.flush()
        os.fsync(self._out.fileno())
        self._out.close()
        os.replace(self._tmp, self.path)
        return self._digest.hexdigest()

    def discard(self) -> None:
        self._out.close()
        self._tmp.unlink(missing_ok=True)


def write_tar(path: Path, blocks: Iterable[bytes]) -> str:
    """Write tar member ``blocks`` and the trailer to ``path`` (``TarWriter``); its sha256."""
    writer = TarWriter(path)
    try:
        for block in blocks:
            writer.write(block)
        return writer.close()
    finally:
        writer.discard()  # a no-op once closed


class ShardAssembler:
    """A shard built while it is played: each episode's fragment goes in as soon as it and
    every episode before it are written, so when play ends only the last fragments, the
    trailer and the sync are left (before, the whole shard was copied, hashed and synced only
    then, on one core). ``add``, ``add_blocks`` and ``close`` run on one thread: the
    generator's encoder, after the fragment writes they follow."""

    def __init__(self, path: Path, episodes: Iterable[int]) -> None:
        self._writer = TarWriter(path)
        self._order = deque(episodes)
        self._ready: dict[int, Path] = {}

    def add(self, episode: int, fragment: Path) -> None:
        """Episode ``episode``'s fragment is complete at ``fragment`` (deleted once copied)."""
        self._ready[episode] = fragment
        self._drain()

    def _drain(self) -> None:
        """Copy in the fragments whose turn has come."""
        while self._order and self._order[0] in self._ready:
            path = self._ready.pop(self._order.popleft())
            with open(path, "rb") as f:
                for block in iter(lambda f=f: f.read(1 << 20), b""):
                    self._writer.write(block)
            path.unlink()

    def add_blocks(self, episode: int, blocks: Iterator[bytes], fragment: Path) -> None:
        """Episode ``episode``'s fragment as tar blocks: written straight into the shard when
        every episode before it is in (no fragment file to write, read back and delete), else
        to ``fragment`` until its turn."""
        if self._order and self._order[0] == episode:
            self._order.popleft()
            for block in blocks:
                self._writer.write(block)
            self._drain()
        else:
            with open(fragment, "wb") as out:
                out.writelines(blocks)
            self.add(episode, fragment)

    def close(self) -> str:
        """The shard, renamed into place; its sha256. RuntimeError if an episode is missing."""
        if self._order:
            raise RuntimeError(f"{self._writer.path}: episodes {list(self._order)} were never added")
        return self._writer.close()

    def discard(self) -> None:
        self._writer.discard()

    def __enter__(self) -> ShardAssembler:
        return self

    def __exit__(self, *exc) -> None:
        self.discard()  # after ``close``: nothing left to remove


def assemble_shard(fragments: Iterable[Path], path: Path) -> str:
    """Concatenate episode fragments, in order, into ``path``; return its sha256."""
    fragments = list(fragments)
    with ShardAssembler(path, range(len(fragments))) as assembler:
        for k, fragment in enumerate(fragments):
            assembler.add(k, fragment)
        return assembler.close()
