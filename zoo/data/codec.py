"""Byte encodings of one CrafterPlay sample: lossless frames, npy array streams, JSON meta.

Frames (both games draw them from 16-pixel textures, then blend in daylight and, at night,
grey random static) are stored as zstd of a reversible re-layout, chosen on scripted
Craftax play, random Craftax and random crafter play (docs/data.md):
- channels decorrelated to (R, G-R, B-G) mod 256: the static is grey, so only R keeps it
  and night frames shrink;
- channel-planar over the chunk, and tile-major inside a plane (each 16x16 block contiguous),
  so a repeated tile is one long zstd match; a 32 MB window spans a 256-step chunk.
The re-layout is one numba pass per frame (``tile_frames``, a fraction of the cost of numpy
transposes, differences and copies), so a recorder lays each frame out as it arrives and its
encoder thread only runs zstd (which releases the GIL).
Arrays are a stream of ``.npy`` records read back with ``allow_pickle=False``: no pickle.
"""

from __future__ import annotations

import io
import json
import threading
from dataclasses import dataclass

import numba
import numpy as np
import zstandard

from zoo.envs.schema import FRAME_SHAPE

TILE = 16
_GRID = FRAME_SHAPE[0] // TILE
PLANES_SHAPE = (3, _GRID, _GRID, TILE, TILE)
"""A chunk's coded layout is (3, n, 9, 9, 16, 16): channel, frame, tile row, tile column, y, x."""
_ROW_BYTES = FRAME_SHAPE[1] * 3
_TILE_WORDS = TILE // 8  # a tile row's 16 bytes as uint64 words


@dataclass(frozen=True)
class FrameCodec:
    """zstd settings for frames and arrays.

    Args:
        level: zstd level; 2 encodes faster than 3 for a few more bytes on scripted play.
        window_log: log2 of the match window; 25 (32 MB) spans a 256-step chunk of frames.
    """

    level: int = 2
    window_log: int = 25

    def compressor(self) -> zstandard.ZstdCompressor:
        params = zstandard.ZstdCompressionParameters.from_level(
            self.level, window_log=self.window_log
        )
        return zstandard.ZstdCompressor(compression_params=params)


def _decompress(data: bytes, what: str) -> bytes:
    try:
        return zstandard.ZstdDecompressor().decompress(data)
    except zstandard.ZstdError as err:
        raise ValueError(f"{what}: not valid zstd data ({err})") from err


