"""The networks PPO trains: segment re-evaluation equals the rollout, LoRA-only gradients."""

from __future__ import annotations

import numpy as np
import torch

from zoo.envs.constants import NUM_ACTIONS
from zoo.models.cvpt import CVPTConfig, CVPTModel
from zoo.rl.policies import CVPTRLPolicy, FrameEncoder, RecurrentActorCritic, count_parameters

N, T = 3, 6


def _cvpt() -> CVPTModel:
    torch.manual_seed(0)
    return CVPTModel(CVPTConfig.from_name(
        "tiny", NUM_ACTIONS, d_model=32, d_ff=64, n_heads=2, n_layers=2, impala_channels=(2, 4, 4),
        encoder_hidden=32, memory_len=4, input_downsample=4,
    ))


def _frames(seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 256, (N, T, 144, 144, 3), dtype=np.uint8)


def _first() -> torch.Tensor:
    first = torch.zeros(N, T, dtype=torch.bool)
    first[:, 0] = True
    first[1, 3] = True  # env 1 starts a new episode inside the segment
    return first


def _rollout(policy, xs: torch.Tensor, first: torch.Tensor):
    """Step the policy through the segment as a rollout does; returns its outputs and the
    state it started from."""
    state0 = state = policy.initial_state(N)
    logits, values, refs = [], [], []
    with torch.no_grad():
        for t in range(T):
            out = policy.step(xs[:, t], first[:, t], state)
            logits.append(out.logits)
            values.append(out.value)
            refs.append(out.ref_logits)
            state = out.state
    return torch.stack(logits, 1), torch.stack(values, 1), refs, state0


def test_recurrent_policy_re_evaluates_a_segment_exactly():
    torch.manual_seed(0)
    policy = RecurrentActorCritic(FrameEncoder(144, 4, 16), 16, 16, 17)
    frames = torch.as_tensor(_frames())
    logits, values, _, state0 = _rollout(policy, frames, _first())
    new_logits, new_values = policy.evaluate(frames, _first(), state0)
    torch.testing.assert_close(new_logits, logits)
    torch.testing.assert_close(new_values, values)
    # a minibatch of envs from its own start states gives the same rows
    idx = torch.tensor([2, 0])
    sub_logits, _ = policy.evaluate(frames[idx], _first()[idx], policy.select_state(state0, idx))
    torch.testing.assert_close(sub_logits, logits[idx])


def test_the_recurrent_policy_forgets_the_previous_episode_at_its_first_step():
    torch.manual_seed(0)
    policy = RecurrentActorCritic(FrameEncoder(144, 4, 16), 16, 16, 17)
    frames, first = torch.as_tensor(_frames()), _first()
    stale = torch.randn(N, 16)  # the hidden state an earlier episode left behind
    fresh = policy.initial_state(N)
    with torch.no_grad():
        carried = policy.step(frames[:, 0], first[:, 0], stale)
        new = policy.step(frames[:, 0], first[:, 0], fresh)
        torch.testing.assert_close(carried.logits, new.logits)
        torch.testing.assert_close(carried.value, new.value)
        torch.testing.assert_close(carried.state, new.state)
        # env 1 starts a new episode at t=3 of the segment: from there on, what came before
        # is gone, as if its episode had begun the segment
        logits, _ = policy.evaluate(frames, first, stale)
        alone, _ = policy.evaluate(frames[1:, 3:], first[1:, 3:], fresh[1:])
    torch.testing.assert_close(logits[1, 3:], alone[0])


def test_cvpt_rl_starts_as_the_pretrained_policy_and_re_evaluates_exactly():
    cvpt = _cvpt()
    frames = _frames()
    with torch.no_grad():
        pretrained, _ = cvpt(torch.as_tensor(frames), _first(), cvpt.initial_state(N))
    policy = CVPTRLPolicy(cvpt, lora_rank=4, lora_alpha=4)
    xs = torch.stack([policy.preprocess(frames[:, t]) for t in range(T)], 1)
    logits, values, refs, state0 = _rollout(policy, xs, _first())
    # LoRA's B starts at zero: the fine-tuned policy and the reference are the pretrained one
    torch.testing.assert_close(logits, pretrained)
    torch.testing.assert_close(torch.stack(refs, 1), pretrained)
    new_logits, new_values = policy.evaluate(xs, _first(), state0)
    torch.testing.assert_close(new_logits, logits)
    torch.testing.assert_close(new_values, values)


def test_only_lora_and_the_value_head_receive_gradients():
    policy = CVPTRLPolicy(_cvpt(), lora_rank=4, lora_alpha=4)
    with torch.no_grad():  # move LoRA off zero so every LoRA matrix gets a gradient
        for name, p in policy.named_parameters():
            if "lora_B" in name:
                p.normal_(0, 0.1)
    frames = _frames()
    xs = torch.stack([policy.preprocess(frames[:, t]) for t in range(T)], 1)
    logits, values = policy.evaluate(xs, _first(), policy.initial_state(N))
    (logits.logsumexp(-1).mean() + (values - 1).pow(2).mean()).backward()
    got = {n for n, p in policy.named_parameters() if p.grad is not None and p.grad.abs().sum() > 0}
    trainable = {n for n, p in policy.named_parameters() if p.requires_grad}
    assert got == trainable
    assert all("lora_" in n or n.startswith("value.") for n in trainable)
    assert any("reference" not in n and "lora_A" in n for n in trainable)
    frozen = [n for n, p in policy.named_parameters() if not p.requires_grad]
    assert any(n.startswith("encoder.") for n in frozen)
    assert any(n.startswith("reference_trxl.") for n in frozen)


def _size(*modules: torch.nn.Module) -> int:
    return sum(p.numel() for m in modules for p in m.parameters())


def test_the_trained_share_counts_the_acting_policy_not_the_kl_reference():
    policy = CVPTRLPolicy(_cvpt(), lora_rank=4, lora_alpha=4)
    # LoRA r 4 on 5 linears per layer, 2 layers (d 32, key_value and ff.0 32->64, ff.3 64->32):
    # 4 * (64 + 96 + 64 + 96 + 96) = 1664 per layer; the value head 32 + 1
    lora, value = 2 * 1664, 33
    assert _size(policy.value) == value
    pretrained_trxl, head = _size(policy.reference_trxl), _size(policy.policy_head)
    assert _size(policy.trxl) == pretrained_trxl + lora
    acting = _size(policy.encoder) + pretrained_trxl + lora + head + value
    counts = count_parameters(policy)
    assert counts == (lora + value, acting, pretrained_trxl + head)
    assert counts == (3361, 26998, 17733)  # 12.4% of the acting policy, not 7.5% of all
