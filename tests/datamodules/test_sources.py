"""Training on several CrafterPlay folders with weights (expert data + DAgger rounds)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from datamodules.crafterplay import CrafterPlayDataModule
from datamodules.seeded_shuffle import WeightedDraws
from zoo.agents import dataset_agent
from zoo.data.generate import GenerationConfig, generate
from zoo.data.sequences import ShardSources, pack_sequences


def _play(out: Path, seed: int, episodes: int, max_steps: int) -> Path:
    config = GenerationConfig(
        expert="random", episodes=episodes, seed=seed, env="crafter", episodes_per_shard=1,
        chunk_length=32, max_steps=max_steps,
    )
    generate(config, out, progress=False, build_agent=dataset_agent)
    return out


@pytest.fixture(scope="module")
def two_folders(tmp_path_factory) -> tuple[Path, Path]:
    """A: 4 episodes of <= 40 steps; B: 2 episodes of <= 80 steps (one shard per episode)."""
    root = tmp_path_factory.mktemp("sources")
    return _play(root / "a", 0, 4, 40), _play(root / "b", 1, 2, 80)


def test_weighted_draws_give_each_folder_its_share_of_steps(two_folders) -> None:
    a, b = two_folders
    sources = ShardSources([a, b], [3.0, 1.0])
    draws = WeightedDraws(salt=0)
    draws.start_epoch(seed=0, epoch=0)
    steps = np.zeros(2)
    for _ in range(3000):
        for shard in draws(iter(sources)):
            steps[shard["source"]] += shard["steps"]
    assert abs(steps[0] / steps.sum() - 0.75) < 0.02  # weights are shares of steps, not shards
    draws.start_epoch(seed=0, epoch=0)
    again = [s["url"] for s in draws(iter(sources))]
    draws.start_epoch(seed=0, epoch=0)
    assert again == [s["url"] for s in draws(iter(sources))]  # (seed, epoch) fixes the draws


def test_module_reads_every_folder(two_folders) -> None:
    a, b = two_folders
    kwargs = dict(seq_len=8, batch_size=2, num_workers=0, noop_filter=False, val_fraction=0.99,
                  test_fraction=0.0)
    sources = [{"root": str(a), "weight": 1}, {"root": str(b), "weight": 2}]
    both = CrafterPlayDataModule(sources=sources, **kwargs)
    only = [CrafterPlayDataModule(str(root), **kwargs) for root in (a, b)]
    count = lambda m: sum(batch["actions"].numel() for batch in m.dataset("val"))  # noqa: E731
    assert count(both) == pytest.approx(sum(count(m) for m in only), abs=16)

    kwargs.update(val_fraction=0.0, train_batches_per_epoch=6, shuffle_buffer=4)
    train = CrafterPlayDataModule(sources=sources, seed=0, **kwargs)
    batches = list(train.dataset("train"))
    assert len(batches) == 6 and batches[0]["frames"].shape == (2, 8, 144, 144, 3)


def test_a_new_folder_starts_a_new_episode_even_with_the_same_episode_index() -> None:
    def chunk(source: int, offset: int, n: int = 3) -> dict:
        return {
            "frames": np.zeros((n, 1), np.uint8), "actions": np.zeros(n, np.int64),
            "meta": {"episode": 0, "offset": offset, "source": source},
        }

    chunks = [chunk(0, 0), chunk(0, 3), chunk(1, 0), chunk(1, 3)]
    (sequence,) = pack_sequences(chunks, seq_len=12)
    assert sequence["first"].nonzero()[0].tolist() == [0, 6]


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(), "exactly one"),
        (dict(root="x", sources=[{"root": "y"}]), r"exactly one.*--data.init_args.sources=null"),
        (dict(sources=[]), "empty"),
        (dict(sources=[{"weight": 1}]), r"sources\[0\]"),
        (dict(sources=[{"root": "a"}, {"root": "b", "weight": 0}]), r"sources\[1\].weight"),
        (dict(sources=[{"root": "a", "wieght": 2}]), "unknown keys"),
    ],
)
def test_bad_sources_are_clear_errors(kwargs, message) -> None:
    with pytest.raises(ValueError, match=message):
        CrafterPlayDataModule(**kwargs)
