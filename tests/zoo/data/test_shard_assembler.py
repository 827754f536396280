"""A shard assembled while it is played: fragments arrive in finish order, the shard holds
them in episode order, and a failed run leaves no shard behind."""

import hashlib
import tarfile

import pytest

from zoo.data.tar_writer import ShardAssembler, TarWriter, tar_member, tar_trailer, write_tar


def _fragments(tmp_path, count: int) -> list:
    paths = []
    for e in range(count):
        path = tmp_path / f"e{e}.tar"
        path.write_bytes(tar_member(f"e{e}.meta.json", f'{{"episode": {e}}}'.encode() * (e + 1)))
        paths.append(path)
    return paths


def test_fragments_added_out_of_order_give_the_in_order_shard(tmp_path):
    fragments = _fragments(tmp_path, 4)
    expected = b"".join(p.read_bytes() for p in fragments)
    expected += tar_trailer(len(expected))
    shard = tmp_path / "shard.tar"
    with ShardAssembler(shard, [10, 11, 12, 13]) as assembler:
        for e in (12, 10, 13, 11):  # the order episodes might finish in
            assembler.add(e, fragments[e - 10])
        sha = assembler.close()
    assert shard.read_bytes() == expected
    assert sha == hashlib.sha256(expected).hexdigest()
    assert not any(p.exists() for p in fragments)  # each is deleted once copied
    with tarfile.open(shard) as tar:
        assert tar.getnames() == [f"e{e}.meta.json" for e in range(4)]


def test_blocks_go_straight_in_at_their_turn_and_wait_in_a_file_before_it(tmp_path):
    blocks = {e: [tar_member(f"e{e}.{k}", bytes([e, k]) * 700) for k in range(3)] for e in range(4)}
    expected = b"".join(b for e in range(4) for b in blocks[e])
    expected += tar_trailer(len(expected))
    spills = {e: tmp_path / f"e{e}.tar" for e in range(4)}
    shard = tmp_path / "shard.tar"
    with ShardAssembler(shard, range(4)) as assembler:
        assembler.add_blocks(1, iter(blocks[1]), spills[1])  # early: waits in its file
        assert spills[1].read_bytes() == b"".join(blocks[1])
        assembler.add_blocks(0, iter(blocks[0]), spills[0])  # its turn: no file, then 1 too
        assert not spills[0].exists() and not spills[1].exists()
        spills[3].write_bytes(b"".join(blocks[3]))
        assembler.add(3, spills[3])  # a fragment file and blocks mix
        assembler.add_blocks(2, iter(blocks[2]), spills[2])
        sha = assembler.close()
    assert shard.read_bytes() == expected
    assert sha == hashlib.sha256(expected).hexdigest()
    assert list(tmp_path.iterdir()) == [shard]


def test_a_missing_episode_fails_close_and_leaves_no_shard(tmp_path):
    fragments = _fragments(tmp_path, 2)
    shard = tmp_path / "shard.tar"
    with pytest.raises(RuntimeError, match=r"episodes \[1\] were never added"):
        with ShardAssembler(shard, [0, 1]) as assembler:
            assembler.add(0, fragments[0])
            assembler.close()
    assert list(tmp_path.glob("shard.tar*")) == []


def test_write_tar_and_a_writer_synced_in_pieces_write_and_hash_the_same_bytes(tmp_path):
    blocks = [tar_member(f"m{k}", bytes([k]) * 3000) for k in range(5)]
    path = tmp_path / "t.tar"
    sha = write_tar(path, blocks)
    assert sha == hashlib.sha256(path.read_bytes()).hexdigest()
    writer = TarWriter(tmp_path / "u.tar", sync_every=4096)  # a sync every other member
    for block in blocks:
        writer.write(block)
    assert writer.close() == sha
    assert (tmp_path / "u.tar").read_bytes() == path.read_bytes()
    assert list(tmp_path.glob("*.tmp-*")) == []
