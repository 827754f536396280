"""CrafterPlay datamodule on real shards from `zoo data generate` (random expert, crafter)."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np
import pytest
import torch

from datamodules.crafterplay import CrafterPlayDataModule, episode_split
from zoo.data.generate import GenerationConfig, generate
from zoo.data.reader import filter_noops, iter_chunks, list_shards

NUM_EPISODES = 8


@pytest.fixture(scope="module")
def crafterplay(tmp_path_factory) -> Path:
    """4 shards of 2 episodes (<= 80 steps), chunks of 32 steps: ~5 s to write."""
    out = tmp_path_factory.mktemp("crafterplay")
    config = GenerationConfig(
        expert="random", episodes=NUM_EPISODES, seed=0, env="crafter", episodes_per_shard=2,
        chunk_length=32, max_steps=80,
    )
    generate(config, out, progress=False)
    return out


def _module(root: Path, **kwargs) -> CrafterPlayDataModule:
    args = dict(seq_len=1, batch_size=4, num_workers=0, val_fraction=0.25, test_fraction=0.25)
    return CrafterPlayDataModule(str(root), **{**args, **kwargs})


def _episodes(module: CrafterPlayDataModule, split: str) -> set[int]:
    return {e for batch in module.dataset(split) for e in batch["episode"].flatten().tolist()}


def test_splits_hold_disjoint_episodes_covering_all(crafterplay: Path) -> None:
    module = _module(crafterplay, noop_filter=False)
    episodes = {split: _episodes(module, split) for split in ("train", "val", "test")}
    assert all(episodes.values())
    assert not episodes["train"] & episodes["val"]
    assert not episodes["train"] & episodes["test"]
    assert not episodes["val"] & episodes["test"]
    assert set.union(*episodes.values()) == set(range(NUM_EPISODES))


def test_episode_split_is_deterministic_with_given_fractions() -> None:
    splits = [episode_split(e, 0.1, 0.2) for e in range(20_000)]
    assert splits == [episode_split(e, 0.1, 0.2) for e in range(20_000)]
    counts = Counter(splits)
    assert abs(counts["val"] / 20_000 - 0.1) < 0.01 and abs(counts["test"] / 20_000 - 0.2) < 0.01
    assert [episode_split(e, 0.1, 0.2, salt=1) for e in range(50)] != splits[:50]


def test_sequences_are_the_filtered_steps_in_order(crafterplay: Path) -> None:
    """Unshuffled split with every episode: sequences join back into the filtered chunks."""
    module = _module(crafterplay, seq_len=7, batch_size=3, val_fraction=0.99, test_fraction=0.0)
    batches = list(module.dataset("val"))
    assert batches[0]["frames"].dtype == torch.uint8
    assert batches[0]["frames"].shape[1:] == (7, 144, 144, 3)
    got = {k: np.concatenate([b[k].flatten(0, 1).numpy() for b in batches]) for k in batches[0]}

    chunks = [filter_noops(c, min_run=20) for c in iter_chunks(list_shards(crafterplay))]
    chunks = [c for c in chunks if len(c["actions"]) and episode_split(c["meta"]["episode"], 0.99, 0.0) == "val"]
    actions = np.concatenate([c["actions"] for c in chunks])
    frames = np.concatenate([c["frames"] for c in chunks])
    episode = np.concatenate([np.full(len(c["actions"]), c["meta"]["episode"]) for c in chunks])
    n = len(got["actions"])
    assert n == len(actions) // 7 * 7
    assert np.array_equal(got["actions"], actions[:n])
    assert np.array_equal(got["frames"], frames[:n])
    assert np.array_equal(got["episode"], episode[:n])
    starts = np.flatnonzero(np.r_[True, episode[1:n] != episode[: n - 1]])
    assert np.array_equal(np.flatnonzero(got["first"]), starts)
    # noop filtering kept no short noop runs
    noop_runs = np.concatenate([c["noop_run"] for c in chunks])[:n]
    assert ((noop_runs == 0) | (noop_runs >= 20)).all()


def test_workers_read_different_shards(crafterplay: Path) -> None:
    kwargs = dict(seq_len=4, noop_filter=False, val_fraction=0.0, test_fraction=0.0, shuffle_buffer=0)

    def sequences(num_workers: int) -> Counter:
        loader = _module(crafterplay, num_workers=num_workers, **kwargs).train_dataloader()
        return Counter(
            (tuple(e), tuple(a))
            for batch in loader
            for e, a in zip(batch["episode"].tolist(), batch["actions"].tolist(), strict=True)
        )

    single, parallel = sequences(0), sequences(2)
    assert max(parallel.values()) == 1  # nothing read twice
    # each worker packs its own shards, so only sequences inside one shard can be compared
    assert sum(parallel.values()) >= sum(single.values()) - 4
    assert sum(parallel.values()) > 0


def test_with_epoch_fixes_the_epoch_length(crafterplay: Path) -> None:
    module = _module(crafterplay, seq_len=16, batch_size=2, train_batches_per_epoch=5)
    assert sum(1 for _ in module.train_dataloader()) == 5


def test_bad_fractions_and_missing_data_are_clear_errors(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="val_fraction=0.5 and test_fraction=0.5"):
        CrafterPlayDataModule(str(tmp_path), val_fraction=0.5, test_fraction=0.5)
    with pytest.raises(FileNotFoundError, match="manifest.json"):
        _module(tmp_path).dataset("train")
