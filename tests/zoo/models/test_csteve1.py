"""C-Steve-1's network: starts as its C-VPT, trains only LoRA + conditioning, guidance is exact."""

from __future__ import annotations

import pytest
import torch

from zoo.envs.constants import NUM_ACTIONS
from zoo.models.cvpt import CVPTConfig, CVPTModel
from zoo.models.csteve1 import CSteve1Config, CSteve1Model, combine_guidance

GOAL_DIM = 8


def _backbone(seed: int = 0, head_hidden: int = 0) -> CVPTModel:
    torch.manual_seed(seed)
    config = CVPTConfig.from_name(
        "tiny", NUM_ACTIONS, d_model=32, d_ff=64, n_layers=2, n_heads=2, encoder_hidden=32,
        impala_channels=(4, 8, 8), memory_len=8, input_downsample=4, head_hidden=head_hidden,
    )
    return CVPTModel(config).eval()


def _inputs(batch: int = 2, steps: int = 5, seed: int = 1):
    g = torch.Generator().manual_seed(seed)
    frames = torch.randint(0, 256, (batch, steps, 144, 144, 3), dtype=torch.uint8, generator=g)
    first = torch.zeros(batch, steps, dtype=torch.bool)
    first[:, 0] = True
    goal = torch.randn(batch, steps, GOAL_DIM, generator=g)
    return frames, first, goal


def _randomise_trainable(model: CSteve1Model) -> None:
    with torch.no_grad():
        for param in model.trainable_parameters().values():
            param.normal_(0, 0.2)


VARIANTS = [("head", 0), ("trxl_input", 0), ("head", 16), ("film", 0)]  # (conditioning, head_hidden)


@pytest.mark.parametrize(("conditioning", "head_hidden"), VARIANTS)
def test_untrained_steve_is_its_cvpt_whatever_the_goal(conditioning: str, head_hidden: int) -> None:
    frames, first, goal = _inputs()
    cvpt = _backbone()
    expected, _ = cvpt(frames, first, cvpt.initial_state(2))
    config = CSteve1Config(goal_dim=GOAL_DIM, conditioning=conditioning, head_hidden=head_hidden)
    steve = CSteve1Model(_backbone(), config)
    logits, _ = steve(frames, first, goal, steve.initial_state(2))
    torch.testing.assert_close(logits, expected, rtol=1e-5, atol=1e-5)  # float rounding only


def test_only_lora_and_conditioning_train() -> None:
    steve = CSteve1Model(_backbone(), CSteve1Config(goal_dim=GOAL_DIM, lora_rank=4))
    trainable = steve.trainable_parameters()
    assert trainable and all(n.startswith("condition.") or "lora_" in n for n in trainable)
    # every TrXL linear layer named in lora_targets got an adapter: 5 per layer, A and B each
    assert sum("lora_A" in n for n in trainable) == 5 * 2
    frozen = {n: p.detach().clone() for n, p in steve.named_parameters() if not p.requires_grad}
    assert any(n.startswith("backbone.encoder") for n in frozen)
    assert any(n.startswith("backbone.policy_head") for n in frozen)

    optimizer = torch.optim.AdamW(trainable.values(), lr=1e-2)
    before = {n: p.detach().clone() for n, p in trainable.items()}
    frames, first, goal = _inputs()
    logits, _ = steve(frames, first, goal, steve.initial_state(2))
    logits.logsumexp(-1).mean().backward()
    assert all(p.grad is None for p in steve.parameters() if not p.requires_grad)
    optimizer.step()
    for name, param in steve.named_parameters():
        if name in frozen:
            assert torch.equal(param, frozen[name]), f"frozen {name} changed"
    changed = [n for n, p in trainable.items() if not torch.equal(p, before[n])]
    assert any(n.startswith("condition.") for n in changed) and any("lora_B" in n for n in changed)


def test_goal_changes_the_policy_once_trained() -> None:
    steve = CSteve1Model(_backbone(), CSteve1Config(goal_dim=GOAL_DIM))
    _randomise_trainable(steve)
    frames, first, goal = _inputs()
    a, _ = steve(frames, first, goal, steve.initial_state(2))
    b, _ = steve(frames, first, -goal, steve.initial_state(2))
    assert not torch.allclose(a, b)


@pytest.mark.parametrize(("head_hidden", "backbone_head_hidden"), [(0, 0), (16, 0), (0, 16)])
def test_head_goal_effect_depends_on_the_state_only_with_a_hidden_layer(
    head_hidden: int, backbone_head_hidden: int
) -> None:
    """Over C-VPT's linear head, head conditioning shifts every state's logits by the same
    vector; a hidden layer after the goal (C-Steve-1's head block, or the frozen VPT-style head
    of the C-VPT) makes the shift state-dependent."""
    backbone = _backbone(head_hidden=backbone_head_hidden)
    steve = CSteve1Model(backbone, CSteve1Config(goal_dim=GOAL_DIM, head_hidden=head_hidden))
    _randomise_trainable(steve)
    has_block = any(n.startswith("head_block.") for n in steve.trainable_parameters())
    assert has_block == (head_hidden > 0)
    hidden = torch.randn(10, 1, 32, generator=torch.Generator().manual_seed(0))  # 10 states
    goal = torch.randn(1, 1, GOAL_DIM).expand(10, 1, GOAL_DIM)  # one goal for every state
    with torch.no_grad():
        cond = steve.head(hidden + steve._goal_term(goal, hidden))
        uncond = steve.head(hidden + steve._goal_term(torch.zeros_like(goal), hidden))
    shift = (cond - uncond)[:, 0]
    spread = (shift - shift[0]).abs().max().item()
    if head_hidden or backbone_head_hidden:
        assert spread > 0.1
    else:
        assert spread < 1e-5


