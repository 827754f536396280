"""The frame encoder's numba layout against the numpy re-layout it replaced (kept here only):
the same bytes before zstd, so the same zstd bytes, and the same frames decoded."""

from __future__ import annotations

import tarfile

import numpy as np
import pytest

from zoo.data.codec import (
    FrameCodec,
    compact_planes,
    compress_planes,
    decode_frames,
    encode_frames,
    tile_frames,
)
from zoo.data.shards import (
    STATE_ROW_BYTES,
    BufferPool,
    ChunkEncoder,
    EpisodeRecorder,
    state_views,
)
from zoo.data.tar_writer import assemble_shard
from zoo.envs.schema import STATE_FIELDS, empty_state, index_state

TILE, GRID = 16, 9


def reference_planes(frames: np.ndarray) -> np.ndarray:
    """The numpy encoder's layout before zstd: channel-planar (R, G-R, B-G), tile-major."""
    n = len(frames)
    tiles = frames.reshape(n, GRID, TILE, GRID, TILE, 3).transpose(5, 0, 1, 3, 2, 4)
    planes = np.ascontiguousarray(tiles)  # (3, n, 9, 9, 16, 16)
    planes[2] -= planes[1]
    planes[1] -= planes[0]
    return planes


def reference_encode(frames: np.ndarray, codec: FrameCodec | None = None) -> bytes:
    codec = FrameCodec() if codec is None else codec
    return codec.compressor().compress(reference_planes(frames).tobytes())


@pytest.fixture(scope="module")
def real_frames(craftax_env) -> np.ndarray:
    """70 Craftax frames of random play (2 envs x 35 steps), the last 10 with a band of noise
    (as incompressible as night static)."""
    rng = np.random.default_rng(0)
    step = craftax_env.reset(np.array([3, 4]))
    frames = [step.frames]
    for _ in range(34):
        step = craftax_env.step(rng.integers(0, 17, 2))
        frames.append(step.frames)
    frames = np.concatenate(frames)
    frames[-10:, 40:100] = rng.integers(0, 256, (10, 60, 144, 3), dtype=np.uint8)  # noisy
    return frames


def _random_frames(n: int, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 256, (n, 144, 144, 3), dtype=np.uint8)


@pytest.mark.parametrize("n", [0, 1, 2, 7, 33])
def test_layout_and_bytes_match_the_numpy_encoder_on_random_frames(n):
    frames = _random_frames(n, seed=n)
    planes = np.empty((3, n, GRID, GRID, TILE, TILE), np.uint8)
    tile_frames(frames, planes)
    assert planes.tobytes() == reference_planes(frames).tobytes()
    coded = encode_frames(frames)
    assert coded == reference_encode(frames)
    np.testing.assert_array_equal(decode_frames(coded, n), frames)


@pytest.mark.parametrize("n", [0, 5, 40])
def test_a_recycled_layout_buffer_gives_the_same_bytes(n):
    # the encoder lays each stored chunk out in a pooled (3, L, ...) buffer holding old bytes
    frames = _random_frames(n, seed=n)
    out = np.random.default_rng(1).integers(0, 256, (3, 40, GRID, GRID, TILE, TILE), np.uint8)
    assert encode_frames(frames, out=out) == encode_frames(frames) == reference_encode(frames)


def test_layout_and_bytes_match_the_numpy_encoder_on_a_real_chunk(real_frames):
    frames = real_frames
    planes = np.empty((3, len(frames), GRID, GRID, TILE, TILE), np.uint8)
    for i, frame in enumerate(frames):  # frame by frame, as a recorder lays them out
        tile_frames(frame[None], planes, i)
    assert planes.tobytes() == reference_planes(frames).tobytes()
    codec = FrameCodec(level=3, window_log=24)  # another codec: same settings both ways
    assert compress_planes(planes, codec) == reference_encode(frames, codec)
    coded = encode_frames(frames)
    assert coded == reference_encode(frames)
    np.testing.assert_array_equal(decode_frames(coded, len(frames)), frames)


@pytest.mark.parametrize("length", [1, 2, 5, 16])
def test_a_short_chunk_compacted_in_its_buffer(length):
    frames = _random_frames(length, seed=100 + length)
    for n in range(length + 1):
        buffer = np.full((3, length, GRID, GRID, TILE, TILE), 7, np.uint8)
        tile_frames(frames[:n], buffer)
        planes = compact_planes(buffer, n)
        assert np.shares_memory(planes, buffer) or n == 0
        assert planes.tobytes() == reference_planes(frames[:n]).tobytes()
        assert compress_planes(planes) == reference_encode(frames[:n])


def test_tile_frames_refuses_what_does_not_fit():
    planes = np.empty((3, 4, GRID, GRID, TILE, TILE), np.uint8)
    with pytest.raises(ValueError, match="do not fit"):
        tile_frames(_random_frames(2), planes, 3)
    with pytest.raises(ValueError, match="frames must be uint8"):
        tile_frames(np.zeros((1, 144, 144, 3), np.int16), planes)
    with pytest.raises(ValueError, match="C-contiguous"):
        tile_frames(_random_frames(1), planes[:, ::2])


def test_state_rows_hold_every_field_exactly():
    rng = np.random.default_rng(0)
    state = empty_state(5)
    for name, arr in state.items():
        if arr.dtype == bool:
            state[name] = rng.random(arr.shape) < 0.5
        else:
            info = np.finfo(arr.dtype) if arr.dtype.kind == "f" else np.iinfo(arr.dtype)
            state[name] = rng.uniform(info.min / 2, info.max / 2, arr.shape).astype(arr.dtype)
    rows = np.zeros((5, STATE_ROW_BYTES), np.uint8)
    for name, view in state_views(rows).items():
        view[...] = state[name]
    back = state_views(rows.copy())
    assert set(back) == set(STATE_FIELDS)
    for name in STATE_FIELDS:
        assert back[name].dtype == STATE_FIELDS[name].dtype
        np.testing.assert_array_equal(back[name], state[name], name)


def _chunk_members(path) -> dict[str, bytes]:
    with tarfile.open(path) as tar:
        return {m.name: tar.extractfile(m).read() for m in tar.getmembers()}


def test_recorded_frames_are_the_numpy_encoders_bytes(real_frames, tmp_path):
    """Frames laid out as they arrive, in recycled buffers, code as the numpy path coded the
    whole chunk, full chunks and the short last one alike, over two shards sharing a pool."""
    frames = real_frames[:23]
    state = empty_state(len(frames))
    state["timestep"][:] = np.arange(len(frames))
    pool = BufferPool()
    shape = (3, 8, GRID, GRID, TILE, TILE)
    spares = []
    for shard in range(2):  # the second shard reuses the first one's buffers
        with ChunkEncoder(max_pending=1, pool=pool) as encoder:
            rec = EpisodeRecorder(0, 1, tmp_path, 8, {"env": "craftax", "expert": "random"},
                                  encoder, FrameCodec())
            for t in range(len(frames)):
                rec.observe(frames[t], index_state(state, t))
                if t + 1 < len(frames):
                    rec.act(0, 0.0, False)
            rec.finish().result()
            assert rec.final_state["timestep"] == len(frames) - 1
        members = _chunk_members(rec.fragment)
        for start in (0, 8, 16):
            coded = members[f"e0000000_{start:06d}.frames.zst"]
            assert coded == reference_encode(frames[start:start + 8])
        assemble_shard([rec.fragment], tmp_path / f"s{shard}.tar")
        spares.append(len(pool._spare[shape]))
    assert spares[0] == spares[1] > 0  # given back after the first shard, none new after
