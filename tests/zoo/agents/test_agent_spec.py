"""``AgentSpec``: one description of an agent, checked once, built once, recorded with its files'
sha256s; and C-Steve-1 exports that name the goal models they read text with, so one flag
(``--checkpoint``) plays them."""

from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from zoo.agents import AgentSpec
from zoo.agents.csteve1_agent import CSteve1Policy
from zoo.cli import main
from zoo.weights.export import (
    CONFIG_FILE,
    GOAL_MODELS,
    checkpoint_sha256,
    export_checkpoint,
    recorded_goal_models,
    verify_export,
)
from zoo.weights.guidance import PAPER_CFG_SCALE

WEIGHTS = Path(__file__).resolve().parents[3] / "weights"
STEVE, CCLIP, PRIOR = (WEIGHTS / name for name in ("csteve1_cpu", "cclip_cpu", "prior_cpu"))


@pytest.mark.parametrize(
    "fields, message",
    [
        ({}, "give --agent NAME (one of random, scripted, ppo, cvpt, csteve1, rl) or --checkpoint"),
        ({"kind": "walker"}, "unknown agent 'walker'"),
        ({"kind": "cvpt"}, "agent 'cvpt' needs --checkpoint PATH (a C-VPT .ckpt or export dir)"),
        ({"kind": "random", "temperature": 0.5}, "temperature applies to the cvpt, csteve1 and rl"),
        ({"kind": "scripted", "temperature": -1.0}, "temperature must be >= 0, got -1.0"),
        ({"kind": "random", "expert_options": {"plants_first": True}},
         "expert options apply to the scripted expert only, not 'random'"),
        ({"kind": "scripted", "cfg_scale": 1.0}, "--cfg-scale apply to C-Steve-1 only"),
        ({"checkpoint": STEVE, "cclip": CCLIP}, "give --cclip and --prior together"),
        ({"checkpoint": STEVE, "cfg_scale": -0.5}, "cfg_scale must be >= 0, got -0.5"),
        ({"checkpoint": "nope"}, "--checkpoint nope does not exist"),
        ({"checkpoint": STEVE, "cclip": CCLIP, "prior": "nope"}, "--prior nope does not exist"),
    ],
)
def test_each_misuse_is_one_message(fields: dict, message: str) -> None:
    with pytest.raises(ValueError, match="^" + message.replace("(", r"\(").replace(")", r"\)")):
        AgentSpec(**fields)


def test_the_kind_comes_from_the_checkpoint_and_the_record_pins_every_file() -> None:
    spec = AgentSpec(checkpoint=STEVE, temperature=0.5)
    assert spec.kind == "csteve1" and spec.checkpoint == str(STEVE)
    record = spec.record()
    assert record == {"kind": "csteve1", "checkpoint": str(STEVE.resolve()),
                      "checkpoint_sha256": checkpoint_sha256(STEVE), "temperature": 0.5}
    assert AgentSpec.from_record(record) == spec
    told = AgentSpec(checkpoint=STEVE, cclip=CCLIP, prior=PRIOR).record()
    assert told["cclip_sha256"] == checkpoint_sha256(CCLIP)
    assert told["prior_sha256"] == checkpoint_sha256(PRIOR)
    scripted = AgentSpec("scripted", expert_options={"plants_first": True})
    assert scripted.record() == {"kind": "scripted", "expert_options": {"plants_first": True}}
    assert hash(scripted) == hash(AgentSpec("scripted"))  # a dict field, still hashable


def test_the_shipped_c_steve_1_names_its_goal_models() -> None:
    config = json.loads((STEVE / CONFIG_FILE).read_text())
    assert config[GOAL_MODELS] == {
        "cclip": {"path": "../cclip_cpu", "sha256": checkpoint_sha256(CCLIP)},
        "prior": {"path": "../prior_cpu", "sha256": checkpoint_sha256(PRIOR)},
    }
    assert recorded_goal_models(STEVE) == {"cclip": CCLIP.resolve(), "prior": PRIOR.resolve()}
    assert CSteve1Policy.load(STEVE).goals.goal_dim == 64  # built from them, when first asked


def _goals_and_actions(spec: AgentSpec) -> tuple[np.ndarray, np.ndarray]:
    from zoo.envs import make_env

    agent = spec.build(2)
    env = make_env("crafter", 2, pixels=True)
    seeds = np.array([3, 4])
    step = env.reset(seeds)
    agent.reset(seeds)
    agent.instruct(["obtain sapling", "craft wood pickaxe"])
    return agent._goal.numpy().copy(), agent.act(step)


