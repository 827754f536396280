"""CrafterPlay datamodule on real shards from `zoo data generate` (random expert, crafter)."""

from __future__ import annotations

import pickle
import re
import shutil
import tarfile
from collections import Counter
from pathlib import Path
from types import SimpleNamespace

import lightning as L
import numpy as np
import pytest
import torch

from datamodules.crafterplay import CrafterPlayDataModule, episode_split
from datamodules.seeded_shuffle import seeded_loader
from zoo.agents import dataset_agent
from zoo.data.generate import GenerationConfig, generate
from zoo.data.manifest import MissingDatasetError
from zoo.data.reader import CorruptShardError, filter_noops, iter_chunks, list_shards

NUM_EPISODES = 8


@pytest.fixture(scope="module")
def crafterplay(tmp_path_factory) -> Path:
    """4 shards of 2 episodes (<= 80 steps), chunks of 32 steps: ~5 s to write."""
    out = tmp_path_factory.mktemp("crafterplay")
    config = GenerationConfig(
        expert="random", episodes=NUM_EPISODES, seed=0, env="crafter", episodes_per_shard=2,
        chunk_length=32, max_steps=80,
    )
    generate(config, out, progress=False, build_agent=dataset_agent)
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


def test_a_dataset_without_training_episodes_is_an_error_not_an_endless_empty_epoch(
    crafterplay: Path,
) -> None:
    from zoo.data.sequences import episode_split as split_of

    salt = next(s for s in range(1000)  # a salt that puts all 8 episodes out of training
                if all(split_of(e, 0.45, 0.5, s) != "train" for e in range(NUM_EPISODES)))
    module = _module(crafterplay, val_fraction=0.45, test_fraction=0.5, split_salt=salt)
    with pytest.raises(ValueError, match=f"no training episodes in {crafterplay}: all 8"):
        module.dataset("train")
    assert _episodes(module, "val") | _episodes(module, "test")  # the other splits still read


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


def test_min_noop_run_sets_the_shortest_noop_run_kept(crafterplay: Path) -> None:
    """``min_noop_run: 3``: every step the data module yields is a non-noop or a noop of a run
    of at least 3 (never a sleeping step), and every such step is yielded: the runs of 3-19
    noops the paper's default of 20 drops are kept."""
    module = _module(crafterplay, seq_len=1, batch_size=1, val_fraction=0.99, test_fraction=0.0,
                     min_noop_run=3)
    got = [(int(b["episode"][0, 0]), int(b["step"][0, 0])) for b in module.dataset("val")]
    expected, short_runs = [], 0
    for chunk in iter_chunks(list_shards(crafterplay)):
        episode = chunk["meta"]["episode"]
        if episode_split(episode, 0.99, 0.0) != "val":
            continue
        noop, run = chunk["noop"].astype(bool), chunk["noop_run"]
        keep = (~noop | (run >= 3)) & ~chunk["state"]["player_sleeping"].astype(bool)
        expected += [(episode, chunk["meta"]["offset"] + int(i)) for i in np.flatnonzero(keep)]
        short_runs += int((noop & (run >= 3) & (run < 20)).sum())
    assert short_runs > 0, "the data holds no noop run of 3-19 steps: the test shows nothing"
    assert got == expected


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


