"""CrafterPlay for behaviour cloning: streamed, noop-filtered, packed into long sequences.

Pipeline per split (plain ``webdataset``): shard list -> split by node and DataLoader worker
(each worker reads its own shards) -> shard order shuffled (train) -> chunks decoded with
``zoo.data.reader.decode_sample`` -> keep this split's episodes -> ``filter_noops`` ->
consecutive chunks packed into sequences of ``seq_len`` steps (an episode's chunks are
consecutive in a shard, so steps stay in order; ``first`` marks each episode's first kept
step, and a sequence may run from one episode into the next) -> sequence shuffle buffer
(train) -> batches of {frames uint8 (B, S, 144, 144, 3), actions int64 (B, S) with -1 for the
final observation, first bool (B, S), episode int64 (B, S)}.

Splits are by episode: a hash of the episode index (and ``split_salt``) puts every episode in
exactly one of train/val/test, whatever shard or worker reads it.
"""

from __future__ import annotations

import hashlib
from collections.abc import Iterable, Iterator

import lightning as L
import numpy as np
import torch
import webdataset as wds
from torch.utils.data import DataLoader

from zoo.data.reader import decode_sample, filter_noops, list_shards

SPLITS = ("train", "val", "test")
SEQUENCE_KEYS = ("frames", "actions", "first", "episode", "step")


def episode_split(episode: int, val_fraction: float, test_fraction: float, salt: int = 0) -> str:
    """Deterministic split of an episode: a hash maps it to [0, 1), cut at the fractions."""
    digest = hashlib.blake2b(f"{salt}:{episode}".encode(), digest_size=8).digest()
    u = int.from_bytes(digest, "little") / 2**64
    if u < test_fraction:
        return "test"
    if u < test_fraction + val_fraction:
        return "val"
    return "train"


def _select_split(
    chunks: Iterable[dict], split: str, val_fraction: float, test_fraction: float, salt: int
) -> Iterator[dict]:
    for chunk in chunks:
        if episode_split(chunk["meta"]["episode"], val_fraction, test_fraction, salt) == split:
            yield chunk


def _filter_noops(chunks: Iterable[dict], min_run: int) -> Iterator[dict]:
    for chunk in chunks:
        yield filter_noops(chunk, min_run=min_run)


def pack_sequences(chunks: Iterable[dict], seq_len: int) -> Iterator[dict]:
    """Join consecutive chunks into sequences of exactly ``seq_len`` steps.

    ``first`` is True at the first step of a chunk whose episode differs from the previous
    chunk's (so at each episode's first kept step). A shorter remainder at the end of the
    stream is dropped.
    """
    pending: dict[str, list[np.ndarray]] = {key: [] for key in SEQUENCE_KEYS}
    size = 0
    previous_episode = None
    for chunk in chunks:
        n = len(chunk["actions"])
        if n == 0:
            continue
        episode = int(chunk["meta"]["episode"])
        first = np.zeros(n, dtype=bool)
        first[0] = episode != previous_episode
        previous_episode = episode
        pending["frames"].append(chunk["frames"])
        pending["actions"].append(np.asarray(chunk["actions"], dtype=np.int64))
        pending["first"].append(first)
        pending["episode"].append(np.full(n, episode, dtype=np.int64))
        in_chunk = chunk.get("step_index", np.arange(n))  # filtered chunks say which steps stayed
        pending["step"].append(int(chunk["meta"]["offset"]) + np.asarray(in_chunk, np.int64))
        size += n
        while size >= seq_len:
            joined = {key: np.concatenate(parts) for key, parts in pending.items()}
            yield {key: value[:seq_len].copy() for key, value in joined.items()}
            pending = {key: [value[seq_len:]] for key, value in joined.items()}
            size -= seq_len


def collate_sequences(samples: list[dict]) -> dict[str, torch.Tensor]:
    return {key: torch.from_numpy(np.stack([s[key] for s in samples])) for key in SEQUENCE_KEYS}


