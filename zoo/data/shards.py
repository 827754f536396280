"""Writing CrafterPlay shards: episodes recorded chunk by chunk, then laid out as tar bytes.

Raw frames never pile up: a chunk of L steps is compressed and appended to the episode's
spool file as soon as it is full. Chunk metadata (``episode_length``, ``last``) and noop
runs are only known when the episode ends, so samples are assembled then, into one tar
fragment per episode; the shard is those fragments in episode order plus the tar trailer.
Every tar header is fixed (mtime 0, uid 0, mode 644) so a shard's bytes depend on its
content alone. A chunk stores its frames as images (FRAMES) or, in the ``rendered`` mode, as
residuals against re-renders from its states (RESIDUAL + RENDER, see ``zoo.data.rerender``).
"""

from __future__ import annotations

import hashlib
import os
import tarfile
import threading
from collections.abc import Iterable, Iterator
from concurrent.futures import Executor, Future, ThreadPoolExecutor
from pathlib import Path

import numpy as np

from zoo.data.codec import FrameCodec, encode_arrays, encode_frames, encode_json
from zoo.data.noop import noop_runs
from zoo.data.rerender import encode_rendered
from zoo.envs.schema import FRAME_SHAPE, STATE_FIELDS, State
from zoo.files import atomic_path

SHARD_PATTERN = "crafterplay-{index:06d}.tar"
FRAMES, STATE, STEPS, META = "frames.zst", "state.zst", "steps.zst", "meta.json"
RESIDUAL, RENDER = "residual.zst", "render.zst"  # rendered chunks: in place of FRAMES
_BLOCK = tarfile.BLOCKSIZE


def sample_key(episode: int, offset: int) -> str:
    """WebDataset key of the chunk of ``episode`` starting at step ``offset``."""
    return f"e{episode:07d}_{offset:06d}"


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


def _spool_chunk(
    path: Path, frames: np.ndarray, state: State, state_rng: np.ndarray | None,
    codec: FrameCodec,
) -> tuple[int, list[tuple[str, int]], dict]:
    """Compress one chunk and append it to the spool; returns (offset, [(member, bytes)], the
    chunk's extra meta). With ``state_rng`` the frames become residuals against re-renders."""
    if state_rng is None:
        members, meta = {FRAMES: encode_frames(frames, codec)}, {}
    else:
        residual, inputs, crc32 = encode_rendered(frames, state, state_rng, codec)
        members, meta = {RESIDUAL: residual, RENDER: inputs}, {"frames_crc32": crc32}
    members[STATE] = encode_arrays(state, codec)
    with open(path, "ab") as f:
        offset = f.tell()
        f.write(b"".join(members.values()))
    return offset, [(name, len(data)) for name, data in members.items()], meta


