"""CrafterPlay as a stream of training sequences: episode splits, shard reading, packing.

The pieces of the CrafterPlay datamodule's pipeline, kept free of Lightning so DataLoader
workers (spawned, so they import what the pickled pipeline names) start in about a second
instead of the several seconds ``import lightning`` takes.
"""

from __future__ import annotations

import hashlib
import warnings
from collections.abc import Iterable, Iterator, Sequence
from pathlib import Path

import numpy as np
import torch
from torch.utils.data import IterableDataset

from zoo.data.manifest import require_manifest
from zoo.data.reader import CorruptShardError, ReadStats, filter_noops, iter_chunks
from zoo.data.storage import join

SPLITS = ("train", "val", "test")
SEQUENCE_KEYS = ("frames", "actions", "first", "episode", "step")


class ShardSources(IterableDataset):
    """{"url", "episodes", "index", "steps", "source", "draw_weight"} per shard of one or more
    CrafterPlay folders, in folder then index order, from their manifests: the first stage of a
    webdataset pipeline (like ``SimpleShardList``, plus what the later stages need).

    ``source`` is the folder's position in ``roots``. ``draw_weight`` = weight / steps of the
    folder, so drawing shards in proportion to it gives each folder ``weight`` of the steps
    (``datamodules.seeded_shuffle.WeightedDraws``).
    """

    def __init__(
        self, roots: str | Path | Sequence[str | Path], weights: Sequence[float] | None = None
    ) -> None:
        roots = [roots] if isinstance(roots, (str, Path)) else list(roots)
        weights = [1.0] * len(roots) if weights is None else list(weights)
        if len(weights) != len(roots):
            raise ValueError(f"{len(roots)} CrafterPlay folders but {len(weights)} weights")
        self.sources = []
        for source, (root, weight) in enumerate(zip(roots, weights)):
            entries = sorted(require_manifest(root)["shards"], key=lambda e: e["index"])
            total = max(1, sum(int(e["steps"]) for e in entries))
            self.sources += [
                {
                    "url": join(root, e["file"]), "episodes": int(e["episodes"]),
                    "first_episode": int(e.get("first_episode", 0)), "index": e["index"], "steps": int(e["steps"]), "source": source,
                    "draw_weight": float(weight) / total,
                }
                for e in entries
            ]

    def __len__(self) -> int:
        return len(self.sources)

    def split_episodes(self, split: str, val_fraction: float, test_fraction: float,
                       salt: int) -> int:
        """How many of the listed episodes fall in ``split`` (``episode_split``)."""
        return sum(
            episode_split(e, val_fraction, test_fraction, salt) == split
            for source in self.sources
            for e in range(source["first_episode"], source["first_episode"] + source["episodes"])
        )

    def __iter__(self) -> Iterator[dict]:
        return (dict(source) for source in self.sources)


def episode_split(episode: int, val_fraction: float, test_fraction: float, salt: int = 0) -> str:
    """Deterministic split of an episode: a hash maps it to [0, 1), cut at the fractions."""
    digest = hashlib.blake2b(f"{salt}:{episode}".encode(), digest_size=8).digest()
    u = int.from_bytes(digest, "little") / 2**64
    if u < test_fraction:
        return "test"
    if u < test_fraction + val_fraction:
        return "val"
    return "train"


def _whole_shard(url: str, episodes: int) -> Iterator[dict]:
    """Chunks of one shard, checked to hold the manifest's episode count.

    ``iter_chunks`` catches a cut inside a tar member or inside an episode; a shard cut exactly
    between two episodes reads cleanly, and only the manifest knows episodes are missing.
    """
    finished = 0
    for chunk in iter_chunks(url):
        finished += bool(chunk["meta"]["last"])
        yield chunk
    if finished != episodes:
        raise CorruptShardError(
            f"{url}: truncated shard: {finished} whole episodes, the manifest lists {episodes}"
        )


def read_shards(sources: Iterable[dict], skip_corrupt: bool) -> Iterator[dict]:
    """Chunks of each {"url", "episodes"} shard in file order; a corrupt one raises, or is
    abandoned where it breaks (chunks before that were yielded) with a warning naming it."""
    stats = ReadStats()
    for source in sources:
        try:
            for chunk in _whole_shard(source["url"], source["episodes"]):
                chunk["meta"]["source"] = source.get("source", 0)  # episodes are per folder
                yield chunk
        except CorruptShardError as err:
            if not skip_corrupt:
                raise
            stats.skipped_shards.append(source["url"])
            stats.reasons.append(str(err))
            warnings.warn(
                f"skipped corrupt shard {source['url']} ({stats.num_skipped} skipped so far in "
                f"this pass): {stats.reasons[-1]}",
                stacklevel=1,
            )


def select_split(
    chunks: Iterable[dict], split: str, val_fraction: float, test_fraction: float, salt: int
) -> Iterator[dict]:
    for chunk in chunks:
        if episode_split(chunk["meta"]["episode"], val_fraction, test_fraction, salt) == split:
            yield chunk


def filter_noop_chunks(chunks: Iterable[dict], min_run: int) -> Iterator[dict]:
    for chunk in chunks:
        yield filter_noops(chunk, min_run=min_run)


def pack_sequences(
    chunks: Iterable[dict], seq_len: int, extra_keys: tuple[str, ...] = ()
) -> Iterator[dict]:
    """Join consecutive chunks into sequences of exactly ``seq_len`` steps.

    ``first`` is True at the first step of a chunk that starts an episode or whose episode
    (of its source folder) differs from the previous chunk's: at each episode's first kept step. A shorter remainder at the end of the
    stream is dropped. ``extra_keys`` are further per-step arrays of the chunks to carry
    along (C-Steve-1's goals).
    """
    pending: dict[str, list[np.ndarray]] = {key: [] for key in (*SEQUENCE_KEYS, *extra_keys)}
    size = 0
    previous_episode = None
    for chunk in chunks:
        n = len(chunk["actions"])
        if n == 0:
            continue
        meta = chunk["meta"]
        episode = int(meta["episode"])
        key = (meta.get("source", 0), episode)
        first = np.zeros(n, dtype=bool)
        first[0] = key != previous_episode or int(meta["offset"]) == 0
        previous_episode = key
        pending["frames"].append(chunk["frames"])
        pending["actions"].append(np.asarray(chunk["actions"], dtype=np.int64))
        pending["first"].append(first)
        pending["episode"].append(np.full(n, episode, dtype=np.int64))
        in_chunk = chunk.get("step_index", np.arange(n))  # filtered chunks say which steps stayed
        pending["step"].append(int(chunk["meta"]["offset"]) + np.asarray(in_chunk, np.int64))
        for key in extra_keys:
            pending[key].append(chunk[key])
        size += n
        while size >= seq_len:
            yield {key: _take(parts, seq_len) for key, parts in pending.items()}
            size -= seq_len


def _take(parts: list[np.ndarray], n: int) -> np.ndarray:
    """The first ``n`` rows of ``parts`` joined, as a new array; ``parts`` keeps the rest as
    views. Each step is copied once (joining all that is pending at every sequence copied a
    256-step chunk's frames ~3.5 times over at 64-step sequences)."""
    taken, size = [], 0
    while size < n:
        part = parts.pop(0)
        if len(part) > n - size:
            parts.insert(0, part[n - size:])
            part = part[: n - size]
        taken.append(part)
        size += len(part)
    return np.concatenate(taken)


def collate_sequences(samples: list[dict]) -> dict[str, torch.Tensor]:
    return {key: torch.from_numpy(np.stack([s[key] for s in samples])) for key in samples[0]}
