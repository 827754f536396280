"""Writing CrafterPlay shards: episodes recorded chunk by chunk, then laid out as tar bytes.

Raw frames never pile up: a chunk of L steps is compressed and appended to the episode's
spool file as soon as it is full. Stored frames are copied into a buffer the encoder
recycles; the encoder lays each chunk out for the codec (``tile_frames``) and runs zstd.
Chunk metadata (``episode_length``, ``last``) and noop runs are only known when the episode
ends, so samples are assembled then, into one tar fragment per episode; the shard is those
fragments in episode order plus the tar trailer.
Every tar header is fixed (mtime 0, uid 0, mode 644) so a shard's bytes depend on its
content alone. A chunk stores its frames as images (FRAMES) or, in the ``rendered`` mode, as
residuals against re-renders from its states (RESIDUAL + RENDER, see ``zoo.data.rerender``).
"""

from __future__ import annotations

import mmap
import os
import threading
from collections import deque
from collections.abc import Callable, Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path

import numpy as np

from zoo.data.codec import (
    PLANES_SHAPE,
    FrameCodec,
    encode_arrays,
    encode_frames,
    encode_json,
)
from zoo.data.noop import noop_runs
from zoo.data.rerender import encode_rendered, render_frames
from zoo.data.tar_writer import tar_member
from zoo.envs.schema import FRAME_SHAPE, STATE_FIELDS, State

SHARD_PATTERN = "crafterplay-{index:06d}.tar"
FRAMES, STATE, STEPS, META = "frames.zst", "state.zst", "steps.zst", "meta.json"
RESIDUAL, RENDER = "residual.zst", "render.zst"  # rendered chunks: in place of FRAMES


def sample_key(episode: int, offset: int) -> str:
    """WebDataset key of the chunk of ``episode`` starting at step ``offset``."""
    return f"e{episode:07d}_{offset:06d}"


def _state_layout() -> tuple[dict[str, tuple[int, int]], int]:
    """Byte range of each state field in a packed step, widest dtypes first (all aligned)."""
    layout, start = {}, 0
    for name, f in sorted(STATE_FIELDS.items(), key=lambda kv: -np.dtype(kv[1].dtype).itemsize):
        size = np.dtype(f.dtype).itemsize * int(np.prod(f.shape))
        layout[name], start = (start, start + size), start + size
    return layout, start


_STATE_LAYOUT, STATE_ROW_BYTES = _state_layout()
"""A step's exported state packed in one row of bytes: a recorder copies an observation in one
assignment instead of one per field, the generator packing its envs' states
together (``state_views``)."""


def state_views(rows: np.ndarray) -> State:
    """The state fields of (n, STATE_ROW_BYTES) uint8 ``rows``, as writable views."""
    n = len(rows)
    return {
        k: rows[:, a:b].view(STATE_FIELDS[k].dtype).reshape(n, *STATE_FIELDS[k].shape)
        for k, (a, b) in _STATE_LAYOUT.items()
    }


def _unpack_states(rows: np.ndarray, n: int) -> State:
    views = state_views(rows[:n])
    return {k: np.ascontiguousarray(views[k]) for k in STATE_FIELDS}


def _spool_chunk(
    path: Path, n: int, frames: np.ndarray | None, rows: np.ndarray,
    state_rng: np.ndarray | None, rendered: bool, codec: FrameCodec,
    pool: BufferPool | None = None,
) -> tuple[int, list[tuple[str, int]], dict]:
    """Compress a chunk of n steps and append it to the spool; returns (offset,
    [(member, bytes)], the chunk's extra meta). ``rows``: the steps' packed states. Stored
    chunks are laid out here, off the playing thread, in one numba pass that lets go of the
    GIL (``tile_frames``); ``rendered`` chunks store their frames as residuals against
    re-renders. ``frames`` None (the env drew none: a state-only expert played Craftax): a
    stored chunk's frames are drawn here from the states and ``state_rng``, also off the
    playing thread. Buffers go back to ``pool`` once coded."""
    state = _unpack_states(rows, n)
    if not rendered:
        if frames is None:  # bit-exact with the env's own frames (zoo.data.rerender)
            shape = (len(rows), *FRAME_SHAPE)
            frames = np.empty(shape, np.uint8) if pool is None else pool.take(shape)
            render_frames(state, state_rng, out=frames[:n])
        planes = None if pool is None else pool.take((3, len(frames), *PLANES_SHAPE[1:]))
        members, meta = {FRAMES: encode_frames(frames[:n], codec, planes)}, {}
        if pool is not None:
            pool.give(planes)
    else:
        drawn = None if frames is None else frames[:n]
        residual, inputs, crc32 = encode_rendered(drawn, state, state_rng, codec)
        members, meta = {RESIDUAL: residual, RENDER: inputs}, {"frames_crc32": crc32}
    if pool is not None:
        pool.give(rows)
        if frames is not None:
            pool.give(frames)
    members[STATE] = encode_arrays(state, codec)
    with open(path, "ab") as f:
        offset = f.tell()
        f.write(b"".join(members.values()))
    return offset, [(name, len(data)) for name, data in members.items()], meta