@numba.njit(cache=True, boundscheck=False)
def _tile_frame(frame, r, g, b, row_buf, row_words):
    """One frame's (R, G-R, B-G) planes, tile-major, as uint64 words: each image row is split
    into channels in a 432-byte buffer (a loop LLVM vectorises with byte shuffles), then its
    nine 16-byte tile rows are copied to their tiles, two words each."""
    for yy in range(FRAME_SHAPE[0]):
        start = np.uint64(yy * _ROW_BYTES)
        for c in range(np.uint64(FRAME_SHAPE[1])):  # unsigned: no negative-index wrap check
            red = frame[start + np.uint64(3) * c]
            green = frame[start + np.uint64(3) * c + np.uint64(1)]
            blue = frame[start + np.uint64(3) * c + np.uint64(2)]
            row_buf[0, c] = red
            row_buf[1, c] = green - red  # uint8 wraps: reversible
            row_buf[2, c] = blue - green
        first = (yy // TILE * _GRID * TILE + yy % TILE) * _TILE_WORDS
        for col in range(_GRID):
            out = first + col * TILE * _TILE_WORDS
            for w in range(_TILE_WORDS):
                r[out + w] = row_words[0, col * _TILE_WORDS + w]
                g[out + w] = row_words[1, col * _TILE_WORDS + w]
                b[out + w] = row_words[2, col * _TILE_WORDS + w]


def _tile_loop(frames, planes, offset):
    row_buf = np.empty((3, FRAME_SHAPE[1]), np.uint8)
    row_words = row_buf.view(np.uint64)
    words = planes.reshape(3, planes.shape[1], -1)
    for i in range(frames.shape[0]):
        _tile_frame(
            frames[i].reshape(-1), words[0, offset + i].view(np.uint64),
            words[1, offset + i].view(np.uint64), words[2, offset + i].view(np.uint64),
            row_buf, row_words,
        )


# A frame takes microseconds: a call that let go of the GIL for it would hand the GIL to a waiting
# thread and wait to get it back (up to the 5 ms switch interval). Batches of frames do.
_tile_frames = numba.njit(cache=True, boundscheck=False)(_tile_loop)
_tile_frames_nogil = numba.njit(cache=True, nogil=True, boundscheck=False)(_tile_loop)


def tile_frames(frames: np.ndarray, planes: np.ndarray, offset: int = 0) -> None:
    """Write (k, 144, 144, 3) uint8 ``frames`` into ``planes[:, offset:offset + k]`` of a
    C-contiguous (3, L, 9, 9, 16, 16) uint8 buffer: ``encode_frames``' layout before zstd."""
    if frames.dtype != np.uint8 or frames.shape[1:] != FRAME_SHAPE:
        raise ValueError(
            f"frames must be uint8 (n, {FRAME_SHAPE}), got {frames.dtype} {frames.shape}"
        )
    if (planes.dtype != np.uint8 or planes.ndim != 6 or planes.shape[0] != 3
            or planes.shape[2:] != PLANES_SHAPE[1:] or not planes.flags.c_contiguous):
        raise ValueError(f"planes must be C-contiguous uint8 (3, L, 9, 9, 16, 16), got "
                         f"{planes.dtype} {planes.shape}")
    if not 0 <= offset <= planes.shape[1] - len(frames):
        raise ValueError(f"{len(frames)} frames at {offset} do not fit {planes.shape[1]} slots")
    kernel = _tile_frames if len(frames) < 8 else _tile_frames_nogil
    kernel(np.ascontiguousarray(frames), planes, offset)


_COMPRESSORS = threading.local()


def _compressor(codec: FrameCodec) -> zstandard.ZstdCompressor:
    """This thread's compressor for ``codec`` (one per thread: they are not thread-safe)."""
    cache = _COMPRESSORS.__dict__.setdefault("by_codec", {})
    if codec not in cache:
        cache[codec] = codec.compressor()
    return cache[codec]


def compact_planes(planes: np.ndarray, n: int) -> np.ndarray:
    """The first n frames of a C-contiguous (3, L, 9, 9, 16, 16) buffer as a contiguous
    (3, n, ...) array, moved to the buffer's front in place (no new 16 MB array: its pages
    would fault); the rest of the buffer is left undefined."""
    length = planes.shape[1]
    if not planes.flags.c_contiguous or not 0 <= n <= length:
        raise ValueError(f"need a C-contiguous buffer of at least {n} frames, got {planes.shape}")
    flat, frame = planes.reshape(-1), int(np.prod(planes.shape[2:]))
    for c in (1, 2) if n < length else ():  # plane c moves down by c * (length - n) frames,
        step = c * (length - n)  # in pieces no longer than that: a piece never overlaps
        for start in range(0, n, step):
            stop = min(start + step, n)
            flat[(c * n + start) * frame:(c * n + stop) * frame] = (
                flat[(c * length + start) * frame:(c * length + stop) * frame])
    return flat[:3 * n * frame].reshape(3, n, *planes.shape[2:])


def compress_planes(planes: np.ndarray, codec: FrameCodec = FrameCodec()) -> bytes:
    """zstd of C-contiguous (3, n, 9, 9, 16, 16) planes laid out by ``tile_frames``."""
    if planes.shape[0] != 3 or planes.shape[2:] != PLANES_SHAPE[1:]:
        raise ValueError(f"planes must be (3, n, 9, 9, 16, 16), got {planes.shape}")
    return _compressor(codec).compress(np.ascontiguousarray(planes, np.uint8))


def encode_frames(
    frames: np.ndarray, codec: FrameCodec = FrameCodec(), out: np.ndarray | None = None
) -> bytes:
    """(n, 144, 144, 3) uint8 -> zstd of the decorrelated, planar, tile-major bytes. ``out``:
    a (3, L >= n, 9, 9, 16, 16) buffer to lay them out in (a recycled one: a fresh 16 MB
    array page-faults on its first fill); its contents are left undefined."""
    if frames.dtype != np.uint8 or frames.shape[1:] != FRAME_SHAPE:
        raise ValueError(
            f"frames must be uint8 (n, {FRAME_SHAPE}), got {frames.dtype} {frames.shape}"
        )
    if out is None:
        out = np.empty((3, len(frames), *PLANES_SHAPE[1:]), np.uint8)
    tile_frames(frames, out)
    return compress_planes(compact_planes(out, len(frames)), codec)


@numba.njit(cache=True, nogil=True, boundscheck=False)
def _untile_frames(planes, frames):
    """``tile_frames`` undone: (3, n, 9, 9, 16, 16) planes of (R, G-R, B-G) into (n, 144, 144,
    3) frames, one pass in the frames' order (numpy transposes would take several times as
    long, a large share of a training loader's time)."""
    for i in range(planes.shape[1]):
        for row in range(_GRID):
            for y in range(TILE):
                for col in range(_GRID):
                    for x in range(TILE):
                        red = planes[0, i, row, col, y, x]
                        green = np.uint8(planes[1, i, row, col, y, x] + red)  # uint8 wraps back
                        pixel = frames[i, row * TILE + y, col * TILE + x]
                        pixel[0] = red
                        pixel[1] = green
                        pixel[2] = np.uint8(planes[2, i, row, col, y, x] + green)


def decode_frames(data: bytes, n: int) -> np.ndarray:
    """Inverse of ``encode_frames`` for ``n`` frames."""
    raw = _decompress(data, "frames")
    expected = n * int(np.prod(FRAME_SHAPE))
    if len(raw) != expected:
        raise ValueError(f"frames: {len(raw)} bytes decoded, expected {expected} for {n} frames")
    planes = np.frombuffer(raw, np.uint8).reshape(3, n, _GRID, _GRID, TILE, TILE)
    frames = np.empty((n, *FRAME_SHAPE), np.uint8)
    _untile_frames(planes, frames)
    return frames


def encode_arrays(arrays: dict[str, np.ndarray], codec: FrameCodec = FrameCodec()) -> bytes:
    """Named arrays -> zstd of a JSON line of names followed by one ``.npy`` record each."""
    buf = io.BytesIO()
    buf.write(json.dumps(list(arrays)).encode() + b"\n")
    for arr in arrays.values():
        np.lib.format.write_array(buf, np.ascontiguousarray(arr), allow_pickle=False)
    return _compressor(codec).compress(buf.getvalue())


def decode_arrays(data: bytes, what: str = "arrays") -> dict[str, np.ndarray]:
    """Inverse of ``encode_arrays``; refuses object arrays (no pickle)."""
    buf = io.BytesIO(_decompress(data, what))
    try:
        names = json.loads(buf.readline())
        return {name: np.lib.format.read_array(buf, allow_pickle=False) for name in names}
    except (ValueError, json.JSONDecodeError) as err:
        raise ValueError(f"{what}: malformed npy stream ({err})") from err


def encode_json(obj: dict) -> bytes:
    """Canonical JSON (sorted keys) so equal metadata gives equal bytes."""
    return json.dumps(obj, sort_keys=True, separators=(",", ":")).encode()