def test_film_goal_effect_depends_on_the_state_over_a_linear_head() -> None:
    """FiLM scales the TrXL features by the goal, so over the same linear head the goal's
    logit shift differs from state to state, and equals the linear head's shift of x * G z."""
    steve = CSteve1Model(_backbone(), CSteve1Config(goal_dim=GOAL_DIM, conditioning="film"))
    _randomise_trainable(steve)
    assert "film_scale.weight" in steve.trainable_parameters()
    hidden = torch.randn(10, 1, 32, generator=torch.Generator().manual_seed(0))
    goal = torch.randn(1, 1, GOAL_DIM).expand(10, 1, GOAL_DIM)
    with torch.no_grad():
        shift = steve.guided_head(hidden, goal, 0.0) - steve.guided_head(hidden, 0 * goal, 0.0)
        head = steve.backbone.policy_head.weight  # linear: hidden 0
        expected = (hidden * steve.film_scale(goal) + steve.condition.weight @ goal[0, 0]) @ head.T
    assert (shift[:, 0] - shift[0, 0]).abs().max().item() > 0.1
    torch.testing.assert_close(shift, expected, rtol=1e-4, atol=1e-4)


@pytest.mark.parametrize("goal_hidden", [0, 16])
def test_goal_hidden_reads_the_goal_nonlinearly_and_keeps_the_zero_goal(goal_hidden: int) -> None:
    """Linear conditioning gives -z the opposite logit shift of z (so a goal between two
    others gets a mix of theirs); [z, relu(V z)] does not. Either way the zero goal (the
    unconditional policy of guidance) is x + b, and the untrained model is its C-VPT."""
    frames, first, goal = _inputs()
    cvpt = _backbone()
    expected, _ = cvpt(frames, first, cvpt.initial_state(2))
    config = CSteve1Config(goal_dim=GOAL_DIM, conditioning="film", goal_hidden=goal_hidden)
    steve = CSteve1Model(_backbone(), config)
    logits, _ = steve(frames, first, goal, steve.initial_state(2))
    torch.testing.assert_close(logits, expected, rtol=1e-5, atol=1e-5)
    assert any(n.startswith("goal_net.") for n in steve.trainable_parameters()) == (goal_hidden > 0)
    _randomise_trainable(steve)
    hidden = torch.randn(10, 1, 32, generator=torch.Generator().manual_seed(0))
    z = torch.randn(1, 1, GOAL_DIM).expand(10, 1, GOAL_DIM)
    with torch.no_grad():
        none = steve._after_trxl(hidden, torch.zeros_like(z))
        plus, minus = steve._after_trxl(hidden, z) - none, steve._after_trxl(hidden, -z) - none
    torch.testing.assert_close(none, hidden + steve.condition.bias)
    asymmetry = (plus + minus).abs().max().item()
    assert asymmetry > 0.1 if goal_hidden else asymmetry < 1e-5


def test_combine_guidance_on_fixed_logits() -> None:
    cond = torch.tensor([[2.0, 0.0, -1.0]])
    uncond = torch.tensor([[1.0, 1.0, 1.0]])
    # (1 + 1.5) * cond - 1.5 * uncond
    expected = torch.tensor([[3.5, -1.5, -4.0]])
    torch.testing.assert_close(combine_guidance(cond, uncond, 1.5), expected)
    torch.testing.assert_close(combine_guidance(cond, uncond, 0.0), cond)


@pytest.mark.parametrize(("conditioning", "head_hidden"), VARIANTS)
def test_guided_steps_equal_separate_conditional_and_unconditional_passes(
    conditioning: str, head_hidden: int
) -> None:
    """Step by step with cached memory, one batched forward = two full-history passes."""
    config = CSteve1Config(goal_dim=GOAL_DIM, conditioning=conditioning, head_hidden=head_hidden)
    steve = CSteve1Model(_backbone(), config)
    _randomise_trainable(steve)
    frames, first, goal = _inputs(steps=6)
    scale = 1.5
    with torch.no_grad():
        cond, _ = steve(frames, first, goal, steve.initial_state(2))
        uncond, _ = steve(frames, first, torch.zeros_like(goal), steve.initial_state(2))
        state = steve.guidance_state(2)
        guided = []
        for t in range(frames.shape[1]):
            step = slice(t, t + 1)
            logits, state = steve.guided_logits(
                frames[:, step], first[:, step], goal[:, step], state, scale
            )
            guided.append(logits)
    torch.testing.assert_close(
        torch.cat(guided, 1), combine_guidance(cond, uncond, scale), rtol=1e-4, atol=1e-4
    )


def test_bad_goal_shape_and_config_are_named() -> None:
    steve = CSteve1Model(_backbone(), CSteve1Config(goal_dim=GOAL_DIM))
    frames, first, goal = _inputs()
    with pytest.raises(ValueError, match=r"goal must have shape \(2, 5, 8\)"):
        steve(frames, first, goal[..., :4], steve.initial_state(2))
    with pytest.raises(ValueError, match="head_hidden=-1"):
        CSteve1Config(head_hidden=-1)
    with pytest.raises(ValueError, match="conditioning='resnet'"):
        CSteve1Config(conditioning="resnet")  # type: ignore[arg-type]
