"""C-Steve-1 data: CrafterPlay sequences with relabelled goals from `zoo goals embed` shards."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from datamodules.csteve1 import CSteve1DataModule
from zoo.cli import main
from zoo.goals.embed import load_embedding_manifest, read_embedding_shard

MAX_GAP = 6


def _module(play: Path, embeddings: Path, **kwargs) -> CSteve1DataModule:
    args = {
        "max_gap": MAX_GAP, "seq_len": 32, "batch_size": 2, "num_workers": 0, "val_fraction": 0.0,
        "test_fraction": 0.0, "shuffle_buffer": 1, "pin_memory": False, "noop_filter": False,
        "seed": 0,
    }
    return CSteve1DataModule(str(play), str(embeddings), **{**args, **kwargs})


def _batches(module: CSteve1DataModule, epoch: int = 0) -> list[dict[str, torch.Tensor]]:
    return list(module.dataset("train", first_epoch=epoch))


def _all_goals(embeddings: Path) -> dict[int, dict[str, np.ndarray]]:
    out = {}
    for entry in load_embedding_manifest(embeddings)["shards"]:
        out.update(read_embedding_shard(embeddings / entry["file"]))
    return out


def _assert_goals_of_their_episodes(batches: list[dict], stored: dict) -> None:
    """Every step's goal is its own episode's clip at its goal step, 0..MAX_GAP-1 steps ahead
    (zeros where it has none)."""
    assert batches
    for batch in batches:
        b, s = batch["actions"].shape
        assert batch["goal"].shape == (b, s, 64) and batch["goal"].dtype == torch.float16
        assert batch["goal_mask"].dtype == torch.bool and batch["goal_step"].dtype == torch.int64
        ahead = batch["goal_step"] - batch["step"]
        assert (ahead >= 0).all() and (ahead < MAX_GAP).all()
        for i in range(b):
            for t in range(s):
                episode, goal_step = int(batch["episode"][i, t]), int(batch["goal_step"][i, t])
                assert goal_step < len(stored[episode]["goal"]), "goal outside its episode"
                expected = stored[episode]["goal"][goal_step] if batch["goal_mask"][i, t] else 0
                np.testing.assert_array_equal(batch["goal"][i, t].numpy(), expected)


def test_batches_carry_goals_from_the_same_episode_within_the_gap(
    steve_play: Path, steve_embeddings: Path
) -> None:
    _assert_goals_of_their_episodes(
        _batches(_module(steve_play, steve_embeddings)), _all_goals(steve_embeddings)
    )


@pytest.fixture(scope="module")
def chunked(steve_cclip: Path, tmp_path_factory) -> tuple[Path, Path]:
    """3 random-expert episodes of up to 60 steps in chunks of 16, and their embeddings."""
    play, embed = tmp_path_factory.mktemp("chunked_play"), tmp_path_factory.mktemp("chunked_embed")
    assert main(["data", "generate", "--expert", "random", "--env", "crafter", "--episodes", "3",
                 "--episodes-per-shard", "2", "--chunk-length", "16", "--max-steps", "60",
                 "--seed", "1", "--out", str(play), "--no-progress"]) == 0
    assert main(["goals", "embed", "--checkpoint", str(steve_cclip), "--src", str(play),
                 "--out", str(embed), "--no-progress"]) == 0
    return play, embed


def test_later_chunks_of_an_episode_get_the_goals_of_their_own_steps(
    chunked: tuple[Path, Path],
) -> None:
    """An episode read in several chunks: the goals attached to its 2nd, 3rd... chunk are
    those of that chunk's steps, not of the episode's first steps."""
    play, embed = chunked
    batches = _batches(_module(play, embed))
    assert int(torch.cat([b["step"] for b in batches]).max()) >= 32  # a third chunk was read
    _assert_goals_of_their_episodes(batches, _all_goals(embed))


@pytest.mark.parametrize("uncond_prob", [0.0, 1.0])
def test_uncond_prob_sets_which_steps_go_without_a_goal(
    steve_play: Path, steve_embeddings: Path, uncond_prob: float
) -> None:
    """Per piece (the default): with 0 every step keeps its goal, with 1 none has one (its goal
    is zeros, the input of the unconditional policy guidance subtracts)."""
    batches = _batches(_module(steve_play, steve_embeddings, uncond_prob=uncond_prob))
    mask = torch.cat([b["goal_mask"].flatten() for b in batches])
    goal = torch.cat([b["goal"].flatten(0, 1) for b in batches])
    assert len(mask) > 0
    if uncond_prob == 0.0:
        assert mask.all() and (goal != 0).any(dim=1).all()
    else:
        assert not mask.any() and (goal == 0).all()


def test_uncond_prob_is_the_share_of_pieces_without_a_goal(
    steve_play: Path, steve_embeddings: Path
) -> None:
    """0.5 per piece: about half the relabelled pieces (runs of one goal step) have no goal."""
    batches = _batches(_module(steve_play, steve_embeddings, uncond_prob=0.5))
    pieces = conditioned = 0
    for batch in batches:
        for steps, mask in zip(batch["goal_step"], batch["goal_mask"]):
            starts = torch.ones_like(steps, dtype=torch.bool)
            starts[1:] = steps[1:] != steps[:-1]
            pieces += int(starts.sum())
            conditioned += int(mask[starts].sum())
    assert pieces > 100
    # ~240 pieces: the binomial std of the share is ~0.03
    assert 0.3 < conditioned / pieces < 0.7


def test_goals_follow_the_seed_and_change_with_the_epoch(
    steve_play: Path, steve_embeddings: Path
) -> None:
    def goal_steps(seed: int, epoch: int) -> torch.Tensor:
        module = _module(steve_play, steve_embeddings, seed=seed)
        return torch.cat([b["goal_step"] for b in _batches(module, epoch)])

    assert torch.equal(goal_steps(0, 0), goal_steps(0, 0))
    assert not torch.equal(goal_steps(0, 0), goal_steps(0, 1))
    assert not torch.equal(goal_steps(0, 0), goal_steps(1, 0))


def test_noop_filter_drops_goals_with_their_steps(steve_play: Path, steve_embeddings: Path) -> None:
    module = _module(steve_play, steve_embeddings, noop_filter=True, min_noop_run=5)
    for batch in _batches(module):
        assert batch["goal"].shape[:2] == batch["actions"].shape
        assert (batch["goal_step"] >= batch["step"]).all()


def test_embeddings_of_other_data_are_refused(steve_embeddings: Path, tmp_path: Path) -> None:
    other = tmp_path / "other"
    assert main(["data", "generate", "--expert", "random", "--env", "crafter", "--episodes", "1",
                 "--max-steps", "20", "--seed", "3", "--out", str(other), "--no-progress"]) == 0
    module = _module(other, steve_embeddings)
    with pytest.raises(ValueError, match="rerun zoo goals embed|lists"):
        _batches(module)


def test_partial_embeddings_train_on_the_embedded_shards_only(
    steve_play: Path, steve_cclip: Path, tmp_path: Path
) -> None:
    assert main(["goals", "embed", "--checkpoint", str(steve_cclip), "--src", str(steve_play),
                 "--out", str(tmp_path), "--shards", "0:1", "--no-progress"]) == 0
    with pytest.raises(ValueError, match="partial_embeddings=true"):
        _batches(_module(steve_play, tmp_path))
    with pytest.warns(UserWarning, match="the 1 of 2 CrafterPlay shards"):
        batches = _batches(_module(steve_play, tmp_path, partial_embeddings=True))
    embedded = set(_all_goals(tmp_path))
    assert {int(e) for b in batches for e in b["episode"].flatten()} <= embedded


def test_uncond_per_sequence_drops_whole_sequences_and_follows_the_epoch(
    steve_play: Path, steve_embeddings: Path
) -> None:
    """STEVE-1's unconditional goals: a sequence has all its goals or none; which ones is
    seeded and redrawn per epoch."""
    def masks(epoch: int) -> torch.Tensor:
        module = _module(steve_play, steve_embeddings, uncond_prob=0.5, uncond_per="sequence")
        return torch.cat([b["goal_mask"] for b in _batches(module, epoch)])

    first = masks(0)
    whole = first.all(dim=1) | ~first.any(dim=1)
    assert whole.all() and first.all(dim=1).any() and (~first.any(dim=1)).any()
    assert torch.equal(first, masks(0))
    assert any(not torch.equal(first, masks(epoch)) for epoch in (1, 2, 3))