FragmentSink = Callable[[int, Iterator[bytes], Path], None]
"""``sink(episode, blocks, fragment)``: where an episode's tar blocks go once it ends."""


def _anonymous_buffer(shape: tuple[int, ...]) -> np.ndarray:
    """A uint8 array in its own anonymous map (4 KB pages: no huge-page advice)."""
    size = int(np.prod(shape))
    return np.frombuffer(mmap.mmap(-1, max(1, size)), np.uint8)[:size].reshape(shape)


class BufferPool:
    """Buffers of recorders (a chunk's frames, its packed states) and of the encoder (a chunk's
    codec layout), given back once the chunk is coded and reused by the next chunks (and
    shards, when a generator keeps its pool). A fresh buffer page-faults on its first fill;
    buffers are plain anonymous maps, not numpy's (numpy advises huge pages for arrays of
    4 MB and more, and where the kernel then compacts memory to find them, a 16 MB buffer's
    first fill is many times slower than in 4 KB pages). It holds at
    most the most buffers ever in use at once (at L=256 and 8 envs: 8 filling, up to 9
    queued, one coding, and the layout buffer: ~300 MB, kept between shards)."""

    def __init__(self) -> None:
        self._spare: dict[tuple[int, ...], deque[np.ndarray]] = {}  # deques: thread-safe
        self._made: dict[tuple[int, ...], int] = {}  # buffers made per shape, in use or not
        self._lock = threading.Lock()  # for _made: take and prefill run on two threads

    def take(self, shape: tuple[int, ...]) -> np.ndarray:
        """A uint8 buffer of ``shape``, a spare one if any (contents undefined)."""
        try:
            return self._spare[shape].pop()
        except (KeyError, IndexError):
            self._count(shape)
            return _anonymous_buffer(shape)

    def prefill(self, shape: tuple[int, ...], count: int) -> None:
        """Make buffers of ``shape`` until ``count`` exist, each page touched: run on the
        encoder thread at a shard's start, so the page faults of a fresh buffer are not
        taken by the playing thread."""
        while self._count(shape, below=count):
            buf = _anonymous_buffer(shape)
            buf.reshape(-1)[:: mmap.PAGESIZE] = 0
            self.give(buf)

    def _count(self, shape: tuple[int, ...], below: int | None = None) -> bool:
        """Count one more buffer of ``shape`` (if fewer than ``below`` exist); whether it did."""
        with self._lock:
            made = self._made.get(shape, 0)
            if below is not None and made >= below:
                return False
            self._made[shape] = made + 1
            return True

    def give(self, buf: np.ndarray) -> None:
        """Take back a buffer no one uses any more (from any thread: deques are thread-safe)."""
        self._spare.setdefault(buf.shape, deque()).append(buf)


class ChunkEncoder(ThreadPoolExecutor):
    """One background thread for compression and fragment writing, in submission order.

    ``submit_chunk`` blocks while ``max_pending`` chunks wait, so raw chunks queued for
    compression (16 MB each at L=256) stay bounded when the encoder is slower than the envs.
    Other jobs (fragment writes, shard appends) hold no buffer and never block: taking slots
    too, their bursts at episodes' ends would stall play.
    Recorders take their buffers from ``pool`` (a new one by default), given back once coded.
    """

    def __init__(self, max_pending: int, pool: BufferPool | None = None) -> None:
        super().__init__(max_workers=1)
        self._slots = threading.BoundedSemaphore(max_pending)
        self.pool = BufferPool() if pool is None else pool

    def submit_chunk(self, fn, /, *args) -> Future:
        """``submit`` for a job that holds a chunk's buffers: waits for a free slot first."""
        self._slots.acquire()
        future = self.submit(fn, *args)
        future.add_done_callback(lambda _: self._slots.release())
        return future


