"""`zoo eval` plays `zoo rl train` checkpoints on fixed seeds, with the trained parameters, and
refuses LoRA weights whose frozen base model changed underneath them."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from zoo.agents import AgentSpec, checkpoint_kind
from zoo.cli import main
from zoo.envs.base import Step
from zoo.envs.constants import NUM_ACTIONS
from zoo.models.cvpt import CVPTConfig, CVPTModel
from zoo.rl.config import RLConfig
from zoo.rl.train import list_checkpoints, train_rl
from zoo.weights.export import save_exported

TINY = RLConfig(
    agent="ppo_rnn", task="T2", env="crafter", num_envs=2, num_steps=4, total_env_steps=8,
    num_minibatches=1, update_epochs=1, hidden_size=16, input_downsample=4, seed=3,
)


def _step(n: int, seed: int = 0) -> Step:
    frames = np.random.default_rng(seed).integers(0, 256, (n, 144, 144, 3), dtype=np.uint8)
    return Step(frames, {}, np.zeros(n, np.float32), np.zeros(n, bool))


def _tiny_cvpt(folder, seed: int = 0):
    torch.manual_seed(seed)
    model = CVPTModel(CVPTConfig.from_name(
        "tiny", NUM_ACTIONS, d_model=32, d_ff=64, n_heads=2, n_layers=2, impala_channels=(2, 4, 4),
        encoder_hidden=32, memory_len=4, input_downsample=4,
    ))
    return save_exported(model, folder)


def test_a_run_folder_plays_its_trained_policy_in_zoo_eval(tmp_path):
    run = tmp_path / "run"
    train_rl(TINY, run, progress=False)
    assert checkpoint_kind(run) == "rl" == checkpoint_kind(list_checkpoints(run)[-1])
    agent = AgentSpec(checkpoint=run).build(2)
    trained = torch.load(list_checkpoints(run)[-1], weights_only=False)["trainable"]
    assert all(torch.equal(agent.policy.state_dict()[k], v) for k, v in trained.items())
    agent.reset(np.array([5, 6]))
    first = agent.act(_step(2))
    agent.reset(np.array([5, 6]))
    assert np.array_equal(agent.act(_step(2)), first)  # each env's seed drives its sampling
    out = tmp_path / "eval"
    assert main(["eval", "--checkpoint", str(run), "--task", "T2", "--env", "crafter",
                 "--episodes", "2", "--num-envs", "2", "--max-steps", "5", "--out", str(out),
                 "--no-gif"]) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["agent"] == "ppo_rnn" and report["episodes"] == 2


def test_lora_weights_on_a_changed_base_model_are_refused(tmp_path):
    base = _tiny_cvpt(tmp_path / "cvpt")
    config = TINY.replace(agent="cvpt_rl", checkpoint=str(base), kl_coef=0.1, lora_rank=2)
    run = tmp_path / "run"
    train_rl(config, run, progress=False)
    agent = AgentSpec(checkpoint=run).build(2)
    assert agent.name == "cvpt_rl"
    _tiny_cvpt(tmp_path / "cvpt", seed=1)  # same path, other weights
    with pytest.raises(ValueError, match="trained on other weights"):
        AgentSpec(checkpoint=run).build(2)
    with pytest.raises(ValueError, match="trained on other weights"):
        train_rl(config.replace(total_env_steps=16), run, resume=True, progress=False)


def test_ppo_steve_plays_its_planner_every_option_and_restarts_it_with_an_episode():
    from tests.zoo.rl.test_envs import _steve
    from zoo.rl.agents import planner_network
    from zoo.rl.envs import CaptionExecutor
    from zoo.rl.play import PlannerAgent

    steve = _steve()
    goals = torch.randn(5, 8, generator=torch.Generator().manual_seed(1))
    seen = []
    original = steve.model.guided_head
    steve.model.guided_head = lambda h, goal, scale: seen.append(goal[:, 0].clone()) or original(
        h, goal, scale)
    executor = CaptionExecutor(steve, goals)
    planner = planner_network(executor.feature_dim + 5, 16, 5)
    calls = []
    planner_step = planner.step
    planner.step = lambda x, first, state: calls.append((len(x), first.tolist(), x[:, 16:])) or (
        planner_step(x, first, state))
    agent = PlannerAgent(planner, executor, option_steps=3, num_envs=2)
    agent.reset(np.array([1, 2]))
    choices = []
    for t in range(7):
        if t == 4:
            agent.reset(np.array([9, 9]), mask=np.array([False, True]))  # env 1: new episode
        agent.act(_step(2, seed=t))
        choices.append(agent.choice.copy())
    # both envs decide at steps 0 and 3, env 1 again at its restart (step 4), env 0 at step 6
    assert [(n, first) for n, first, _ in calls] == [
        (2, [True, True]), (2, [False, False]), (1, [True]), (1, [False]),
    ]
    assert calls[0][2].sum() == 0 and calls[2][2].sum() == 0  # nothing chosen yet this episode
    assert calls[1][2][0, choices[0][0]] == 1  # the one-hot carries the caption chosen last
    for t, goal in enumerate(seen):  # C-Steve-1 follows the caption in force at every step
        torch.testing.assert_close(goal, goals[torch.as_tensor(choices[t])])
