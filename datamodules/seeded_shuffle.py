"""Shuffles whose order is a function of the run's seed, the epoch, the rank and the worker.

webdataset's ``shuffle`` seeds itself from the process id and the clock, so ``seed_everything``
cannot make a run reproducible. Seeding from the DataLoader worker's torch seed (the earlier
approach) repeats a run from scratch but not a resumed one: Lightning does not checkpoint the
global RNG, so after ``--ckpt_path`` the workers draw other seeds. Here every shuffle draws from
``random.Random(f"{seed}:{epoch}:{rank}:{worker}:{salt}:{pass}")``, where ``EpochSeededStream``
takes the epoch from the trainer: a resumed run sees the same order from its first new epoch as
a straight one.

Where the trainer's epoch is read: Lightning restores the loop state *after* it builds the
dataloaders, but before it iterates them. So the stream reads it at iteration time in the main
process (``num_workers=0``), and when it is pickled into worker processes, which happens when
the first epoch they serve starts; workers then count epochs themselves, so they must stay alive
across epochs (``persistent_workers=True``, as ``seeded_loader`` builds the loader).
"""

from __future__ import annotations

import multiprocessing
import os
import random
from collections.abc import Callable, Iterable, Iterator
from typing import Any, Protocol

from torch.utils.data import DataLoader, IterableDataset
from webdataset.utils import pytorch_worker_info


def run_seed(seed: int | None) -> int:
    """``seed``, or the one ``seed_everything`` set (``PL_GLOBAL_SEED``), else 0."""
    if seed is not None:
        return seed
    return int(os.environ.get("PL_GLOBAL_SEED", 0))


class EpochSeeded(Protocol):
    """A pipeline stage whose randomness is a function of (seed, epoch)."""

    def start_epoch(self, seed: int, epoch: int) -> None: ...


class _PassSeeded:
    """A stage whose n-th pass of an epoch draws from rng(seed, epoch, rank, worker, salt, n)."""

    def __init__(self, salt: int) -> None:
        self.salt = salt
        self.seed = 0
        self.epoch = 0
        self.passes = 0

    def start_epoch(self, seed: int, epoch: int) -> None:
        self.seed, self.epoch, self.passes = seed, epoch, 0

    def _next_pass_rng(self) -> random.Random:
        rank, _, worker, _ = pytorch_worker_info()
        rng = random.Random(f"{self.seed}:{self.epoch}:{rank}:{worker}:{self.salt}:{self.passes}")
        self.passes += 1  # a stream repeated within an epoch (with_epoch) reorders each pass
        return rng


class SeededShuffle(_PassSeeded):
    """A shuffle-buffer stage; ``start_epoch`` fixes the order of the passes that follow."""

    def __init__(self, bufsize: int, salt: int) -> None:
        super().__init__(salt)
        self.bufsize = bufsize

    def __call__(self, items: Iterable) -> Iterator:
        rng = self._next_pass_rng()
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


class WeightedDraws(_PassSeeded):
    """Draws shards with replacement in proportion to their ``draw_weight`` (several datasets
    mixed by weight), as many per pass as it is given; ``start_epoch`` fixes the draws."""

    def __call__(self, items: Iterable[dict]) -> Iterator[dict]:
        rng = self._next_pass_rng()
        items = list(items)
        if items:
            yield from rng.choices(items, weights=[it["draw_weight"] for it in items], k=len(items))


class EpochSeededStream(IterableDataset):
    """A pipeline whose every iteration is one epoch: re-seeds its shuffles, then streams.

    ``current_epoch`` (the trainer's, in the main process) names the epoch an iteration is;
    without it, or in a worker process, epochs are counted from ``first_epoch``.
    """

    def __init__(
        self,
        pipeline: Iterable,
        shuffles: list[EpochSeeded],
        seed: int,
        first_epoch: int = 0,
        current_epoch: Callable[[], int] | None = None,
    ) -> None:
        self.pipeline = pipeline
        self.shuffles = shuffles
        self.seed = seed
        self.next_epoch = first_epoch
        self.current_epoch = current_epoch

    def _follow_trainer(self) -> None:
        if self.current_epoch is not None:
            self.next_epoch = self.current_epoch()

    def __getstate__(self) -> dict:
        # pickled into DataLoader workers as the first epoch they serve starts
        self._follow_trainer()
        return {**self.__dict__, "current_epoch": None}

    def __iter__(self) -> Iterator:
        self._follow_trainer()
        for shuffle in self.shuffles:
            shuffle.start_epoch(self.seed, self.next_epoch)
        self.next_epoch += 1
        return iter(self.pipeline)


def seeded_loader(
    dataset: IterableDataset, num_workers: int, pin_memory: bool, trainer: Any = None
) -> DataLoader:
    """A DataLoader over a batched stream; workers are spawned and kept across epochs.

    With a ``trainer``, an ``EpochSeededStream`` follows its ``current_epoch`` (so a resumed
    fit continues the straight fit's order).

    Spawned, not forked: JAX (loaded by the envs and experts) runs threads, and forking a
    process with threads can deadlock the child. Kept alive: ``EpochSeededStream`` counts
    epochs in the workers' copies, and a spawn start (re-importing torch) is paid once.
    """
    if trainer is not None and isinstance(dataset, EpochSeededStream):
        dataset.current_epoch = lambda: trainer.current_epoch  # dropped when pickled
    workers = num_workers > 0
    return DataLoader(
        dataset,
        batch_size=None,
        num_workers=num_workers,
        pin_memory=pin_memory,
        multiprocessing_context=multiprocessing.get_context("spawn") if workers else None,
        persistent_workers=workers,
    )


__all__ = ["EpochSeeded", "EpochSeededStream", "SeededShuffle", "run_seed", "seeded_loader"]
