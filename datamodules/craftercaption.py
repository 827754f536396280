"""CrafterCaption for C-CLIP: streamed 6-frame clips with their template caption ids.

Pipeline per split (plain ``webdataset``): the split's shard list from manifest.json -> split by
node and DataLoader worker -> shard order shuffled (train) -> samples decoded with
``zoo.captions.dataset.decode_caption_sample`` -> sample shuffle buffer (train) -> batches of
{frames uint8 (B, 6, 144, 144, 3), caption_id int64 (B,), episode int64, step int64, caption,
rule, category (lists of str)}. Training repeats the stream and cuts it into epochs of
``train_batches_per_epoch`` batches. Shuffles are seeded from each worker's torch seed, so
``seed_everything`` makes them reproducible while each epoch and each pass gets a new order.

CrafterCaption has a train and a held-out ("test") split of whole episodes; validation and test
both read the held-out split by default (the paper evaluates retrieval on held-out episodes).
"""

from __future__ import annotations

import json
import random
from collections.abc import Iterable, Iterator
from pathlib import Path

import lightning as L
import numpy as np
import torch
import webdataset as wds
from lightning.pytorch.utilities import rank_zero_warn
from torch.utils.data import DataLoader

from zoo.captions.dataset import decode_caption_sample, list_caption_shards
from zoo.captions.vocabulary import load_vocabulary

TENSOR_KEYS = {
    "frames": torch.uint8, "caption_id": torch.int64, "episode": torch.int64, "step": torch.int64
}
TEXT_KEYS = ("caption", "rule", "category")


class SeededShuffle:
    """A shuffle-buffer stage whose order comes from the worker's torch seed and a pass counter.

    webdataset's own shuffle seeds from the clock; DataLoader gives every worker a seed derived from
    the main process's torch RNG, which differs per epoch and is fixed by ``seed_everything``.
    """

    def __init__(self, bufsize: int, salt: int) -> None:
        self.bufsize = bufsize
        self.salt = salt
        self.passes = 0

    def __call__(self, items: Iterable) -> Iterator:
        rng = random.Random(f"{torch.initial_seed()}:{self.salt}:{self.passes}")
        self.passes += 1
        buffer: list = []
        for item in items:
            if len(buffer) < self.bufsize:
                buffer.append(item)
                continue
            index = rng.randrange(len(buffer))
            buffer[index], item = item, buffer[index]
            yield item
        rng.shuffle(buffer)
        yield from buffer


def collate_clips(samples: list[dict]) -> dict:
    """Decoded samples -> one batch (tensors for arrays and numbers, lists for strings)."""
    batch: dict = {
        key: torch.as_tensor(np.stack([np.asarray(s[key]) for s in samples]), dtype=dtype)
        for key, dtype in TENSOR_KEYS.items()
    }
    batch.update({key: [str(s[key]) for s in samples] for key in TEXT_KEYS})
    return batch


def check_manifest_captions(root: str | Path) -> None:
    """Caption ids in the shards must mean the captions this checkout's vocabulary lists."""
    path = Path(root) / "manifest.json"
    if not path.is_file():
        raise FileNotFoundError(f"{path} does not exist; write the data with `zoo captions ...`")
    listed = [entry["caption"] for entry in json.loads(path.read_text()).get("captions", [])]
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
    ) -> None:
        """Args:
            root: CrafterCaption folder (manifest.json + shards), written by zoo.captions.dataset.
            batch_size: training clips per batch (paper: 64).
            eval_batch_size: clips per validation/test batch.
            num_workers: DataLoader workers; each reads different shards.
            shuffle_buffer: training clips held for shuffling per worker (each ~370 KB decoded).
            train_batches_per_epoch: epoch length in batches over all workers (the stream repeats
                to fill it); None: one pass over the training shards.
            train_split: manifest split to train on.
            val_split: manifest split to validate on; None: "val" when the manifest has one
                (``zoo data caption --val-episodes``), else the test split (with a warning:
                a best-by-validation checkpoint is then chosen on the test episodes).
            test_split: manifest split to test on (the held-out episodes).
            pin_memory: page-locked batches for faster host-to-GPU copies.
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
            raise FileNotFoundError(f"{self.hparams.root}/manifest.json lists no {split!r} shards")
        return urls

    def dataset(self, split: str, train: bool) -> wds.DataPipeline:
        """The stream of batches of one manifest split (an IterableDataset; no length)."""
        hp = self.hparams
        urls = self.shards(split)
        stages = [wds.SimpleShardList(urls), wds.split_by_node, wds.split_by_worker]
        if train:
            stages.append(SeededShuffle(len(urls), salt=0))
        stages += [wds.tarfile_to_samples(), wds.map(decode_caption_sample)]
        if train and hp.shuffle_buffer > 1:
            stages.append(SeededShuffle(hp.shuffle_buffer, salt=1))
        batch_size = hp.batch_size if train else hp.eval_batch_size
        stages.append(wds.batched(batch_size, collation_fn=collate_clips, partial=not train))
        pipeline = wds.DataPipeline(*stages)
        if train and hp.train_batches_per_epoch is not None:
            per_worker = max(1, hp.train_batches_per_epoch // max(1, hp.num_workers))
            pipeline = pipeline.with_epoch(per_worker)
        return pipeline

    def _loader(self, split: str, train: bool) -> DataLoader:
        return DataLoader(
            self.dataset(split, train),
            batch_size=None,
            num_workers=self.hparams.num_workers,
            pin_memory=self.hparams.pin_memory and torch.cuda.is_available(),
        )

    def train_dataloader(self) -> DataLoader:
        return self._loader(self.hparams.train_split, train=True)

    @property
    def val_split(self) -> str:
        """The split validation reads (see ``val_split`` in ``__init__``)."""
        if self.hparams.val_split is not None:
            return self.hparams.val_split
        manifest = json.loads((Path(self.hparams.root) / "manifest.json").read_text())
        if "val" in manifest["splits"]:
            return "val"
        rank_zero_warn(
            f"{self.hparams.root} has no val split: validating on {self.hparams.test_split!r}, so "
            "a checkpoint chosen by validation is chosen on the test episodes "
            "(make one with zoo data caption --val-episodes N)"
        )
        return self.hparams.test_split

    def val_dataloader(self) -> DataLoader:
        return self._loader(self.val_split, train=False)

    def test_dataloader(self) -> DataLoader:
        return self._loader(self.hparams.test_split, train=False)

    def predict_dataloader(self) -> DataLoader:
        """``zoo predict`` embeds the test split's clips, in order."""
        return self._loader(self.hparams.test_split, train=False)


__all__ = ["CrafterCaptionDataModule", "SeededShuffle", "collate_clips", "check_manifest_captions"]
