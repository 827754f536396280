"""Shard checksums: the sha256 a manifest records must catch a changed byte anywhere in a
shard, not only in the part a reader happens to look at first."""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import pytest

from zoo.data.info import check_shards
from zoo.files import sha256_file

SIZE = (5 << 19) + 123  # 2.5 MiB and a bit: three read blocks of 1 MiB, the last one partial


def test_sha256_file_is_the_sha256_of_the_whole_file(tmp_path: Path) -> None:
    (tmp_path / "abc").write_bytes(b"abc")  # FIPS 180-2's example digest
    assert sha256_file(tmp_path / "abc") == (
        "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
    )
    (tmp_path / "empty").write_bytes(b"")
    assert sha256_file(tmp_path / "empty") == hashlib.sha256(b"").hexdigest()
    data = np.random.default_rng(0).integers(0, 256, SIZE, dtype=np.uint8).tobytes()
    (tmp_path / "big").write_bytes(data)
    assert sha256_file(tmp_path / "big") == hashlib.sha256(data).hexdigest()


@pytest.mark.parametrize("where", [0, 1 << 20, 2 << 20, SIZE - 1])
def test_a_byte_changed_anywhere_in_a_shard_fails_its_checksum(tmp_path: Path, where: int) -> None:
    """One shard of 2.5 MiB: intact it passes; one byte flipped in its first, second or last
    read block (the very last byte included) and `zoo data info` reports it as bad."""
    data = bytearray(np.random.default_rng(1).integers(0, 256, SIZE, dtype=np.uint8).tobytes())
    shard = tmp_path / "crafterplay-000000.tar"
    shard.write_bytes(bytes(data))
    manifest = {"shards": [{"file": shard.name, "sha256": hashlib.sha256(data).hexdigest()}]}
    intact = check_shards(tmp_path, manifest)
    assert (len(intact.good), intact.bad) == (1, [])
    data[where] ^= 0x01
    shard.write_bytes(bytes(data))
    damaged = check_shards(tmp_path, manifest)
    assert damaged.good == []
    assert [file for file, _ in damaged.bad] == [str(shard)]
    assert damaged.bad[0][1].startswith("sha256 ")