class ChunkEncoder(ThreadPoolExecutor):
    """One background thread for compression and fragment writing, in submission order.

    ``submit`` blocks while ``max_pending`` jobs wait, so raw chunks queued for compression
    (16 MB each at L=256) stay bounded when the encoder is slower than the envs.
    """

    def __init__(self, max_pending: int) -> None:
        super().__init__(max_workers=1)
        self._slots = threading.BoundedSemaphore(max_pending)

    def submit(self, fn, /, *args, **kwargs) -> Future:
        self._slots.acquire()
        future = super().submit(fn, *args, **kwargs)
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
        encoder: a single-thread executor that compresses chunks and writes the fragment in
            order (it overlaps with env stepping).
        rendered: keep each step's Craftax ``state_rng`` and store frames as residuals against
            re-renders from the state (``meta`` should name the renderer version).
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
        encoder: Executor,
        codec: FrameCodec,
        rendered: bool = False,
        instructed: bool = False,
    ) -> None:
        self.episode, self.seed, self.meta = episode, seed, meta
        self.chunk_length, self.encoder, self.codec = chunk_length, encoder, codec
        self.spool = workdir / f"e{episode:07d}.spool"
        self.fragment = workdir / f"e{episode:07d}.tar"
        self.spool.unlink(missing_ok=True)
        self._frames = np.empty((chunk_length, *FRAME_SHAPE), np.uint8)
        self._state = {
            k: np.empty((chunk_length, *f.shape), f.dtype) for k, f in STATE_FIELDS.items()
        }
        self._rng = np.empty((chunk_length, 2), np.uint32) if rendered else None
        self._drawn = True
        self._fill = 0
        self._chunks: list[Future] = []
        self.actions: list[int] = []
        self.rewards: list[float] = []
        self.noop: list[bool] = []
        self.instructions: list[int] | None = [] if instructed else None
        self.sleeping: list[bool] = []  # per observation, for the manifest's filtered noop ratio
        self.final_state: State | None = None

    def observe(
        self, frame: np.ndarray | None, state: State, state_rng: np.ndarray | None = None
    ) -> None:
        """Add the observation at which the next action is taken (or the final one);
        ``state_rng`` (Craftax's key of that state) is needed by rendered recorders, which
        also take ``frame`` None when the env drew none (the frame is then the re-render)."""
        if self._rng is not None:
            if state_rng is None:
                raise ValueError(f"episode {self.episode}: a rendered recorder needs state_rng")
            self._rng[self._fill] = state_rng
        if frame is None and self._rng is None:
            raise ValueError(f"episode {self.episode}: a stored-frames recorder needs the frame")
        self._drawn = frame is not None  # rendered recorders may get None: frame = re-render
        if self._drawn:
            self._frames[self._fill] = frame
        for k, v in state.items():
            self._state[k][self._fill] = v
        self._fill += 1
        self.sleeping.append(bool(state["player_sleeping"]))
        self.final_state = state
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
        n = self._fill
        frames = self._frames[:n].copy() if self._drawn else None
        state = {k: v[:n].copy() for k, v in self._state.items()}
        rng = None if self._rng is None else self._rng[:n].copy()
        job = self.encoder.submit(_spool_chunk, self.spool, frames, state, rng, self.codec)
        self._chunks.append(job)
        self._fill = 0

    def finish(self, episode_meta: dict | None = None) -> Future:
        """Close the episode after its final observation. The fragment is written on the
        encoder (after the episode's chunks), so play goes on meanwhile; wait on the result.
        ``episode_meta`` (what is known of the episode only at its end) goes into the meta of
        each of its chunks."""
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
        return self.encoder.submit(self._write_fragment, steps, episode_meta or {})

    def _write_fragment(self, steps: dict[str, np.ndarray], episode_meta: dict) -> None:
        length = len(steps["actions"])
        spans = [future.result() for future in self._chunks]  # done: same single thread
        with open(self.spool, "rb") as spool, open(self.fragment, "wb") as out:
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
                out.writelines(
                    tar_member(f"{key}.{name}", spool.read(size)) for name, size in members
                )
                chunk_steps = {name: arr[start:stop] for name, arr in steps.items()}
                out.write(tar_member(f"{key}.{STEPS}", encode_arrays(chunk_steps, self.codec)))
                out.write(tar_member(f"{key}.{META}", encode_json(meta)))
        self.spool.unlink()


def write_tar(path: Path, blocks: Iterable[bytes]) -> str:
    """Write tar member ``blocks`` and the end-of-archive trailer to ``path`` via a temp name
    (renamed when complete and synced, so a killed writer leaves no half shard); its sha256."""
    digest, size = hashlib.sha256(), 0
    with atomic_path(path) as tmp, open(tmp, "wb") as out:
        for block in blocks:
            out.write(block)
            digest.update(block)
            size += len(block)
        trailer = tar_trailer(size)
        out.write(trailer)
        digest.update(trailer)
        out.flush()
        os.fsync(out.fileno())
    return digest.hexdigest()


def _file_blocks(paths: list[Path]) -> Iterator[bytes]:
    for fragment in paths:
        with open(fragment, "rb") as f:
            yield from iter(lambda f=f: f.read(1 << 20), b"")


def assemble_shard(fragments: list[Path], path: Path) -> str:
    """Concatenate episode fragments into ``path`` (via a temp name); return its sha256."""
    sha = write_tar(path, _file_blocks(fragments))
    for fragment in fragments:
        fragment.unlink()
    return sha
