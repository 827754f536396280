"""C-Steve-1 as an agent: goals from text/caption/clip, seeded by the episode, CFG in play."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from zoo.agents.csteve1_agent import GoalEncoder, CSteve1Agent, CSteve1Policy
from zoo.envs.base import Step
from zoo.envs.constants import NUM_ACTIONS
from zoo.envs.schema import empty_state
from zoo.models.cclip import CCLIPConfig, CCLIPModel
from zoo.models.cvpt import CVPTConfig, CVPTModel
from zoo.models.prior import CVAEPrior, PriorConfig
from zoo.models.csteve1 import CSteve1Config, CSteve1Model
from zoo.models.trxl import TrXLState


@pytest.fixture(scope="module")
def goals() -> GoalEncoder:
    torch.manual_seed(0)
    cclip = CCLIPModel(CCLIPConfig.from_name("smoke"))
    prior = CVAEPrior(PriorConfig(embed_dim=64, hidden=32, latent_dim=8))
    return GoalEncoder(cclip, prior)


def _policy(cfg_scale: float = 1.5) -> CSteve1Policy:
    torch.manual_seed(1)
    backbone = CVPTModel(CVPTConfig.from_name(
        "tiny", NUM_ACTIONS, d_model=32, d_ff=64, n_heads=2, n_layers=1, impala_channels=(2, 4, 4),
        encoder_hidden=32, memory_len=4, input_downsample=4,
    ))
    model = CSteve1Model(backbone, CSteve1Config(goal_dim=64, lora_rank=2))
    with torch.no_grad():
        for param in model.trainable_parameters().values():
            param.normal_(0, 0.5)
    return CSteve1Policy(model, cfg_scale=cfg_scale)


def _step(n: int, seed: int = 0) -> Step:
    frames = np.random.default_rng(seed).integers(0, 256, (n, 144, 144, 3), dtype=np.uint8)
    return Step(frames, empty_state(n), np.zeros(n, np.float32), np.zeros(n, bool))


def test_text_caption_and_clip_goals_have_the_goal_width(goals: GoalEncoder) -> None:
    assert goals.from_text(["obtain wood", "go to sleep"]).shape == (2, 64)
    torch.testing.assert_close(goals.from_caption_ids([0]), goals.from_text(["obtain wood"]))
    clips = np.zeros((3, 6, 144, 144, 3), np.uint8)
    assert goals.from_clips(clips).shape == (3, 64)
    with pytest.raises(ValueError, match="caption ids \\[99\\]"):
        goals.from_caption_ids([99])


def test_a_goal_depends_on_the_episode_seed_and_the_text_alone(goals: GoalEncoder) -> None:
    a = CSteve1Agent(_policy(), 2, goals)
    a.reset(np.array([5, 6]))
    a.instruct(["obtain wood", "obtain wood"])
    b = CSteve1Agent(_policy(), 2, goals)
    b.instruct(["obtain sapling", None])  # another history before the same episodes
    b.reset(np.array([5, 6]))
    b.instruct(["obtain wood", "obtain wood"])
    torch.testing.assert_close(a._goal, b._goal)
    assert not torch.equal(a._goal[0], a._goal[1]), "two episodes draw their own goals"
    np.testing.assert_array_equal(a.act(_step(2)), b.act(_step(2)))


def _recorded_logits(agent: CSteve1Agent) -> list[torch.Tensor]:
    """The guided logits of each of ``agent``'s later steps, as its policy computes them."""
    seen, logits = [], agent.policy.logits

    def record(*args: object, **kwargs: object) -> tuple[torch.Tensor, TrXLState]:
        out = logits(*args, **kwargs)
        seen.append(out[0])
        return out

    agent.policy.logits = record
    return seen


def test_no_instruction_is_the_zero_goal_and_actions_are_sampled_from_the_guided_logits(
    goals: GoalEncoder,
) -> None:
    agent = CSteve1Agent(_policy(), 3, goals)
    agent.reset(np.array([1, 2, 3]))
    agent.instruct(["obtain wood", None, "place table on grass"])
    assert torch.count_nonzero(agent._goal[1]) == 0
    actions = agent.act(_step(3))
    assert actions.shape == (3,) and actions.dtype == np.int32
    # the same network's guided logits (scale 1.5) at each episode's first step, sampled with
    # the first draw of each episode seed's stream
    model = _policy().model
    with torch.no_grad():
        logits, _ = model.guided_logits(
            torch.tensor(_step(3).frames).unsqueeze(1), torch.ones(3, 1, dtype=torch.bool),
            agent._goal.unsqueeze(1), model.guidance_state(3), 1.5,
        )
    cdf = torch.softmax(logits[:, 0].double(), -1).cumsum(-1).numpy()
    uniforms = [np.random.default_rng(seed).random() for seed in (1, 2, 3)]
    expected = [np.searchsorted(c, u * c[-1], side="right") for c, u in zip(cdf, uniforms)]
    np.testing.assert_array_equal(actions, expected)


