"""C-VPT playing API: Lightning-free loading, cached stepping, seeded sampling, export folders."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from zoo.agents.cvpt_agent import CVPTAgent, CVPTPolicy
from zoo.envs.base import Step
from zoo.envs.constants import NUM_ACTIONS
from zoo.models.cvpt import CVPTConfig, CVPTModel
from zoo.weights import load_model
from zoo.weights.export import export_checkpoint

HPARAMS = dict(
    model="tiny", d_model=32, d_ff=64, n_heads=2, n_layers=1, impala_channels=[4, 8, 8],
    encoder_hidden=32, memory_len=3, lr=1e-3,
)


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory) -> tuple[Path, CVPTModel]:
    """A file shaped like a Lightning checkpoint of lit_models.cvpt.CVPT (no Lightning needed)."""
    torch.manual_seed(0)
    overrides = {k: v for k, v in HPARAMS.items() if k not in ("model", "lr")}
    overrides["impala_channels"] = tuple(overrides["impala_channels"])
    model = CVPTModel(CVPTConfig.from_name("tiny", NUM_ACTIONS, **overrides)).eval()
    path = tmp_path_factory.mktemp("ckpt") / "last.ckpt"
    state_dict = {f"model.{k}": v for k, v in model.state_dict().items()}
    torch.save({"state_dict": state_dict, "hyper_parameters": HPARAMS, "global_step": 3}, path)
    return path, model


def _frames(n: int, t: int, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 256, (t, n, 144, 144, 3), dtype=np.uint8)


def test_policy_steps_match_full_window(checkpoint) -> None:
    path, model = checkpoint
    policy = CVPTPolicy(load_model(path, "cvpt"))
    frames = _frames(2, 7)
    first = np.zeros((7, 2), bool)
    first[0] = True
    first[4, 1] = True
    state = policy.initial_state(2)
    stepped = []
    for t in range(7):
        logits, state = policy.logits(frames[t], state, first[t])
        stepped.append(logits)
    with torch.no_grad():
        full, _ = model(
            torch.from_numpy(frames).transpose(0, 1),
            torch.from_numpy(first).T,
            model.initial_state(2),
        )
    torch.testing.assert_close(torch.stack(stepped, 1), full, atol=1e-5, rtol=0)


def test_greedy_is_argmax_and_sampling_follows_uniforms(checkpoint) -> None:
    path, _ = checkpoint
    model = load_model(path, "cvpt")
    frames, first = _frames(3, 1)[0], np.ones(3, bool)
    greedy = CVPTPolicy(model, greedy=True)
    logits, _ = greedy.logits(frames, greedy.initial_state(3), first)
    actions, _ = greedy.act(frames, greedy.initial_state(3), first)
    assert np.array_equal(actions, logits.argmax(-1).numpy())
    sampler = CVPTPolicy(model)
    low, _ = sampler.act(frames, sampler.initial_state(3), first, uniforms=np.zeros(3))
    high, _ = sampler.act(frames, sampler.initial_state(3), first, uniforms=np.full(3, 0.999999))
    assert (low == 0).all() and (high == 16).all()


def _play(agent: CVPTAgent, frames: np.ndarray, seeds: np.ndarray) -> np.ndarray:
    agent.reset(seeds)
    actions = []
    for t in range(len(frames)):
        step = Step(frames[t], {}, np.zeros(len(seeds), np.float32), np.zeros(len(seeds), bool))
        actions.append(agent.act(step))
    return np.stack(actions)


def test_agent_is_deterministic_per_seed_and_reset_forgets(checkpoint) -> None:
    path, _ = checkpoint
    agent = CVPTAgent.from_checkpoint(path, num_envs=2)
    frames = _frames(2, 5)
    a = _play(agent, frames, np.array([1, 2]))
    b = _play(agent, frames, np.array([1, 2]))
    assert a.dtype == np.int32 and a.shape == (5, 2)
    assert np.array_equal(a, b)
    # env 1 seeded like env 0 and shown env 0's frames acts like env 0
    c = _play(agent, frames[:, [0, 0]], np.array([1, 1]))
    assert np.array_equal(c[:, 0], c[:, 1])


def test_agent_needs_pixels(checkpoint) -> None:
    agent = CVPTAgent.from_checkpoint(checkpoint[0], num_envs=1)
    with pytest.raises(ValueError, match="pixels=True"):
        agent.act(Step(None, {}, np.zeros(1, np.float32), np.zeros(1, bool)))


def test_export_round_trip_and_checksum(checkpoint, tmp_path: Path) -> None:
    path, model = checkpoint
    out = export_checkpoint(path, tmp_path / "export")
    assert sorted(p.name for p in out.iterdir()) == ["config.json", "model.safetensors", "sha256.txt"]
    loaded = load_model(out)
    assert loaded.config == model.config
    for key, value in model.state_dict().items():
        assert torch.equal(loaded.state_dict()[key], value)
    agent = CVPTAgent.from_checkpoint(out, num_envs=1)  # a folder loads as an export
    assert agent.policy.model.config == model.config
    weights = out / "model.safetensors"
    data = bytearray(weights.read_bytes())
    data[-1] ^= 0xFF
    weights.write_bytes(bytes(data))
    with pytest.raises(ValueError, match="checksum mismatch for .*model.safetensors"):
        load_model(out)


def test_not_a_checkpoint_is_a_clear_error(tmp_path: Path) -> None:
    path = tmp_path / "weights.pt"
    torch.save({"weights": torch.zeros(1)}, path)
    with pytest.raises(ValueError, match="not a Lightning checkpoint"):
        load_model(path, "cvpt")
    with pytest.raises(FileNotFoundError, match="not a `zoo export` folder"):
        load_model(tmp_path)


def test_zoo_eval_plays_a_checkpoint_without_agent_name(checkpoint, tmp_path: Path) -> None:
    import json

    from zoo.agents import checkpoint_kind
    from zoo.cli import main

    path, _ = checkpoint
    assert checkpoint_kind(path) == "cvpt"
    with pytest.raises(ValueError, match="cannot tell what"):
        checkpoint_kind(tmp_path)
    out = tmp_path / "eval"
    argv = ["eval", "--checkpoint", str(path), "--env", "crafter", "--episodes", "2",
            "--max-steps", "5", "--no-gif", "--out", str(out)]
    assert main(argv) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["agent"] == "cvpt" and report["episodes"] == 2


def test_temperature_shapes_the_sampled_distribution(checkpoint, monkeypatch) -> None:
    """Actions follow softmax(logits / T); T = 0 always plays the argmax."""
    from zoo.agents import AgentSpec

    n = 500
    logits = torch.linspace(-2.0, 2.0, 17).repeat(n, 1)  # spread: T = 0.5, 1 and 2 differ
    frames = np.broadcast_to(np.zeros((144, 144, 3), np.uint8), (n, 144, 144, 3))
    uniforms = (np.arange(n) + 0.5) / n  # an even grid: frequencies are the CDF's steps
    for temperature in (0.5, 2.0):
        policy = AgentSpec(checkpoint=checkpoint[0], temperature=temperature).build(n).policy
        monkeypatch.setattr(policy, "logits", lambda frames, state, first=None: (logits, state))
        actions, _ = policy.act(frames, policy.initial_state(n), uniforms=uniforms)
        frequencies = np.bincount(actions, minlength=17) / n
        expected = torch.softmax(logits[0] / temperature, -1).numpy()
        np.testing.assert_allclose(frequencies, expected, atol=1 / n + 1e-6)

    agent = AgentSpec(checkpoint=checkpoint[0], temperature=0).build(n)
    monkeypatch.setattr(agent.policy, "logits", lambda frames, state, first=None: (logits, state))
    agent.reset(np.arange(n))  # n different sampling streams, all ignored
    step = Step(frames, {}, np.zeros(n, np.float32), np.zeros(n, bool))
    assert (agent.act(step) == 16).all()


def test_plain_act_from_initial_state_needs_no_flags(checkpoint) -> None:
    policy = CVPTPolicy.load(checkpoint[0], greedy=True)
    frames = _frames(2, 2)
    state = policy.initial_state(2)
    flagged, _ = policy.act(frames[0], policy.initial_state(2), np.ones(2, bool))
    actions, state = policy.act(frames[0], state)
    assert np.array_equal(actions, flagged)
    actions, state = policy.act(frames[1], state)
    assert actions.shape == (2,) and state.memory.shape[1] == 2
