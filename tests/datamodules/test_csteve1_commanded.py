"""C-Steve-1 data from goal-directed CrafterPlay: commanded goals (the caption's embedding or
the completing clip's), their mix with hindsight, checked step by step on a tiny dataset."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from datamodules.csteve1 import CSteve1DataModule
from zoo.cli import main
from zoo.data.reader import iter_episodes, list_shards
from zoo.goals.embed import load_embedding_manifest, read_embedding_shard

ARGS = {
    "max_gap": 6, "seq_len": 32, "batch_size": 2, "num_workers": 0, "val_fraction": 0.0,
    "test_fraction": 0.0, "shuffle_buffer": 1, "pin_memory": False, "noop_filter": False,
    "seed": 0, "uncond_prob": 0.0,
}


@pytest.fixture(scope="module")
def play(tmp_path_factory) -> Path:
    """2 goal-directed crafter episodes of 150 steps, 30-action timeouts, in 2 shards."""
    out = tmp_path_factory.mktemp("instructed_play")
    assert main(["data", "generate", "--expert", "scripted", "--env", "crafter", "--episodes",
                 "2", "--episodes-per-shard", "1", "--max-steps", "150", "--seed", "1",
                 "--instructions", "captions", "--instruction-timeout", "30", "--out", str(out),
                 "--no-progress"]) == 0
    return out


@pytest.fixture(scope="module")
def embeddings(play: Path, steve_cclip: Path, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("instructed_embed")
    assert main(["goals", "embed", "--checkpoint", str(steve_cclip), "--src", str(play),
                 "--out", str(out), "--no-progress"]) == 0
    return out


def _records(embeddings: Path) -> dict[int, dict[str, np.ndarray]]:
    out = {}
    for entry in load_embedding_manifest(embeddings)["shards"]:
        out.update(read_embedding_shard(embeddings / entry["file"]))
    return out


def _steps(module: CSteve1DataModule):
    """(episode, step, goal, goal_step, goal_mask) of every step of every training batch."""
    for batch in module.dataset("train"):
        b, s = batch["actions"].shape
        for i in range(b):
            for t in range(s):
                yield (int(batch["episode"][i, t]), int(batch["step"][i, t]),
                       batch["goal"][i, t].numpy(), int(batch["goal_step"][i, t]),
                       bool(batch["goal_mask"][i, t]))


def _module(play: Path, embeddings: Path, **kwargs) -> CSteve1DataModule:
    return CSteve1DataModule(str(play), str(embeddings), **{**ARGS, **kwargs})


def test_commanded_steps_get_their_captions_mean_clip_embedding(play, embeddings) -> None:
    records = _records(embeddings)
    rows = np.concatenate([r["goal"] for r in records.values()]).astype(np.float32)
    captions = np.concatenate([r["caption"] for r in records.values()])
    episodes = {e["meta"]["episode"]: e for e in iter_episodes(list_shards(play))}
    checked = 0
    for episode, step, goal, goal_step, mask in _steps(_module(play, embeddings,
                                                             goal_source="commanded")):
        assert mask
        commanded = int(episodes[episode]["instruction"][step])
        if commanded >= 0 and (captions == commanded).any():  # hand-made caption embedding
            mean = rows[captions == commanded].mean(axis=0)
            np.testing.assert_allclose(goal, mean / np.linalg.norm(mean), atol=2e-3)
            assert goal_step == -1
            checked += 1
        else:  # no instruction (the final observation) or a caption that never fired
            assert goal_step >= step
            np.testing.assert_array_equal(goal, records[episode]["goal"][goal_step])
    assert checked > 100


def test_completion_goals_are_the_clip_that_completed_the_instruction(play, embeddings) -> None:
    records = _records(embeddings)
    completion = {}
    for episode in iter_episodes(list_shards(play)):
        for start, stop, _, outcome in episode["meta"]["instructions"]:
            for t in range(start, stop):
                completion[episode["meta"]["episode"], t] = stop - 1 if outcome == "completed" else None
    assert any(v is None for v in completion.values()) and any(completion.values())
    module = _module(play, embeddings, goal_source="commanded", commanded_goal="completion")
    for episode, step, goal, goal_step, _ in _steps(module):
        done = completion.get((episode, step))
        if done is not None:
            assert goal_step == done
        else:
            assert step <= goal_step < step + ARGS["max_gap"]  # hindsight
        np.testing.assert_array_equal(goal, records[episode]["goal"][goal_step])


def test_mix_weights_zero_and_one_are_hindsight_and_commanded(play, embeddings) -> None:
    def goals(**kwargs) -> torch.Tensor:
        return torch.cat([b["goal"] for b in _module(play, embeddings, **kwargs).dataset("train")])

    hindsight, commanded = goals(), goals(goal_source="commanded")
    assert not torch.equal(hindsight, commanded)
    assert torch.equal(goals(goal_source="mix", commanded_weight=0.0), hindsight)
    assert torch.equal(goals(goal_source="mix", commanded_weight=1.0), commanded)
    half = goals(goal_source="mix", commanded_weight=0.5)
    assert not torch.equal(half, hindsight) and not torch.equal(half, commanded)


def test_uncond_per_sequence_drops_whole_sequences_of_commanded_goals(play, embeddings) -> None:
    module = _module(play, embeddings, goal_source="commanded", uncond_prob=0.5,
                     uncond_per="sequence")
    masks = torch.cat([b["goal_mask"] for b in module.dataset("train")])
    assert (masks.all(dim=1) | ~masks.any(dim=1)).all()
    assert masks.all(dim=1).any() and (~masks.any(dim=1)).any()


def test_commanded_goals_need_goal_directed_data(steve_play, steve_embeddings) -> None:
    module = _module(steve_play, steve_embeddings, goal_source="mix")
    with pytest.raises(ValueError, match="generated without instructions"):
        module.dataset("train")


def test_prior_goals_are_the_priors_goals_of_the_caption_text(
    play, embeddings, steve_cclip, tmp_path
) -> None:
    """``commanded_goal: prior``: a commanded step's goal is what GoalEncoder gives its
    caption's text, the goal a typed instruction gets at play time."""
    from zoo.agents.csteve1_agent import GoalEncoder
    from zoo.models.prior import CVAEPrior, PriorConfig
    from zoo.weights.export import save_exported

    torch.manual_seed(0)
    prior = save_exported(CVAEPrior(PriorConfig(embed_dim=64, hidden=16, latent_dim=4)),
                          tmp_path / "prior")
    module = _module(play, embeddings, goal_source="commanded", commanded_goal="prior",
                     cclip=str(steve_cclip), prior=str(prior), prior_samples=3)
    encoder = GoalEncoder.load(steve_cclip, prior)
    episodes = {e["meta"]["episode"]: e for e in iter_episodes(list_shards(play))}
    checked = 0
    for episode, step, goal, goal_step, _ in _steps(module):
        commanded = int(episodes[episode]["instruction"][step])
        if commanded < 0:
            continue
        expected = encoder.from_caption_ids([commanded] * 3, seed=commanded).numpy()
        assert np.abs(expected - goal).max(axis=1).min() < 2e-3  # one of its 3 samples
        assert goal_step == -1
        checked += 1
    assert checked > 100


def test_prior_goals_need_the_checkpoints(play, embeddings) -> None:
    module = _module(play, embeddings, goal_source="commanded", commanded_goal="prior")
    with pytest.raises(ValueError, match=r"needs data.init_args.cclip and prior"):
        module.dataset("train")
