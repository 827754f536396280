"""The foundation-model wrappers against the models called directly: C-CLIP's reward is the change
in ``encode_video`` similarity, C-VPT's features are one pass over the episode so far, the goal
is the one ``CSteve1Agent`` draws; each restarts at an episode start, alone and batched (the
vector env's next-step autoreset). Models: the shipped weights/ exports (a few MB, CPU-fast)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from gymnasium.vector import AutoresetMode

from zoo.agents.csteve1_agent import GoalEncoder, CSteve1Agent, CSteve1Policy
from zoo.gym.env import CrafterDojoEnv
from zoo.gym.vector import CraftaxVectorEnv
from zoo.gym.wrappers import (
    CClipReward,
    CVPTFeatures,
    InstructionGoal,
    VectorCClipReward,
    VectorCVPTFeatures,
    VectorInstructionGoal,
)
from zoo.gym.wrappers.base import SHIPPED
from zoo.weights import load_model

TEXT = "obtain drink"
LIMIT = 3
NOOPS = np.zeros(2, np.int32)


@pytest.fixture(scope="module")
def cclip():
    return load_model(SHIPPED / "cclip_cpu", "cclip").eval()


@pytest.fixture(scope="module")
def cvpt():
    return load_model(SHIPPED / "cvpt_tiny_cpu", "cvpt").eval()


@pytest.fixture(scope="module")
def vector():
    """2 Craftax envs with 3-step episodes (the session fixture's compiled programs)."""
    return CraftaxVectorEnv(2, max_steps=LIMIT)


@torch.inference_mode()
def similarity(cclip, window: list[np.ndarray]) -> float:
    video = cclip.encode_video(torch.from_numpy(np.stack(window))[None])[0]
    return float(video @ cclip.encode_text([TEXT])[0])


@torch.inference_mode()
def one_pass(cvpt, frames: list[np.ndarray]) -> np.ndarray:
    """C-VPT's TrXL output at the last of ``frames`` (one episode, from its start)."""
    x = torch.from_numpy(np.stack(frames))[None]
    first = torch.zeros(1, len(frames), dtype=torch.bool)
    first[0, 0] = True
    hidden, _ = cvpt.features(x, first, cvpt.initial_state(1))
    return hidden[0, -1].numpy()


def play_past_limit(env) -> list:
    """Reset (seed 0), step to the limit and once more (the autoreset); every step's output."""
    env.unwrapped.metadata["autoreset_mode"] = AutoresetMode.NEXT_STEP
    out = [env.reset(seed=0)]
    for _ in range(LIMIT + 1):
        out.append(env.step(NOOPS))
    return out


def test_cclip_reward_is_the_change_in_similarity(cclip):
    env = CClipReward(CrafterDojoEnv("crafter"), TEXT, cclip)
    plain = CrafterDojoEnv("crafter")
    obs, info = env.reset(seed=0)
    plain.reset(seed=0)
    window = [obs] * 6  # an episode's first window repeats its first frame
    assert info["cclip_reward"] == 0
    assert info["cclip_similarity"] == pytest.approx(similarity(cclip, window), abs=1e-4)
    start, added = info["cclip_similarity"], 0.0
    for t in range(8):
        obs, reward, _, _, info = env.step(t % 17)
        base = plain.step(t % 17)[1]
        window = window[1:] + [obs]
        assert info["cclip_similarity"] == pytest.approx(similarity(cclip, window), abs=1e-4)
        assert reward == pytest.approx(base + info["cclip_reward"], abs=1e-6)
        added += info["cclip_reward"]
    assert added == pytest.approx(info["cclip_similarity"] - start, abs=1e-4)  # telescopes
    obs, info = env.reset()
    assert info["cclip_similarity"] == pytest.approx(similarity(cclip, [obs] * 6), abs=1e-4)


def test_vector_cclip_reward_batches_and_restarts(vector, cclip):
    env = VectorCClipReward(vector, TEXT, cclip)
    out = play_past_limit(env)
    frames = [out[0][0]] + [step[0] for step in out[1:]]
    for i in range(2):
        window = [frames[0][i]] * 6
        for t in range(1, LIMIT + 1):
            window = window[1:] + [frames[t][i]]
        assert out[LIMIT][4]["cclip_similarity"][i] == pytest.approx(
            similarity(cclip, window), abs=1e-4)
    *_, info = out[-1]
    assert (info["cclip_reward"] == 0).all()  # the autoreset step starts a new window
    for i in range(2):
        assert info["cclip_similarity"][i] == pytest.approx(
            similarity(cclip, [frames[-1][i]] * 6), abs=1e-4)


def test_vector_wrapper_masked_reset_marks_only_the_reset_envs(vector, cclip):
    """A masked reset's wrapper info is marked as the env's is (Gymnasium's ``_key`` masks): only
    the reset env, its new window's similarity, zeros in the running env's rows."""
    env = VectorCClipReward(vector, TEXT, cclip)
    env.reset(seed=0)
    mask = np.array([False, True])
    obs, info = env.reset(options={"reset_mask": mask})
    for key in ("episode_index", "cclip_reward", "cclip_similarity"):
        assert info[f"_{key}"].tolist() == [False, True], key
    assert info["cclip_similarity"][0] == 0
    assert info["cclip_similarity"][1] == pytest.approx(similarity(cclip, [obs[1]] * 6), abs=1e-4)


def test_cvpt_features_are_one_pass_over_the_episode(cvpt):
    env = CVPTFeatures(CrafterDojoEnv("crafter"), cvpt)
    assert env.observation_space.shape == (cvpt.config.d_model,)
    frames_env = CrafterDojoEnv("crafter")
    frames = [frames_env.reset(seed=0)[0]]
    features, _ = env.reset(seed=0)
    np.testing.assert_allclose(features, one_pass(cvpt, frames), atol=1e-4)
    for t in range(5):
        features = env.step(t % 17)[0]
        frames.append(frames_env.step(t % 17)[0])
        np.testing.assert_allclose(features, one_pass(cvpt, frames), atol=1e-4)
    features, _ = env.reset()  # memory reset: nothing of the last episode is attended to
    np.testing.assert_allclose(features, one_pass(cvpt, [frames_env.reset()[0]]), atol=1e-4)


def test_vector_cvpt_features_reset_memory_on_autoreset(vector, cvpt):
    out = play_past_limit(VectorCVPTFeatures(vector, cvpt))
    raw = play_past_limit(vector)
    frames = [raw[0][0]] + [step[0] for step in raw[1:]]
    for i in range(2):
        np.testing.assert_allclose(
            out[LIMIT][0][i], one_pass(cvpt, [f[i] for f in frames[: LIMIT + 1]]), atol=1e-4)
        np.testing.assert_allclose(out[-1][0][i], one_pass(cvpt, [frames[-1][i]]), atol=1e-4)


def test_vector_cvpt_features_masked_reset_keeps_the_other_episode(vector, cvpt):
    """Autoreset disabled: ``reset_mask`` restarts env 0's memory and leaves env 1's episode
    going on, its memory rows untouched by env 0's restart."""
    mask = np.array([True, False])
    vector.metadata["autoreset_mode"] = AutoresetMode.DISABLED
    try:
        frames = [vector.reset(seed=0)[0]]  # the raw frames, replayed below through the wrapper
        frames += [vector.step(NOOPS)[0] for _ in range(LIMIT - 1)]
        restart = vector.reset(options={"reset_mask": mask})[0][0]
        after = vector.step(NOOPS)[0]
        env = VectorCVPTFeatures(vector, cvpt)
        env.reset(seed=0)
        features = [env.step(NOOPS)[0] for _ in range(LIMIT - 1)][-1]
        restarted, _ = env.reset(options={"reset_mask": mask})
        np.testing.assert_array_equal(restarted[1], features[1])
        np.testing.assert_allclose(restarted[0], one_pass(cvpt, [restart]), atol=1e-4)
        stepped = env.step(NOOPS)[0]
        np.testing.assert_allclose(stepped[0], one_pass(cvpt, [restart, after[0]]), atol=1e-4)
        episode = [f[1] for f in frames] + [after[1]]
        np.testing.assert_allclose(stepped[1], one_pass(cvpt, episode), atol=1e-4)
    finally:
        vector.metadata["autoreset_mode"] = AutoresetMode.NEXT_STEP


def steve_goal(cclip, prior, seed: int) -> np.ndarray:
    """The goal ``zoo eval`` gives C-Steve-1 told TEXT in the episode seeded ``seed``."""
    agent = CSteve1Agent(CSteve1Policy.load(SHIPPED / "csteve1_cpu"), 1, GoalEncoder(cclip, prior))
    agent.reset(np.array([seed]))
    agent.instruct([TEXT])
    return agent._goal[0].numpy()


def test_instruction_goal_is_c_steve_1s_goal_for_the_episode(cclip):
    prior = load_model(SHIPPED / "prior_cpu", "prior")
    env = InstructionGoal(CrafterDojoEnv("crafter"), TEXT, cclip, prior)
    obs, info = env.reset(seed=0)
    assert set(obs) == {"pixels", "goal"} and obs["goal"] in env.observation_space["goal"]
    goal = steve_goal(cclip, prior, int(info["episode_seed"]))
    np.testing.assert_allclose(obs["goal"], goal, atol=1e-6)
    for t in range(3):
        np.testing.assert_array_equal(env.step(t)[0]["goal"], obs["goal"])
    obs, info = env.reset()
    np.testing.assert_allclose(obs["goal"], steve_goal(cclip, prior, int(info["episode_seed"])),
                               atol=1e-6)
    assert not np.allclose(obs["goal"], goal)


def test_vector_instruction_goal_changes_with_each_episode(vector, cclip):
    prior = load_model(SHIPPED / "prior_cpu", "prior")
    out = play_past_limit(VectorInstructionGoal(vector, TEXT, cclip, prior))
    for obs_info in (out[0], out[-1]):
        obs, info = obs_info[0], obs_info[-1]
        for i in range(2):
            goal = steve_goal(cclip, prior, int(info["episode_seed"][i]))
            np.testing.assert_allclose(obs["goal"][i], goal, atol=1e-6)
    np.testing.assert_array_equal(out[LIMIT][0]["goal"], out[0][0]["goal"])


def test_wrappers_stack_into_a_dict(cclip, cvpt):
    prior = load_model(SHIPPED / "prior_cpu", "prior")
    env = InstructionGoal(CVPTFeatures(CClipReward(CrafterDojoEnv("crafter"), TEXT, cclip), cvpt),
                          TEXT, cclip, prior)
    obs, _ = env.reset(seed=0)
    assert obs in env.observation_space and set(obs) == {"obs", "goal"}


def test_wrappers_refuse_what_they_cannot_read(vector, cclip, cvpt):
    with pytest.raises(ValueError, match="size=144"):
        CClipReward(CrafterDojoEnv("crafter", size=72), TEXT, cclip)
    with pytest.raises(ValueError, match="size=144"):
        CVPTFeatures(CrafterDojoEnv("crafter", size=72), cvpt)
    vector.metadata["autoreset_mode"] = AutoresetMode.SAME_STEP
    with pytest.raises(ValueError, match="NEXT_STEP or DISABLED"):
        VectorCVPTFeatures(vector, cvpt)
    vector.metadata["autoreset_mode"] = AutoresetMode.NEXT_STEP