class EpisodeRecorder:
    """Collects one episode's steps; spools compressed chunks; writes its tar fragment at the end.

    Args:
        episode: global episode index.
        seed: the episode's seed (env and agent).
        workdir: folder for the spool and the finished fragment.
        chunk_length: steps per sample (the last one may be shorter).
        meta: fields copied into every chunk's meta (env, expert).
        encoder: the single-thread ``ChunkEncoder`` that compresses chunks and writes the
            fragment in order (it overlaps with env stepping); stored frames are laid out in
            buffers of its ``pool``.
        rendered: keep each step's Craftax ``state_rng`` and store frames as residuals against
            re-renders from the state (``meta`` should name the renderer version).
        drawn: whether the env draws frames (``observe`` gets them). False (Craftax played by
            a state-only expert): each step's ``state_rng`` is kept and the encoder draws
            the frames from the states, so the playing thread never renders.
        instructed: store each step's commanded instruction (``act``'s ``instruction``) as the
            steps array ``instruction``; other recorders write the format as before.
    """

    def __init__(
        self,
        episode: int,
        seed: int,
        workdir: Path,
        chunk_length: int,
        meta: dict,
        encoder: ChunkEncoder,
        codec: FrameCodec,
        rendered: bool = False,
        instructed: bool = False,
        drawn: bool = True,
    ) -> None:
        self.episode, self.seed, self.meta = episode, seed, meta
        self.chunk_length, self.encoder, self.codec = chunk_length, encoder, codec
        self.spool = workdir / f"e{episode:07d}.spool"
        self.fragment = workdir / f"e{episode:07d}.tar"
        self.spool.unlink(missing_ok=True)
        # frames the env drew: in a buffer from the encoder's pool, taken at a chunk's first
        self._frames: np.ndarray | None = None
        self._rows: np.ndarray | None = None  # the chunk's packed states, also from the pool
        self._state: State = {}  # views of the rows as fields
        self.rendered = rendered
        keep_rng = rendered or not drawn
        self._rng = np.empty((chunk_length, 2), np.uint32) if keep_rng else None
        self._drawn = drawn
        self._fill = 0
        self._chunks: list[Future] = []
        self.actions: list[int] = []
        self.rewards: list[float] = []
        self.noop: list[bool] = []
        self.instructions: list[int] | None = [] if instructed else None
        self.sleeping: list[bool] = []  # per observation, for the manifest's filtered noop ratio
        self._last_row: np.ndarray | None = None  # the latest observation's state, once flushed

    @property
    def final_state(self) -> State | None:
        """The latest observation's state (after ``finish``: the episode's final one)."""
        if self._fill:
            row = self._rows[self._fill - 1 : self._fill]
        elif self._last_row is not None:
            row = self._last_row[None]
        else:
            return None
        return {k: v[0] for k, v in state_views(row).items()}

    def observe(
        self, frame: np.ndarray | None, state: State | None, state_rng: np.ndarray | None = None,
        row: np.ndarray | None = None,
    ) -> None:
        """Add the observation at which the next action is taken (or the final one);
        ``state_rng`` (Craftax's key of that state) is needed by rendered recorders and those
        made with ``drawn`` False, which take ``frame`` None when the env drew none (the
        frame is then drawn from the state).
        ``row``: the state already packed (a row of ``state_views``' rows), copied in one
        assignment; ``state`` may then be None."""
        if self._rng is not None:
            if state_rng is None:
                raise ValueError(f"episode {self.episode}: this recorder needs state_rng "
                                 "(rendered frames, or frames drawn from the states)")
            self._rng[self._fill] = state_rng
        if frame is None and self._rng is None:
            raise ValueError(f"episode {self.episode}: a stored-frames recorder needs the frame")
        if state is None and row is None:
            raise ValueError(f"episode {self.episode}: observe needs the state or its row")
        self._drawn = frame is not None  # None: the frame is drawn from the state
        if self._drawn:  # into a pooled buffer, handed to the encoder at the flush
            if self._frames is None:
                self._frames = self.encoder.pool.take((self.chunk_length, *FRAME_SHAPE))
            self._frames[self._fill] = frame
        if self._rows is None:
            self._rows = self.encoder.pool.take((self.chunk_length, STATE_ROW_BYTES))
            self._state = state_views(self._rows)
        if row is not None:
            self._rows[self._fill] = row
        else:
            for k, v in self._state.items():
                v[self._fill] = state[k]
        self.sleeping.append(bool(self._state["player_sleeping"][self._fill]))
        self._fill += 1
        if self._fill == self.chunk_length:
            self._flush()

    def act(self, action: int, reward: float, noop: bool, instruction: int = -1) -> None:
        """Record the action taken at the latest observation, its reward and noop flag (and on
        an instructed recorder the caption id it was commanded, -1 for none)."""
        self.actions.append(action)
        self.rewards.append(reward)
        self.noop.append(noop)
        if self.instructions is not None:
            self.instructions.append(instruction)

    def _flush(self) -> None:
        """Hand the chunk to the encoder: its buffers go along (and back to the pool once
        coded); the next chunk takes new ones at its first step."""
        n, rows, self._rows = self._fill, self._rows, None
        self._last_row = rows[n - 1].copy()
        frames, self._frames = self._frames, None
        if frames is not None and not self._drawn:  # the last frames are re-renders: all are
            self.encoder.pool.give(frames)
            frames = None
        args = (frames, rows, None if self._rng is None else self._rng[:n].copy())
        job = self.encoder.submit_chunk(
            _spool_chunk, self.spool, n, *args, self.rendered, self.codec, self.encoder.pool)
        self._chunks.append(job)
        self._fill = 0

    def finish(self, episode_meta: dict | None = None, sink: FragmentSink | None = None) -> Future:
        """Close the episode after its final observation. The fragment is written on the
        encoder (after the episode's chunks), so play goes on meanwhile; wait on the result.
        ``episode_meta`` (what is known of the episode only at its end) goes into the meta of
        each of its chunks. ``sink(episode, blocks, fragment)`` takes the fragment's tar
        blocks (``ShardAssembler.add_blocks``); by default they are written to ``fragment``."""
        if self._fill:
            self._flush()
        self.act(-1, 0.0, False)
        steps = {
            "actions": np.asarray(self.actions, np.int64),
            "rewards": np.asarray(self.rewards, np.float32),
            "noop": np.asarray(self.noop, bool),
        }
        steps["noop_run"] = noop_runs(steps["noop"])
        if self.instructions is not None:
            steps["instruction"] = np.asarray(self.instructions, np.int16)
        return self.encoder.submit(self._write_fragment, steps, episode_meta or {}, sink)

    def _write_fragment(self, steps: dict[str, np.ndarray], episode_meta: dict,
                        sink: FragmentSink | None) -> None:
        blocks = self._fragment_blocks(steps, episode_meta)
        if sink is not None:
            sink(self.episode, blocks, self.fragment)
        else:
            with open(self.fragment, "wb") as out:
                out.writelines(blocks)
        self.spool.unlink()

    def _fragment_blocks(self, steps: dict[str, np.ndarray], episode_meta: dict) -> Iterator[bytes]:
        """The episode's samples as tar member blocks, read back from the spool."""
        length = len(steps["actions"])
        spans = [future.result() for future in self._chunks]  # done: same single thread
        with open(self.spool, "rb") as spool:
            for k, (offset, members, extra) in enumerate(spans):
                start = k * self.chunk_length
                stop = min(start + self.chunk_length, length)
                spool.seek(offset)
                key = sample_key(self.episode, start)
                meta = {
                    **self.meta, **extra, **episode_meta,
                    "episode": self.episode, "seed": self.seed, "offset": start,
                    "length": stop - start, "episode_length": length, "last": stop == length,
                }
                for name, size in members:
                    yield tar_member(f"{key}.{name}", spool.read(size))
                chunk_steps = {name: arr[start:stop] for name, arr in steps.items()}
                yield tar_member(f"{key}.{STEPS}", encode_arrays(chunk_steps, self.codec))
                yield tar_member(f"{key}.{META}", encode_json(meta))
