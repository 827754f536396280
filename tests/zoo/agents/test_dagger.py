"""DAgger rollouts: the learner plays, the expert's labels are stored, the manifest says so."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from zoo.agents.dagger import DaggerMixture
from zoo.cli import main
from zoo.data.generate import generate
from zoo.data.reader import iter_episodes, list_shards
from zoo.data.shard_generator import DaggerSettings, GenerationConfig
from zoo.envs.base import Step
from zoo.envs.constants import NUM_ACTIONS, Action
from zoo.experts.scripted import ScriptedExpert
from zoo.models.cclip import CCLIPConfig, CCLIPModel
from zoo.models.cvpt import CVPTConfig, CVPTModel
from zoo.models.prior import CVAEPrior, PriorConfig
from zoo.models.csteve1 import CSteve1Config, CSteve1Model
from zoo.weights.export import checkpoint_sha256, save_exported

SIZES = dict(d_model=32, d_ff=64, n_heads=2, n_layers=1, impala_channels=(4, 8, 8),
             encoder_hidden=32, memory_len=3)


class ConstantAgent:
    """Always plays one action (a stand-in learner or expert)."""

    name = "constant"
    needs_pixels = False

    def __init__(self, action: int, num_envs: int) -> None:
        self.action, self.num_envs, self.resets = action, num_envs, 0

    def reset(self, seeds, mask=None) -> None:
        self.resets += 1

    def act(self, step) -> np.ndarray:
        return np.full(self.num_envs, self.action, np.int32)


def _step(n: int) -> Step:
    return Step(None, {}, np.zeros(n), np.zeros(n, bool), None)


@pytest.mark.parametrize("beta, played", [(0.0, 3), (1.0, 5)])
def test_mixture_plays_learner_or_expert_and_always_labels_with_the_expert(beta, played) -> None:
    mixture = DaggerMixture(ConstantAgent(3, 4), ConstantAgent(5, 4), 4, beta, "step")
    mixture.reset(np.arange(4))
    assert (mixture.act(_step(4)) == played).all()
    assert (mixture.labels == 5).all() and (mixture.learner_actions == 3).all()


def test_mixture_draws_follow_the_episode_seed_and_beta() -> None:
    n = 2000
    episode = DaggerMixture(ConstantAgent(3, n), ConstantAgent(5, n), n, 0.3, "episode")
    episode.reset(np.arange(n))
    first = episode.act(_step(n))
    assert abs((first == 5).mean() - 0.3) < 0.04  # the expert plays ~beta of the episodes
    assert (episode.act(_step(n)) == first).all()  # ... for the whole episode
    again = DaggerMixture(ConstantAgent(3, n), ConstantAgent(5, n), n, 0.3, "episode")
    again.reset(np.arange(n))
    assert (again.act(_step(n)) == first).all()  # seeded by the episode seeds alone

    step = DaggerMixture(ConstantAgent(3, 1), ConstantAgent(5, 1), 1, 0.3, "step")
    step.reset(np.array([7]))
    share = np.mean([step.act(_step(1))[0] == 5 for _ in range(3000)])
    assert abs(share - 0.3) < 0.03  # a fresh draw at every step


def test_mixture_rejects_bad_arguments() -> None:
    with pytest.raises(ValueError, match="beta"):
        DaggerMixture(ConstantAgent(0, 1), ConstantAgent(0, 1), 1, 1.5)
    with pytest.raises(ValueError, match="mix"):
        DaggerMixture(ConstantAgent(0, 1), ConstantAgent(0, 1), 1, 0.5, "round")


@pytest.fixture(scope="module")
def learner(tmp_path_factory) -> Path:
    torch.manual_seed(0)
    model = CVPTModel(CVPTConfig.from_name("tiny", NUM_ACTIONS, **SIZES)).eval()
    return save_exported(model, tmp_path_factory.mktemp("learner") / "cvpt")


PLAY = ["--env", "crafter", "--episodes", "2", "--episodes-per-shard", "1", "--max-steps", "60",
        "--seed", "3", "--no-progress"]


def _dagger_argv(learner: Path, out: Path, beta: str = "0.25", num_envs: int = 2) -> list[str]:
    return ["data", "dagger", "--checkpoint", str(learner), "--beta", beta, "--mix", "step",
            "--round", "2", *PLAY, "--num-envs", str(num_envs), "--out", str(out)]


def _shas(root: Path) -> dict[str, str]:
    manifest = json.loads((root / "manifest.json").read_text())
    return {e["file"]: e["sha256"] for e in manifest["shards"]}


@pytest.fixture(scope="module")
def dagger_data(learner: Path, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("dagger") / "r1"
    assert main(_dagger_argv(learner, out)) == 0
    return out


def test_dagger_manifest_records_the_round_learner_and_beta(dagger_data, learner) -> None:
    manifest = json.loads((dagger_data / "manifest.json").read_text())
    dagger = manifest["config"]["dagger"]
    assert dagger["round"] == 2 and dagger["beta"] == 0.25 and dagger["mix"] == "step"
    assert dagger["learner"] == {"kind": "cvpt", "checkpoint": str(learner.resolve()),
                                 "checkpoint_sha256": checkpoint_sha256(learner),
                                 "temperature": 1.0}
    assert not {"source", "learner", "beta"} & set(manifest["config"])
    for entry in manifest["shards"]:
        assert 0.0 <= entry["dagger"]["learner_agreement"] <= 1.0
        assert 0.0 < entry["dagger"]["expert_share"] < 0.6  # ~beta of the steps


def test_stored_actions_are_the_expert_labels_of_the_visited_states(dagger_data) -> None:
    """A fresh expert replayed over the stored states gives the stored actions: its labels
    depend on the states the learner reached, not on the actions the expert would have taken."""
    episodes = list(iter_episodes(sorted(str(p) for p in dagger_data.glob("*.tar"))))
    assert len(episodes) == 2
    played_by_learner = 0
    for episode in episodes:
        expert = ScriptedExpert(1)
        expert.reset(np.array([episode["meta"]["seed"]]))
        actions = episode["actions"][:-1]  # the final observation has no action
        for t, label in enumerate(actions):
            state = {k: v[t : t + 1] for k, v in episode["state"].items()}
            assert expert.act(Step(None, state, np.zeros(1), np.zeros(1, bool), None))[0] == label
        moved = episode["state"]["player_pos"][1:] != episode["state"]["player_pos"][:-1]
        played_by_learner += int(moved.any(-1).sum())
    assert played_by_learner > 0


def test_dagger_rerun_is_identical_and_refuses_another_learner(dagger_data, learner, tmp_path) -> None:
    out = tmp_path / "again"
    assert main(_dagger_argv(learner, out, num_envs=1)) == 0
    assert _shas(out) == _shas(dagger_data)  # the bytes depend on the seed, not on --num-envs
    assert main(_dagger_argv(learner, out, beta="0.5")) == 2  # another beta: refused


def test_dagger_cli_errors_name_the_argument(tmp_path, capsys) -> None:
    with pytest.raises(SystemExit):
        main(["data", "dagger", "--checkpoint", str(tmp_path / "none"), "--episodes", "1",
              "--seed", "0", "--out", str(tmp_path / "o")])
    assert "--checkpoint" in capsys.readouterr().err


def test_dagger_rendered_frames_need_craftax(learner, tmp_path, capsys) -> None:
    with pytest.raises(SystemExit):
        main(["data", "dagger", "--checkpoint", str(learner), "--episodes", "1", "--seed", "0",
              "--env", "crafter", "--frames", "rendered", "--out", str(tmp_path / "o")])
    assert "--frames rendered needs --env craftax" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_dagger_shard_range_outside_the_dataset_is_named(learner, tmp_path, capsys) -> None:
    with pytest.raises(SystemExit):
        main(["data", "dagger", "--checkpoint", str(learner), "--episodes", "2", "--seed", "0",
              "--episodes-per-shard", "1", "--shards", "5:6", "--out", str(tmp_path / "o")])
    assert "holds none of the dataset's shards 0:2" in capsys.readouterr().err


# --- goal-directed DAgger: a C-Steve-1 learner told the expert's instruction ------------------


class InstructableConstant(ConstantAgent):
    """A stand-in for an instructable learner or the expert: remembers what it was told."""

    config = "expert config"

    def __init__(self, action: int, num_envs: int) -> None:
        super().__init__(action, num_envs)
        self.told: list[str | None] = [None] * num_envs

    def instruct(self, instructions, mask=None) -> None:
        for i in range(self.num_envs) if mask is None else np.flatnonzero(mask):
            self.told[i] = instructions[i]


def test_mixture_tells_an_instructable_learner_what_the_expert_is_told() -> None:
    learner, expert = InstructableConstant(3, 2), InstructableConstant(5, 2)
    mixture = DaggerMixture(learner, expert, 2, 0.0)
    mixture.instruct(["obtain wood", "obtain drink"])
    mixture.instruct(["obtain sapling", None], np.array([False, True]))
    assert learner.told == expert.told == ["obtain wood", None]
    assert mixture.config == "expert config" and mixture.num_envs == 2  # what a schedule reads
    plain = DaggerMixture(ConstantAgent(3, 2), expert, 2, 0.0)  # a C-VPT takes no instructions
    plain.instruct(["obtain drink", "obtain drink"])
    assert expert.told == ["obtain drink", "obtain drink"]


@pytest.fixture(scope="module")
def steve_learner(tmp_path_factory) -> dict[str, Path]:
    """A tiny random C-Steve-1 export with the C-CLIP and prior exports it reads text with."""
    root = tmp_path_factory.mktemp("steve_learner")
    torch.manual_seed(0)
    backbone = CVPTModel(CVPTConfig.from_name("tiny", NUM_ACTIONS, **SIZES))
    steve = CSteve1Model(backbone, CSteve1Config(goal_dim=64, lora_rank=2, conditioning="film"))
    with torch.no_grad():
        for param in steve.trainable_parameters().values():
            param.normal_(0, 0.5)  # a goal that moves the actions
    return {
        "checkpoint": save_exported(steve.eval(), root / "csteve1", inference={"cfg_scale": 1.0}),
        "cclip": save_exported(CCLIPModel(CCLIPConfig.from_name("smoke")).eval(), root / "cclip"),
        "prior": save_exported(
            CVAEPrior(PriorConfig(embed_dim=64, hidden=32, latent_dim=8)).eval(), root / "prior"),
    }


def _told_argv(paths: dict[str, Path], out: Path, num_envs: int = 2) -> list[str]:
    return ["data", "dagger", "--checkpoint", str(paths["checkpoint"]), "--cclip",
            str(paths["cclip"]), "--prior", str(paths["prior"]), "--instructions", "subgoals",
            "--instruction-timeout", "20", "--beta", "0", *PLAY, "--num-envs", str(num_envs),
            "--out", str(out)]


def test_a_steve_learner_is_told_the_schedule_and_its_rollouts_are_reproducible(
    steve_learner, tmp_path
) -> None:
    out = tmp_path / "told"
    assert main(_told_argv(steve_learner, out)) == 0
    config = json.loads((out / "manifest.json").read_text())["config"]
    learner = config["dagger"]["learner"]
    assert learner["kind"] == "csteve1"
    assert learner["cclip_sha256"] == checkpoint_sha256(steve_learner["cclip"])
    assert learner["prior_sha256"] == checkpoint_sha256(steve_learner["prior"])
    assert "cfg_scale" not in learner and config["instructions"]["timeout"] == 20
    commanded = np.concatenate([
        e["instruction"][:-1] for e in iter_episodes(sorted(str(p) for p in out.glob("*.tar")))
    ])
    # every action records the caption it pursued; 60 steps at timeout 20: several per episode
    assert set(commanded.tolist()) <= set(config["instructions"]["caption_ids"]) | {-1}
    assert len(set(commanded.tolist()) - {-1}) >= 2
    # the learner's goals are drawn from the episode seeds and texts alone: --num-envs changes
    # nothing
    again = tmp_path / "again"
    assert main(_told_argv(steve_learner, again, num_envs=1)) == 0
    assert _shas(again) == _shas(out)


def test_goal_directed_dagger_cli_names_what_is_missing(
    steve_learner, learner, tmp_path, capsys
) -> None:
    for dropped, message in [
        ("--prior", "give --cclip and --prior together"),
        ("--instructions", "a C-Steve-1 learner needs --instructions"),
    ]:
        argv = _told_argv(steve_learner, tmp_path / dropped.strip("-"))
        i = argv.index(dropped)
        del argv[i : i + 2]
        with pytest.raises(SystemExit):
            main(argv)
        assert message in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main([*_dagger_argv(learner, tmp_path / "c"), "--cclip", str(steve_learner["cclip"])])
    assert "--cclip apply to C-Steve-1 only, not 'cvpt'" in capsys.readouterr().err


IDLE = int(Action.NOOP)


def _idle_learner(label: int):
    """A build_agent: the learner always idles (NOOP), the expert always labels ``label``."""

    def build(config: GenerationConfig, num_envs: int) -> DaggerMixture:
        return DaggerMixture(
            ConstantAgent(IDLE, num_envs), ConstantAgent(label, num_envs), num_envs, 0.0, "step"
        )

    return build


@pytest.mark.parametrize(("label", "noop"), [(int(Action.MOVE_LEFT), False), (IDLE, True)])
def test_an_idle_learner_is_a_noop_only_where_the_expert_would_idle_too(
    tmp_path: Path, label: int, noop: bool
) -> None:
    """The learner plays NOOP at every step (beta 0), so every played step had no effect.
    Labelled MOVE_LEFT, no stored step is a noop: the noop filter must keep the expert's way
    out of the idle states. Labelled NOOP, every step is one (the played and the stored action
    agree and did nothing)."""
    config = GenerationConfig(
        expert="scripted", episodes=1, seed=0, env="crafter", episodes_per_shard=1,
        chunk_length=16, max_steps=30,
        dagger=DaggerSettings({"kind": "cvpt", "checkpoint": "idle", "checkpoint_sha256": "0" * 64},
                                  0.0, "step"),
    )
    generate(config, tmp_path, progress=False, build_agent=_idle_learner(label))
    (episode,) = iter_episodes(list_shards(tmp_path))
    acted = episode["actions"] >= 0  # the final observation has no action
    assert acted.sum() == 30 and (episode["actions"][acted] == label).all()
    assert (episode["noop"][acted] == noop).all()
    assert not episode["noop"][~acted].any()
