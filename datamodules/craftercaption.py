"""CrafterCaption for C-CLIP: streamed 6-frame clips with their template caption ids.

Pipeline per split (plain ``webdataset``): the split's shard list from manifest.json -> split by
node and DataLoader worker -> shard order shuffled (train) -> samples decoded with
``zoo.captions.dataset.decode_caption_sample`` -> sample shuffle buffer (train) -> batches of
{frames uint8 (B, 6, 144, 144, 3), caption_id int64 (B,), episode int64, step int64, caption,
rule, category (lists of str)}. Training repeats the stream and cuts it into epochs of
``train_batches_per_epoch`` batches. Shuffles follow the run's seed, epoch, rank and worker
(``datamodules.seeded_shuffle``): ``seed_everything`` (or ``seed``) makes them reproducible, a
resumed fit included, while each epoch and each pass gets a new order.

CrafterCaption has a train and a held-out ("test") split of whole episodes; validation and test
both read the held-out split by default (the paper evaluates retrieval on held-out episodes).
"""

from __future__ import annotations

from pathlib import Path

import lightning as L
import torch
import webdataset as wds
from lightning.pytorch.utilities import rank_zero_warn
from torch.utils.data import DataLoader

from datamodules.seeded_shuffle import EpochSeededStream, SeededShuffle, run_seed, seeded_loader
from zoo.captions.clips import collate_clips
from zoo.captions.dataset import (
    decode_caption_sample,
    list_caption_shards,
    load_caption_manifest,
)
from zoo.captions.vocabulary import load_vocabulary
from zoo.data.manifest import MissingDatasetError
from zoo.data.storage import join, tar_samples


def check_manifest_captions(root: str | Path) -> None:
    """Caption ids in the shards must mean the captions this checkout's vocabulary lists."""
    path = join(root, "manifest.json")
    listed = [entry["caption"] for entry in load_caption_manifest(root).get("captions", [])]
    expected = load_vocabulary().texts()
    if listed != expected:
        changed = [i for i, (a, b) in enumerate(zip(listed, expected)) if a != b]
        raise ValueError(
            f"{path}: its {len(listed)} captions differ from zoo/captions/captions.yaml "
            f"({len(expected)} captions; first differing ids {changed[:5]}); caption ids would "
            "mean different captions, so regenerate the data"
        )