def test_ddp_ranks_read_disjoint_shards_that_cover_the_split(
    crafterplay: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    kwargs = dict(seq_len=4, noop_filter=False, val_fraction=0.0, test_fraction=0.0)
    monkeypatch.setenv("WORLD_SIZE", "2")  # what DDP sets for each rank (webdataset reads it)
    seen = []
    for rank in ("0", "1"):
        monkeypatch.setenv("RANK", rank)
        seen.append(_episodes(_module(crafterplay, **kwargs), "train"))
    assert seen[0] and seen[1] and not seen[0] & seen[1]
    assert seen[0] | seen[1] == set(range(NUM_EPISODES))


def test_with_epoch_fixes_the_epoch_length(crafterplay: Path) -> None:
    module = _module(crafterplay, seq_len=16, batch_size=2, train_batches_per_epoch=5)
    assert sum(1 for _ in module.train_dataloader()) == 5


def test_bad_fractions_and_missing_data_are_clear_errors(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="val_fraction=0.5 and test_fraction=0.5"):
        CrafterPlayDataModule(str(tmp_path), val_fraction=0.5, test_fraction=0.5)
    with pytest.raises(MissingDatasetError, match="manifest.json"):  # zoo fit: one line
        _module(tmp_path).dataset("train")


def _order(loader, epochs: int) -> list[list[tuple]]:
    """(episode, step) of each sequence's first step, per epoch, in batch order."""
    return [
        [
            (int(e[0]), int(s[0]))
            for batch in loader
            for e, s in zip(batch["episode"], batch["step"], strict=True)
        ]
        for _ in range(epochs)
    ]


def test_training_order_follows_the_seed_and_the_epoch(crafterplay: Path) -> None:
    kwargs = dict(seq_len=8, batch_size=2, val_fraction=0.0, test_fraction=0.0, shuffle_buffer=8)
    straight = _order(_module(crafterplay, seed=3, **kwargs).train_dataloader(), 3)
    assert straight == _order(_module(crafterplay, seed=3, **kwargs).train_dataloader(), 3)
    assert straight[0] != straight[1] != straight[2]  # each epoch its own order
    assert {e for e, _ in straight[0]} == {e for e, _ in straight[1]}  # of the same episodes
    assert _order(_module(crafterplay, seed=4, **kwargs).train_dataloader(), 1)[0] != straight[0]
    # a run resumed at epoch 1 sees what the straight run saw from epoch 1 on
    resumed = _module(crafterplay, seed=3, **kwargs)
    resumed_loader = seeded_loader(resumed.dataset("train", first_epoch=1), 0, False)
    assert _order(resumed_loader, 2) == straight[1:]


def test_seed_everything_sets_the_order_when_no_seed_is_given(crafterplay: Path) -> None:
    kwargs = dict(seq_len=8, batch_size=2, val_fraction=0.0, test_fraction=0.0, shuffle_buffer=8)
    orders = []
    for seed in (5, 5, 6):
        L.seed_everything(seed)
        orders.append(_order(_module(crafterplay, **kwargs).train_dataloader(), 1)[0])
    assert orders[0] == orders[1] != orders[2]


def test_worker_processes_are_spawned_and_keep_the_seeded_order(crafterplay: Path) -> None:
    # JAX runs threads, and a forked child of a threaded process can deadlock: workers are
    # spawned; they persist so the epoch count (and the order) carries across epochs.
    kwargs = dict(seq_len=8, batch_size=2, val_fraction=0.0, test_fraction=0.0, num_workers=2)
    loader = _module(crafterplay, seed=3, **kwargs).train_dataloader()
    assert loader.multiprocessing_context.get_start_method() == "spawn"
    assert loader.persistent_workers
    first = _order(loader, 2)
    assert first[0] != first[1]
    assert _order(_module(crafterplay, seed=3, **kwargs).train_dataloader(), 2) == first


def _cut_shard(crafterplay: Path, tmp_path: Path, where: str) -> tuple[Path, str]:
    """A copy of the dataset whose shard 1 (episodes 2 and 3) is cut inside a tar member, or
    exactly where its last episode begins (a cut that leaves a valid tar of whole episodes)."""
    root = tmp_path / where
    shutil.copytree(crafterplay, root)
    shard = list_shards(root)[1]
    with tarfile.open(shard) as tar:
        last_episode = [m for m in tar.getmembers() if m.name.startswith("e0000003_")]
    cut = last_episode[0].offset if where == "between-episodes" else last_episode[0].offset_data + 7
    Path(shard).write_bytes(Path(shard).read_bytes()[:cut])
    return root, shard


@pytest.mark.parametrize("where", ["inside-a-member", "between-episodes"])
def test_corrupt_shard_met_in_training_is_named_or_skipped(
    crafterplay: Path, tmp_path: Path, where: str
) -> None:
    root, shard = _cut_shard(crafterplay, tmp_path, where)
    kwargs = dict(seq_len=4, noop_filter=False, val_fraction=0.0, test_fraction=0.0)
    with pytest.raises(CorruptShardError, match=re.escape(shard)):
        list(_module(root, **kwargs).train_dataloader())

    warning = rf"skipped corrupt shard {re.escape(shard)} \(1 skipped so far"
    with pytest.warns(UserWarning, match=warning):
        loader = _module(root, skip_corrupt=True, **kwargs).train_dataloader()
        read = {e for e, _ in _order(loader, 1)[0]}
    assert read == set(range(NUM_EPISODES)) - {3}  # episode 2, read before the cut, is kept


def test_stream_takes_the_trainers_epoch_and_carries_it_into_workers(crafterplay: Path) -> None:
    # Lightning restores a resumed fit's epoch after building the loaders: the stream reads it
    # when iterated (main process) or when pickled into worker processes.
    kwargs = dict(seq_len=8, batch_size=2, val_fraction=0.0, test_fraction=0.0, seed=3)
    epochs = _order(seeded_loader(_module(crafterplay, **kwargs).dataset("train"), 0, False), 4)
    trainer = SimpleNamespace(current_epoch=2)  # as restored from a checkpoint
    loader = seeded_loader(_module(crafterplay, **kwargs).dataset("train"), 0, False, trainer)
    assert _order(loader, 1) == [epochs[2]]
    in_worker = pickle.loads(pickle.dumps(loader.dataset))  # what a spawned worker receives
    assert in_worker.current_epoch is None
    assert _order(seeded_loader(in_worker, 0, False), 2) == epochs[2:4]
