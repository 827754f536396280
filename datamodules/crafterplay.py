"""CrafterPlay for behaviour cloning: streamed, noop-filtered, packed into long sequences.

Pipeline per split (plain ``webdataset``): shard list -> split by node and DataLoader worker
(each worker reads its own shards) -> shard order shuffled (train) -> chunks read with
``zoo.data.reader.iter_chunks`` (a corrupt shard raises an error naming it, or with
``skip_corrupt`` is skipped with a warning) -> keep this split's episodes -> ``filter_noops`` ->
consecutive chunks packed into sequences of ``seq_len`` steps (an episode's chunks are
consecutive in a shard, so steps stay in order; ``first`` marks each episode's first kept
step, and a sequence may run from one episode into the next) -> sequence shuffle buffer
(train) -> batches of {frames uint8 (B, S, 144, 144, 3), actions int64 (B, S) with -1 for the
final observation, first bool (B, S), episode int64 (B, S)}.

Splits are by episode: a hash of the episode index (and ``split_salt``) puts every episode in
exactly one of train/val/test, whatever shard or worker reads it.

Both training shuffles follow the run's seed, epoch, rank and worker
(``datamodules.seeded_shuffle``), so two fits with one seed see the same batches, a resumed fit
sees the batches a straight one would from its next epoch, and DataLoader workers are spawned.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator

import lightning as L
import torch
import webdataset as wds
from torch.utils.data import DataLoader

from datamodules.seeded_shuffle import (
    EpochSeeded,
    EpochSeededStream,
    SeededShuffle,
    WeightedDraws,
    run_seed,
    seeded_loader,
)
from zoo.data.sequences import (
    SPLITS,
    ShardSources,
    collate_sequences,
    episode_split,
    filter_noop_chunks,
    pack_sequences,
    read_shards,
    select_split,
)


def data_sources(root: str | None, sources: list[dict] | None) -> tuple[list[str], list[float]]:
    """The folders and weights of ``root`` or ``sources``, checked (errors name the field)."""
    if (root is None) == (sources is None):
        raise ValueError(
            "give data.init_args.root (one CrafterPlay folder) or data.init_args.sources "
            "([{root: DIR, weight: W}, ...]), exactly one of them (to swap one for the other on "
            "the command line, set the config's to null, e.g. --data.init_args.sources=null)"
        )
    if root is not None:
        return [str(root)], [1.0]
    if not sources:
        raise ValueError("data.init_args.sources is empty; expected [{root: DIR, weight: W}, ...]")
    roots, weights = [], []
    for i, source in enumerate(sources):
        if not isinstance(source, dict) or "root" not in source:
            raise ValueError(f"data.init_args.sources[{i}] is {source!r}; expected {{root: DIR, weight: W}}")
        unknown = sorted(set(source) - {"root", "weight"})
        if unknown:
            raise ValueError(f"data.init_args.sources[{i}] has unknown keys {unknown}; expected root, weight")
        weight = float(source.get("weight", 1.0))
        if not weight > 0:
            raise ValueError(f"data.init_args.sources[{i}].weight must be > 0, got {weight}")
        roots.append(str(source["root"]))
        weights.append(weight)
    return roots, weights


class CrafterPlayDataModule(L.LightningDataModule):
    """Streams CrafterPlay shards as batches of long, noop-filtered sequences."""

    extra_keys: tuple[str, ...] = ()
    """Per-step arrays beyond frames/actions/first/episode/step that batches carry."""

    def __init__(
        self,
        root: str | None = None,
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
        seed: int | None = None,
        skip_corrupt: bool = False,
        sources: list[dict] | None = None,
    ) -> None:
        """Args:
            root: CrafterPlay folder (manifest.json + shards), e.g. from `zoo data generate`,
                or its URL (``https://host/crafterplay/``, ``s3://bucket/crafterplay``: see
                docs/data.md); or give ``sources`` instead.
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
            seed: seed of the training order (shard and sequence shuffles); None: the run's
                ``seed_everything`` value.
            skip_corrupt: skip a shard that cannot be read to its end (with a warning that names
                it) instead of stopping the run; its chunks before the damage are still used.
            sources: several CrafterPlay folders (or URLs) with weights,
                ``[{root: DIR, weight: W}, ...]``
                (expert data plus DAgger rounds): training draws shards so that each folder
                gives a share W / sum(W) of the steps; validation and test read every folder.
        """
        super().__init__()
        self.save_hyperparameters()
        if val_fraction < 0 or test_fraction < 0 or val_fraction + test_fraction >= 1:
            raise ValueError(
                f"val_fraction={val_fraction} and test_fraction={test_fraction} must be >= 0 "
                "and leave a training share (sum < 1)"
            )
        self._roots, self._weights = data_sources(root, sources)
        self._shards: ShardSources | None = None

    @property
    def shards(self) -> ShardSources:
        """The shards the manifests list, folder by folder, in index order."""
        if self._shards is None:
            self._shards = ShardSources(self._roots, self._weights)
            if not self._shards:
                raise FileNotFoundError(f"no CrafterPlay shards listed in {', '.join(self._roots)}")
        return self._shards

    def dataset(self, split: str, first_epoch: int = 0) -> EpochSeededStream:
        """The stream of batches of one split (an IterableDataset; no length).

        Each iteration is one epoch; training shuffles are seeded by (seed, epoch), counting
        from ``first_epoch``.
        """
        if split not in SPLITS:
            raise ValueError(f"unknown split {split!r}; expected one of {SPLITS}")
        hp = self.hparams
        train = split == "train"
        if train and not self.shards.split_episodes(
            "train", hp.val_fraction, hp.test_fraction, hp.split_salt
        ):
            raise ValueError(
                f"no training episodes in {', '.join(self._roots)}: all "
                f"{sum(s['episodes'] for s in self.shards.sources)} fall in the val/test split "
                f"(val_fraction={hp.val_fraction}, test_fraction={hp.test_fraction}); generate "
                "more episodes or lower the fractions"
            )
        shuffles: list[EpochSeeded] = []
        stages = [self.shards, wds.split_by_node, wds.split_by_worker]
        if train and len(self._roots) > 1:
            shuffles.append(WeightedDraws(salt=2))
        elif train:
            shuffles.append(SeededShuffle(len(self.shards), salt=0))
        stages += shuffles
        reader = self.chunk_reader()
        if train and hasattr(reader, "start_epoch"):
            shuffles.append(reader)  # its randomness follows the epoch like the shuffles'
        stages += [
            reader,
            wds.pipelinefilter(select_split)(
                split, hp.val_fraction, hp.test_fraction, hp.split_salt
            ),
        ]
        if hp.noop_filter:
            stages.append(wds.pipelinefilter(filter_noop_chunks)(hp.min_noop_run))
        stages.append(wds.pipelinefilter(pack_sequences)(hp.seq_len, self.extra_keys))
        for stage in self.sequence_stages():
            stages.append(stage)
            if train and hasattr(stage, "start_epoch"):
                shuffles.append(stage)
        if train and hp.shuffle_buffer > 1:
            shuffles.append(SeededShuffle(hp.shuffle_buffer, salt=1))
            stages.append(shuffles[-1])
        stages.append(
            wds.batched(hp.batch_size, collation_fn=collate_sequences, partial=not train)
        )
        pipeline = wds.DataPipeline(*stages)
        if train and hp.train_batches_per_epoch is not None:
            per_worker = max(1, hp.train_batches_per_epoch // max(1, hp.num_workers))
            pipeline = pipeline.with_epoch(per_worker)
        return EpochSeededStream(pipeline, shuffles, run_seed(hp.seed), first_epoch)

    def sequence_stages(self) -> list[Callable[[Iterable[dict]], Iterator[dict]]]:
        """Stages over packed sequences, before shuffling (subclasses add theirs)."""
        return []

    def chunk_reader(self) -> Callable[[Iterable[dict]], Iterator[dict]]:
        """The stage that turns shard sources into chunks (subclasses attach more per step)."""
        return wds.pipelinefilter(read_shards)(self.hparams.skip_corrupt)

    def _loader(self, split: str) -> DataLoader:
        return seeded_loader(
            self.dataset(split),
            self.hparams.num_workers,
            self.hparams.pin_memory and torch.cuda.is_available(),
            self.trainer,
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