def test_its_own_goal_models_play_as_the_same_ones_given_by_flag() -> None:
    own = _goals_and_actions(AgentSpec(checkpoint=STEVE))
    given = _goals_and_actions(AgentSpec(checkpoint=STEVE, cclip=CCLIP, prior=PRIOR))
    np.testing.assert_array_equal(own[0], given[0])
    np.testing.assert_array_equal(own[1], given[1])
    assert np.abs(own[0]).sum() > 0  # the instructions became goals


@pytest.fixture()
def bare_export(tmp_path: Path) -> Path:
    """The shipped C-Steve-1 exported again without its goal models: an export from before
    exports recorded them."""
    out = tmp_path / "bare"
    export_checkpoint(STEVE, out, goal_models={})
    config = json.loads((out / CONFIG_FILE).read_text())
    assert GOAL_MODELS not in config
    return out


def test_an_export_without_goal_models_needs_the_flags_and_says_so(bare_export: Path) -> None:
    with pytest.raises(ValueError, match=r"records none .*: give --cclip and --prior"):
        AgentSpec(checkpoint=bare_export).require_text()
    AgentSpec(checkpoint=bare_export, cclip=CCLIP, prior=PRIOR).require_text()
    assert AgentSpec(checkpoint=bare_export).goal_models() is None


def test_a_moved_export_names_what_is_missing_and_a_copied_one_moves_alone(
    tmp_path: Path, bare_export: Path
) -> None:
    linked = tmp_path / "linked"
    export_checkpoint(bare_export, linked, goal_models={"cclip": CCLIP, "prior": PRIOR})
    moved = tmp_path / "elsewhere" / "deeper" / "linked"
    shutil.copytree(linked, moved)
    with pytest.raises(ValueError, match="records its cclip at .* which does not exist"):
        AgentSpec(checkpoint=moved).goal_models()
    AgentSpec(checkpoint=moved).build(1)  # playing without text needs no goal models
    copied = tmp_path / "copied"
    assert main(["export", "--checkpoint", str(bare_export), "--out", str(copied), "--cclip",
                 str(CCLIP), "--prior", str(PRIOR), "--copy-goal-models"]) == 0
    verify_export(copied)
    alone = tmp_path / "far" / "copied"
    shutil.copytree(copied, alone)
    assert recorded_goal_models(alone) == {"cclip": (alone / "cclip").resolve(),
                                           "prior": (alone / "prior").resolve()}


def test_other_weights_at_the_recorded_path_are_refused(tmp_path: Path) -> None:
    root = tmp_path / "weights"
    for folder in (STEVE, CCLIP, PRIOR):
        shutil.copytree(folder, root / folder.name)
    (root / "prior_cpu" / "sha256.txt").write_text("0" * 64 + "  model.safetensors\n")
    with pytest.raises(ValueError, match="records its prior .* with sha256 .* but it now has"):
        AgentSpec(checkpoint=root / "csteve1_cpu").goal_models()


def test_the_goal_models_must_fit_the_policy(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="is a CVAE prior export"):
        export_checkpoint(STEVE, tmp_path / "x", goal_models={"cclip": PRIOR, "prior": PRIOR})
    with pytest.raises(ValueError, match="together"):
        export_checkpoint(STEVE, tmp_path / "x", goal_models={"cclip": CCLIP})
    with pytest.raises(ValueError, match="records no goal models"):
        export_checkpoint(WEIGHTS / "cvpt_tiny_cpu", tmp_path / "x",
                          goal_models={"cclip": CCLIP, "prior": PRIOR})


def test_the_guidance_default_is_the_papers_and_an_export_keeps_its_own(tmp_path: Path) -> None:
    assert PAPER_CFG_SCALE == 1.5  # paper §4.3
    assert CSteve1Policy.load(STEVE).cfg_scale == 1.0  # what the card measured, recorded
    bare = tmp_path / "paper"
    export_checkpoint(STEVE, bare, inference={"cfg_scale": PAPER_CFG_SCALE})
    assert CSteve1Policy.load(bare).cfg_scale == PAPER_CFG_SCALE
    spec = dataclasses.replace(AgentSpec(checkpoint=STEVE), cfg_scale=2.0)
    assert spec.build(1).inference == {"cfg_scale": 2.0, "temperature": 1.0}


def test_ppo_steve_reads_the_captions_through_the_exports_goal_models() -> None:
    from zoo.rl.agents import load_executor
    from zoo.rl.config import RLConfig

    base = RLConfig(agent="ppo_steve", task="T1", checkpoint=str(STEVE))
    steve, goals = load_executor(base)
    told = load_executor(dataclasses.replace(base, cclip=str(CCLIP), prior=str(PRIOR)))[1]
    assert goals.shape == (61, 64)
    np.testing.assert_array_equal(goals.numpy(), told.numpy())
