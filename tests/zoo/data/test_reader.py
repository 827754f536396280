"""Shard format round trip (synthetic episodes) and the reader's errors for damaged data."""

from __future__ import annotations

import io
import tarfile
import threading

import numpy as np
import pytest

from zoo.data.codec import FrameCodec, decode_arrays, decode_frames, encode_arrays, encode_frames
from zoo.data.reader import (
    CorruptShardError,
    ReadStats,
    decode_sample,
    iter_chunks,
    iter_episodes,
)
from zoo.data.shards import ChunkEncoder, EpisodeRecorder
from zoo.data.tar_writer import assemble_shard
from zoo.envs.schema import STATE_FIELDS, empty_state, index_state


def _random_episode(rng, n):
    frames = rng.integers(0, 256, (n, 144, 144, 3), dtype=np.uint8)
    state = empty_state(n)
    for name, arr in state.items():
        if arr.dtype == bool:
            state[name] = rng.random(arr.shape) < 0.5
        elif arr.dtype.kind == "f":
            state[name] = rng.random(arr.shape, dtype=np.float32)
        else:
            state[name] = rng.integers(0, 100, arr.shape).astype(arr.dtype)
    actions = rng.integers(0, 17, n - 1)
    rewards = rng.normal(size=n - 1).astype(np.float32)
    noop = rng.random(n - 1) < 0.5
    return frames, state, actions, rewards, noop


def _write_shard(tmp_path, name, episodes, chunk_length=4):
    fragments = []
    with ChunkEncoder(max_pending=1) as encoder:
        for index, (frames, state, actions, rewards, noop) in episodes.items():
            rec = EpisodeRecorder(index, 100 + index, tmp_path, chunk_length,
                                  {"env": "craftax", "expert": "random"}, encoder, FrameCodec())
            for t in range(len(frames)):
                rec.observe(frames[t], index_state(state, t))
                if t < len(actions):
                    rec.act(int(actions[t]), float(rewards[t]), bool(noop[t]))
            rec.finish()
            fragments.append(rec.fragment)
    path = tmp_path / name
    assemble_shard(fragments, path)
    return str(path)