def test_an_env_reset_mid_batch_acts_as_a_fresh_agent_on_the_same_frames(
    goals: GoalEncoder,
) -> None:
    """A new episode starts with empty Transformer-XL memory, whatever its env saw before."""
    text = ["obtain wood", "obtain wood"]
    played = CSteve1Agent(_policy(), 2, goals)
    played.reset(np.array([5, 6]))
    played.instruct(text)
    for seed in range(3):
        played.act(_step(2, seed))
    played.reset(np.array([0, 9]), mask=np.array([False, True]))
    fresh = CSteve1Agent(_policy(), 2, goals)
    fresh.reset(np.array([5, 9]))
    fresh.instruct(text)
    seen_played, seen_fresh = _recorded_logits(played), _recorded_logits(fresh)
    actions_played, actions_fresh = played.act(_step(2, 3)), fresh.act(_step(2, 3))
    torch.testing.assert_close(seen_played[0][1], seen_fresh[0][1])
    assert actions_played[1] == actions_fresh[1]
    # env 0 plays on: its memory of the episode's first three steps still counts
    assert not torch.allclose(seen_played[0][0], seen_fresh[0][0])


def test_guidance_scale_zero_is_the_conditional_policy() -> None:
    policy, unguided = _policy(cfg_scale=1.5), _policy(cfg_scale=0.0)
    goal = torch.randn(2, 64)
    frames = _step(2).frames
    guided_logits, _ = policy.logits(frames, goal, policy.initial_state(2))
    plain_logits, _ = unguided.logits(frames, goal, unguided.initial_state(2))
    cond, _ = unguided.model(
        torch.tensor(frames).unsqueeze(1), torch.zeros(2, 1, dtype=torch.bool), goal.unsqueeze(1),
        unguided.model.initial_state(2),
    )
    torch.testing.assert_close(plain_logits, cond[:, 0])
    assert not torch.allclose(guided_logits, plain_logits)


def test_guided_logits_are_the_conditional_ones_pushed_away_from_the_unconditional() -> None:
    """The paper's guidance at scale 1.5: logits = cond + 1.5 (cond - uncond), with cond and
    uncond from two plain passes of the network, with the goal and with the zero goal."""
    policy = _policy(cfg_scale=1.5)
    goal = torch.randn(2, 64, generator=torch.Generator().manual_seed(3))
    frames = _step(2, seed=4).frames
    guided, _ = policy.logits(frames, goal, policy.initial_state(2))
    model, x = policy.model, torch.tensor(frames).unsqueeze(1)
    first = torch.zeros(2, 1, dtype=torch.bool)
    with torch.no_grad():
        cond = model(x, first, goal.unsqueeze(1), model.initial_state(2))[0][:, 0]
        uncond = model(x, first, torch.zeros(2, 1, 64), model.initial_state(2))[0][:, 0]
    assert (cond - uncond).abs().max() > 0.1  # the goal matters, so the test can tell
    torch.testing.assert_close(guided, cond + 1.5 * (cond - uncond), rtol=1e-4, atol=1e-4)


def test_one_feature_pass_gives_the_guided_logits_over_several_steps() -> None:
    """PPO-Steve reads the goal-free feature and then acts towards a caption: the two halves of
    the feature API must give ``logits``' guided logits, step after step, memory carried."""
    policy = _policy()
    goal = torch.randn(3, 64)
    first = np.array([True, True, True])
    state, feature_state = policy.initial_state(3), policy.feature_state(3)
    for t in range(3):
        frames = _step(3, seed=t).frames
        expected, state = policy.logits(frames, goal, state, first)
        hidden, feature_state = policy.features(frames, first, feature_state)
        assert hidden.shape == (3, policy.feature_dim)
        torch.testing.assert_close(policy.logits_from_features(hidden, goal), expected)
        first = np.array([False, t == 0, False])  # env 1 starts a new episode at t = 1


def test_mismatched_goal_width_is_named(goals: GoalEncoder) -> None:
    policy = _policy()
    with pytest.raises(ValueError, match=r"goals must have shape \(2, 64\)"):
        policy.logits(_step(2).frames, torch.zeros(2, 32), policy.initial_state(2))
    small = GoalEncoder(CCLIPModel(CCLIPConfig.from_name("smoke", embed_dim=32)))
    with pytest.raises(ValueError, match="goal_dim=64"):
        CSteve1Agent(policy, 1, small)