class CrafterPlayDataModule(L.LightningDataModule):
    """Streams CrafterPlay shards as batches of long, noop-filtered sequences."""

    def __init__(
        self,
        root: str,
        seq_len: int = 640,
        batch_size: int = 128,
        num_workers: int = 4,
        noop_filter: bool = True,
        min_noop_run: int = 20,
        val_fraction: float = 0.05,
        test_fraction: float = 0.05,
        split_salt: int = 0,
        shuffle_buffer: int = 64,
        train_batches_per_epoch: int | None = None,
        pin_memory: bool = True,
    ) -> None:
        """Args:
            root: CrafterPlay folder (manifest.json + shards), e.g. from `zoo data generate`.
            seq_len: steps per sequence (paper: 640); the model cuts it into TBPTT windows.
            batch_size: sequences per batch (per device).
            num_workers: DataLoader workers; each reads different shards.
            noop_filter: drop noop runs shorter than ``min_noop_run`` (paper: on).
            min_noop_run: noop runs at least this long are kept (paper: 20).
            val_fraction: share of episodes in the validation split.
            test_fraction: share of episodes in the test split.
            split_salt: changes which episodes land in which split.
            shuffle_buffer: training sequences held for shuffling (each 640-step sequence is
                ~40 MB of frames per worker, so keep this modest).
            train_batches_per_epoch: epoch length in batches over all workers (the stream is
                repeated to fill it); None: one pass over the training shards.
            pin_memory: page-locked batches for faster host-to-GPU copies.
        """
        super().__init__()
        self.save_hyperparameters()
        if val_fraction < 0 or test_fraction < 0 or val_fraction + test_fraction >= 1:
            raise ValueError(
                f"val_fraction={val_fraction} and test_fraction={test_fraction} must be >= 0 "
                "and leave a training share (sum < 1)"
            )
        self._shards: list[str] | None = None

    @property
    def shards(self) -> list[str]:
        if self._shards is None:
            self._shards = sorted(list_shards(self.hparams.root))
            if not self._shards:
                raise FileNotFoundError(f"no CrafterPlay shards listed in {self.hparams.root}")
        return self._shards

    def dataset(self, split: str) -> wds.DataPipeline:
        """The stream of batches of one split (an IterableDataset; no length)."""
        if split not in SPLITS:
            raise ValueError(f"unknown split {split!r}; expected one of {SPLITS}")
        hp = self.hparams
        train = split == "train"
        stages = [wds.SimpleShardList(self.shards), wds.split_by_node, wds.split_by_worker]
        if train:
            stages.append(wds.shuffle(len(self.shards), initial=len(self.shards)))
        stages += [
            wds.tarfile_to_samples(),
            wds.map(decode_sample),
            wds.pipelinefilter(_select_split)(
                split, hp.val_fraction, hp.test_fraction, hp.split_salt
            ),
        ]
        if hp.noop_filter:
            stages.append(wds.pipelinefilter(_filter_noops)(hp.min_noop_run))
        stages.append(wds.pipelinefilter(pack_sequences)(hp.seq_len))
        if train and hp.shuffle_buffer > 1:
            stages.append(wds.shuffle(hp.shuffle_buffer, initial=hp.shuffle_buffer))
        stages.append(
            wds.batched(hp.batch_size, collation_fn=collate_sequences, partial=not train)
        )
        pipeline = wds.DataPipeline(*stages)
        if train and hp.train_batches_per_epoch is not None:
            pipeline = pipeline.with_epoch(max(1, hp.train_batches_per_epoch // max(1, hp.num_workers)))
        return pipeline

    def _loader(self, split: str) -> DataLoader:
        return DataLoader(
            self.dataset(split),
            batch_size=None,
            num_workers=self.hparams.num_workers,
            pin_memory=self.hparams.pin_memory and torch.cuda.is_available(),
        )

    def train_dataloader(self) -> DataLoader:
        return self._loader("train")

    def val_dataloader(self) -> DataLoader:
        return self._loader("val")

    def test_dataloader(self) -> DataLoader:
        return self._loader("test")

    def predict_dataloader(self) -> DataLoader:
        """``zoo predict`` reads the test episodes, in order."""
        return self._loader("test")


__all__ = ["CrafterPlayDataModule", "episode_split", "pack_sequences"]
