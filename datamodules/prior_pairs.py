"""C-CLIP (video, text) embedding pairs for the CVAE prior, from a `zoo goals prior-pairs` file.

The whole file sits in memory (120K pairs of 512-d float32 embeddings are 0.5 GB; the CPU
config's 11K of 64-d, 6 MB), so batches are index lookups in the main process, no workers.
Validation holds out whole episodes, drawn by ``seed``: clips of one episode share scenery, and a
prior validated on its training episodes' neighbours would look better than it is. Training order
is a permutation seeded by (seed, epoch), so a resumed fit sees the order a straight one would.

Batches: {video, text float32 (B, D), caption_id, episode int64 (B,)}; validation batches also
carry ``caption_mean`` (B, D), the unit-norm mean training video embedding of each pair's caption,
and ``has_caption_mean`` (B,) bool (False where the caption has no training pair): a text->goal
lookup table, the reference the prior is scored against.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator

import lightning as L
import numpy as np
import torch
from torch.utils.data import DataLoader, Dataset, Sampler

from datamodules.seeded_shuffle import run_seed
from zoo.goals.prior_pairs import read_prior_pairs


class PairsDataset(Dataset):
    """Rows of equal-length tensors; ``__getitems__`` returns a whole batch in one lookup."""

    def __init__(self, tensors: dict[str, torch.Tensor]) -> None:
        self.tensors = tensors

    def __len__(self) -> int:
        return len(self.tensors["video"])

    def __getitems__(self, indices: list[int]) -> dict[str, torch.Tensor]:
        index = torch.as_tensor(indices)
        return {name: tensor[index] for name, tensor in self.tensors.items()}


def _batch_as_is(batch: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """Collate of ``PairsDataset`` batches: they are batches already."""
    return batch


class EpochPermutation(Sampler[int]):
    """A permutation of ``size`` rows seeded by (seed, the epoch ``epoch()`` names)."""

    def __init__(self, size: int, seed: int, epoch: Callable[[], int]) -> None:
        self.size, self.seed, self.epoch = size, seed, epoch

    def __len__(self) -> int:
        return self.size

    def __iter__(self) -> Iterator[int]:
        generator = torch.Generator().manual_seed(self.seed * 1_000_003 + self.epoch())
        return iter(torch.randperm(self.size, generator=generator).tolist())


def split_episodes(episodes: np.ndarray, val_fraction: float, seed: int) -> np.ndarray:
    """Boolean mask of validation rows: a seeded ``val_fraction`` of the episodes (>= 1 each side)."""
    unique = np.unique(episodes)
    if len(unique) < 2:
        raise ValueError(
            f"the pairs come from {len(unique)} episode(s); an episode-level train/val split "
            "needs at least 2"
        )
    count = min(len(unique) - 1, max(1, round(val_fraction * len(unique))))
    held_out = np.random.default_rng(seed).choice(unique, count, replace=False)
    return np.isin(episodes, held_out)


class PriorPairsDataModule(L.LightningDataModule):
    """Train/validation batches of (video, text) embedding pairs, split by episode."""

    def __init__(
        self,
        root: str,
        batch_size: int = 256,
        eval_batch_size: int = 1024,
        val_fraction: float = 0.1,
        seed: int | None = None,
    ) -> None:
        """Args:
            root: the pairs file (.npz) written by `zoo goals prior-pairs`, or its URL.
            batch_size: training pairs per batch.
            eval_batch_size: validation pairs per batch.
            val_fraction: share of the episodes held out for validation (at least one episode).
            seed: seed of the episode split and of the training order; None: the run's
                ``seed_everything`` value.
        """
        super().__init__()
        self.save_hyperparameters()
        if not 0 < val_fraction < 1:
            raise ValueError(f"val_fraction must be in (0, 1), got {val_fraction}")
        self._splits: dict[str, dict[str, torch.Tensor]] | None = None

    @property
    def splits(self) -> dict[str, dict[str, torch.Tensor]]:
        """{"train": columns, "val": columns}, loaded and split on first use."""
        if self._splits is None:
            arrays = read_prior_pairs(self.hparams.root)
            val = split_episodes(arrays["episode"], self.hparams.val_fraction, self.seed)
            columns = {
                name: torch.from_numpy(arrays[name])
                for name in ("video", "text", "caption_id", "episode")
            }
            columns["video"], columns["text"] = columns["video"].float(), columns["text"].float()
            mask = torch.from_numpy(val)
            train = {name: column[~mask] for name, column in columns.items()}
            valid = {name: column[mask] for name, column in columns.items()}
            size = int(columns["caption_id"].max()) + 1
            means, present = caption_means(train["video"], train["caption_id"], size)
            valid["caption_mean"] = means[valid["caption_id"]]
            valid["has_caption_mean"] = present[valid["caption_id"]]
            self._splits = {"train": train, "val": valid}
        return self._splits

    @property
    def seed(self) -> int:
        return run_seed(self.hparams.seed)

    @property
    def embed_dim(self) -> int:
        """Width of the file's embeddings (the prior's ``embed_dim`` must match)."""
        return int(self.splits["train"]["video"].shape[1])

    def train_dataloader(self) -> DataLoader:
        dataset = PairsDataset(self.splits["train"])
        trainer = self.trainer
        sampler = EpochPermutation(
            len(dataset), self.seed, lambda: trainer.current_epoch if trainer is not None else 0
        )
        return DataLoader(
            dataset, batch_size=self.hparams.batch_size, sampler=sampler, drop_last=True,
            collate_fn=_batch_as_is,
        )

    def val_dataloader(self) -> DataLoader:
        return DataLoader(
            PairsDataset(self.splits["val"]), batch_size=self.hparams.eval_batch_size,
            collate_fn=_batch_as_is,
        )


def caption_means(
    video: torch.Tensor, caption_id: torch.Tensor, size: int
) -> tuple[torch.Tensor, torch.Tensor]:
    """Unit-norm mean video embedding of caption ids 0..size-1 (size, D), and which have any."""
    sums = torch.zeros(size, video.shape[1]).index_add_(0, caption_id, video)
    present = torch.bincount(caption_id, minlength=size) > 0
    return torch.nn.functional.normalize(sums, dim=-1), present


__all__ = ["PriorPairsDataModule", "caption_means", "split_episodes"]