@pytest.fixture(scope="module")
def shards(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("shards")
    rng = np.random.default_rng(0)
    data = {0: _random_episode(rng, 10), 1: _random_episode(rng, 4), 2: _random_episode(rng, 7)}
    a = _write_shard(tmp, "crafterplay-000000.tar", {0: data[0], 1: data[1]})
    b = _write_shard(tmp, "crafterplay-000001.tar", {2: data[2]})
    return data, [a, b]


def test_frames_and_arrays_round_trip_bit_exact():
    rng = np.random.default_rng(1)
    frames = rng.integers(0, 256, (5, 144, 144, 3), dtype=np.uint8)
    np.testing.assert_array_equal(decode_frames(encode_frames(frames), 5), frames)
    arrays = {"a": np.arange(6, dtype=np.int16).reshape(2, 3), "b": np.array([True, False])}
    back = decode_arrays(encode_arrays(arrays))
    assert list(back) == ["a", "b"]
    for k in arrays:
        np.testing.assert_array_equal(back[k], arrays[k])
        assert back[k].dtype == arrays[k].dtype


def test_object_arrays_are_refused():
    buf = io.BytesIO()
    buf.write(b'["x"]\n')
    np.lib.format.write_array(buf, np.array([{"a": 1}], dtype=object), allow_pickle=True)
    with pytest.raises(ValueError, match="pickle"):
        decode_arrays(FrameCodec().compressor().compress(buf.getvalue()))


def test_shard_round_trip_bit_exact(shards):
    data, urls = shards
    chunks = list(iter_chunks(urls))
    assert [(c["meta"]["episode"], c["meta"]["offset"]) for c in chunks] == [
        (0, 0), (0, 4), (0, 8), (1, 0), (2, 0), (2, 4)
    ]
    episodes = list(iter_episodes(urls))
    for ep in episodes:
        frames, state, actions, rewards, noop = data[ep["meta"]["episode"]]
        np.testing.assert_array_equal(ep["frames"], frames)
        for name in STATE_FIELDS:
            np.testing.assert_array_equal(ep["state"][name], state[name], name)
            assert ep["state"][name].dtype == state[name].dtype
        assert ep["actions"].tolist() == [*actions.tolist(), -1]
        np.testing.assert_array_equal(ep["rewards"], [*rewards, 0])
        assert ep["noop"].tolist() == [*noop.tolist(), False]
        assert ep["meta"]["seed"] == 100 + ep["meta"]["episode"]
        assert ep["meta"]["episode_length"] == len(frames)


def test_noop_runs_span_chunks(shards):
    _, urls = shards
    for chunk in iter_chunks(urls):
        ep = chunk["meta"]["episode"]
        whole = next(e for e in iter_episodes(urls) if e["meta"]["episode"] == ep)
        part = slice(chunk["meta"]["offset"], chunk["meta"]["offset"] + chunk["meta"]["length"])
        assert chunk["noop_run"].tolist() == whole["noop_run"][part].tolist()


def test_same_content_same_bytes(shards, tmp_path):
    data, urls = shards
    again = _write_shard(tmp_path, "x.tar", {0: data[0], 1: data[1]})
    assert open(again, "rb").read() == open(urls[0], "rb").read()
    with tarfile.open(again) as tar:
        assert {(m.mtime, m.uid, m.mode) for m in tar.getmembers()} == {(0, 0, 0o644)}


def _damaged(tmp_path, url, cut):
    path = tmp_path / "crafterplay-000000.tar"
    path.write_bytes(open(url, "rb").read()[:cut])
    return str(path)


@pytest.mark.parametrize("cut", [3000, "member_boundary"])
def test_truncated_shard_error_names_file(shards, tmp_path, cut):
    _, urls = shards
    if cut == "member_boundary":  # end the shard exactly before episode 0's last chunk
        with tarfile.open(urls[0]) as tar:
            last = [m for m in tar.getmembers() if m.name.startswith("e0000000_000008")][0]
            cut = last.offset
    bad = _damaged(tmp_path, urls[0], cut)
    with pytest.raises(CorruptShardError, match=f"{bad}: .*(corrupt|truncated)"):
        list(iter_chunks([bad, urls[1]]))


def test_skip_corrupt_counts_and_reads_on(shards, tmp_path):
    _, urls = shards
    bad = _damaged(tmp_path, urls[0], 3000)
    stats = ReadStats()
    episodes = list(iter_episodes([bad, urls[1]], skip_corrupt=True, stats=stats))
    assert [e["meta"]["episode"] for e in episodes] == [2]
    assert stats.num_skipped == 1 and stats.skipped_shards == [bad]


def _sample(shards):
    _, urls = shards
    with tarfile.open(urls[1]) as tar:
        members = [m for m in tar.getmembers() if m.name.startswith("e0000002_000000")]
        sample = {m.name.split(".", 1)[1]: tar.extractfile(m).read() for m in members}
    return {**sample, "__key__": "e0000002_000000", "__url__": urls[1]}


def test_decode_sample_missing_field(shards):
    sample = _sample(shards)
    del sample["state.zst"]
    with pytest.raises(ValueError, match=r"e0000002_000000: missing fields \['state.zst'\]"):
        decode_sample(sample)


def test_decode_sample_wrong_shape(shards):
    sample = _sample(shards)
    state = decode_arrays(sample["state.zst"])
    state["map"] = state["map"][:, :32]
    sample["state.zst"] = encode_arrays(state)
    with pytest.raises(ValueError, match=r"'map' has shape \(4, 32, 64\), expected \(4, 64, 64\)"):
        decode_sample(sample)


def test_chunk_encoder_bounds_queued_chunks_but_not_other_jobs():
    # A broken bound must fail, not hang: the first job is always released (leaving the
    # block shuts the encoder down, which waits for it), every wait has a timeout and the
    # submitting thread is a daemon, so one stuck forever cannot keep pytest alive.
    release, submitted = threading.Event(), threading.Event()
    with ChunkEncoder(max_pending=1) as encoder:

        def submit_second() -> None:
            encoder.submit_chunk(int)
            submitted.set()

        blocked = threading.Thread(target=submit_second, daemon=True)
        try:
            encoder.submit_chunk(release.wait, 10)
            small = encoder.submit(int)  # a fragment write or an append: never waits
            blocked.start()
            assert not submitted.wait(0.2)  # the second chunk waits for the first to finish
            assert not small.done()  # queued behind the first chunk, in submission order
        finally:
            release.set()
        assert submitted.wait(5)
        blocked.join(5)
        assert small.result(5) == 0