class CrafterCaptionDataModule(L.LightningDataModule):
    """Streams CrafterCaption shards as batches of clips for C-CLIP."""

    def __init__(
        self,
        root: str,
        batch_size: int = 64,
        eval_batch_size: int = 64,
        num_workers: int = 4,
        shuffle_buffer: int = 2000,
        train_batches_per_epoch: int | None = None,
        train_split: str = "train",
        val_split: str | None = None,
        test_split: str = "test",
        pin_memory: bool = True,
        seed: int | None = None,
    ) -> None:
        """Args:
            root: CrafterCaption folder (manifest.json + shards), written by zoo.captions.dataset,
                or its URL (``https://host/captions/``, ``s3://bucket/captions``: docs/data.md).
            batch_size: training clips per batch (paper: 64).
            eval_batch_size: clips per validation/test batch.
            num_workers: DataLoader workers; each reads different shards.
            shuffle_buffer: training clips held for shuffling per worker (each ~370 KB decoded).
            train_batches_per_epoch: epoch length in batches over all workers (the stream repeats
                to fill it); None: one pass over the training shards.
            train_split: manifest split to train on.
            val_split: manifest split to validate on; None: "val" (``zoo data caption
                --val-episodes``), and an error when the manifest has none. Naming the test split
                here is allowed with a warning (checkpoints are then chosen on test episodes).
            test_split: manifest split to test on (the held-out episodes).
            pin_memory: page-locked batches for faster host-to-GPU copies.
            seed: seed of the training order (shard and clip shuffles); None: the run's
                ``seed_everything`` value.
        """
        super().__init__()
        self.save_hyperparameters()
        if train_batches_per_epoch is not None and train_batches_per_epoch < 1:
            raise ValueError(f"train_batches_per_epoch must be >= 1, got {train_batches_per_epoch}")
        self._checked = False

    def shards(self, split: str) -> list[str]:
        if not self._checked:
            check_manifest_captions(self.hparams.root)
            self._checked = True
        urls = list_caption_shards(self.hparams.root, split)
        if not urls:
            where = join(self.hparams.root, "manifest.json")
            raise MissingDatasetError(f"{where} lists no {split!r} shards")
        return urls

    def dataset(self, split: str, train: bool, first_epoch: int = 0) -> EpochSeededStream:
        """The stream of batches of one manifest split (an IterableDataset; no length).

        Each iteration is one epoch; training shuffles are seeded by (seed, epoch), counting
        from ``first_epoch``.
        """
        hp = self.hparams
        urls = self.shards(split)
        shuffles: list[SeededShuffle] = []
        stages = [wds.SimpleShardList(urls), wds.split_by_node, wds.split_by_worker]
        if train:
            shuffles.append(SeededShuffle(len(urls), salt=0))
            stages.append(shuffles[-1])
        stages += [tar_samples, wds.map(decode_caption_sample)]
        if train and hp.shuffle_buffer > 1:
            shuffles.append(SeededShuffle(hp.shuffle_buffer, salt=1))
            stages.append(shuffles[-1])
        batch_size = hp.batch_size if train else hp.eval_batch_size
        stages.append(wds.batched(batch_size, collation_fn=collate_clips, partial=not train))
        pipeline = wds.DataPipeline(*stages)
        if train and hp.train_batches_per_epoch is not None:
            per_worker = max(1, hp.train_batches_per_epoch // max(1, hp.num_workers))
            pipeline = pipeline.with_epoch(per_worker)
        return EpochSeededStream(pipeline, shuffles, run_seed(hp.seed), first_epoch)

    def _loader(self, split: str, train: bool) -> DataLoader:
        return seeded_loader(
            self.dataset(split, train),
            self.hparams.num_workers,
            self.hparams.pin_memory and torch.cuda.is_available(),
            self.trainer,
        )

    def train_dataloader(self) -> DataLoader:
        return self._loader(self.hparams.train_split, train=True)

    @property
    def val_split(self) -> str:
        """The split validation reads (see ``val_split`` in ``__init__``).

        Validation picks the best checkpoint, so it must never read the test split by accident:
        without a "val" split in the manifest this refuses, and an explicit ``val_split`` equal
        to the test split is allowed with a warning.
        """
        hp = self.hparams
        if hp.val_split is None:
            if "val" not in load_caption_manifest(hp.root)["splits"]:
                raise ValueError(
                    f"{join(hp.root, 'manifest.json')} has no 'val' split, and validating on "
                    f"{hp.test_split!r} would choose checkpoints on the test episodes. Rebuild it "
                    "with `zoo data caption ... --val-episodes N`, or set "
                    f"data.init_args.val_split={hp.test_split} to accept that (smoke runs)"
                )
            return "val"
        if hp.val_split == hp.test_split:
            rank_zero_warn(
                f"data.init_args.val_split={hp.val_split!r} is the test split: a checkpoint chosen "
                "by validation is chosen on the test episodes, so its test scores are optimistic"
            )
        return hp.val_split

    def val_dataloader(self) -> DataLoader:
        return self._loader(self.val_split, train=False)

    def test_dataloader(self) -> DataLoader:
        return self._loader(self.hparams.test_split, train=False)

    def predict_dataloader(self) -> DataLoader:
        """``zoo predict`` embeds the test split's clips, in order."""
        return self._loader(self.hparams.test_split, train=False)


__all__ = ["CrafterCaptionDataModule", "check_manifest_captions"]
