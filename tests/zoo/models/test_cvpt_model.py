"""C-VPT network: preset sizes against the paper, frame layouts, and clear errors."""

from __future__ import annotations

import pytest
import torch

from zoo.envs.constants import NUM_ACTIONS
from zoo.models.cvpt import PAPER_PARAMS, CVPTConfig, CVPTModel
from zoo.weights.kinds import config_from_hparams

SMALL = dict(d_model=32, d_ff=64, n_heads=2, n_layers=1, impala_channels=(4, 8, 8), encoder_hidden=32)


@pytest.mark.parametrize("name", ["tiny", "base", "large"])
def test_preset_parameter_counts_match_paper(name: str) -> None:
    with torch.device("meta"):  # counts only; no memory for the 64M-parameter model
        model = CVPTModel(CVPTConfig.from_name(name, NUM_ACTIONS))
    assert abs(model.get_num_params() / PAPER_PARAMS[name] - 1) < 0.05


def test_unknown_preset_and_config_fields_are_errors() -> None:
    with pytest.raises(ValueError, match="unknown C-VPT preset 'huge'"):
        CVPTConfig.from_name("huge", NUM_ACTIONS)
    with pytest.raises(ValueError, match=r"unknown CVPTConfig fields \['hidsize'\]"):
        CVPTConfig.from_dict({"hidsize": 3})


def test_the_builder_gives_the_action_count_and_cvpt_runs_get_the_games() -> None:
    with pytest.raises(TypeError, match="num_actions"):
        CVPTConfig()
    assert CVPTModel(CVPTConfig.from_name("tiny", 5, **SMALL)).policy_head.out_features == 5
    # lit_models.cvpt.CVPT's hyper-parameters hold no action count: checkpoints read the game's
    assert config_from_hparams({"model": "tiny"}).num_actions == NUM_ACTIONS
    assert config_from_hparams({"model": "tiny", "num_actions": 5}).num_actions == 5


def test_config_dict_round_trip() -> None:
    config = CVPTConfig.from_name("tiny", NUM_ACTIONS, **SMALL)
    assert CVPTConfig.from_dict(config.to_dict()) == config


def test_channels_last_and_first_frames_give_same_logits() -> None:
    torch.manual_seed(0)
    model = CVPTModel(CVPTConfig.from_name("tiny", NUM_ACTIONS, **SMALL)).eval()
    frames = torch.randint(0, 256, (2, 3, 144, 144, 3), dtype=torch.uint8)
    first = torch.zeros(2, 3, dtype=torch.bool)
    with torch.no_grad():
        hwc, _ = model(frames, first, model.initial_state(2))
        chw, _ = model(frames.permute(0, 1, 4, 2, 3), first, model.initial_state(2))
    assert hwc.shape == (2, 3, 17)
    torch.testing.assert_close(hwc, chw)


def test_wrong_frame_shape_or_dtype_is_a_clear_error() -> None:
    model = CVPTModel(CVPTConfig.from_name("tiny", NUM_ACTIONS, **SMALL))
    first = torch.zeros(1, 1, dtype=torch.bool)
    bad = torch.zeros(1, 1, 64, 64, 3, dtype=torch.uint8)
    with pytest.raises(ValueError, match=r"\(B, T, 144, 144, 3\) or \(B, T, 3, 144, 144\), got \(1, 1, 64, 64, 3\)"):
        model(bad, first, model.initial_state(1))
    with pytest.raises(TypeError, match="frames must be uint8"):
        model(torch.zeros(1, 1, 144, 144, 3), first, model.initial_state(1))


def test_value_head_only_when_configured() -> None:
    model = CVPTModel(CVPTConfig.from_name("tiny", NUM_ACTIONS, **SMALL, value_head=True))
    hidden, _ = model.features(
        torch.zeros(1, 2, 144, 144, 3, dtype=torch.uint8), torch.zeros(1, 2), model.initial_state(1)
    )
    assert model.value_head(hidden).shape == (1, 2)
    with pytest.raises(RuntimeError, match="value_head=False"):
        CVPTModel(CVPTConfig.from_name("tiny", NUM_ACTIONS, **SMALL)).value_head(hidden)


def test_input_downsample_sees_the_average_pooled_frame() -> None:
    # A 2x downsampling model on a frame equals the same weights at frame_size 72 on the
    # 2x2-averaged frame; a factor that does not divide 144 is refused.
    torch.manual_seed(0)
    half = CVPTModel(CVPTConfig.from_name("tiny", NUM_ACTIONS, input_downsample=2, **SMALL)).eval()
    small = CVPTModel(CVPTConfig.from_name("tiny", NUM_ACTIONS, frame_size=72, **SMALL)).eval()
    small.load_state_dict(half.state_dict())
    frames = torch.randint(0, 4, (1, 2, 72, 72, 3), dtype=torch.uint8) * 64
    big = frames.repeat_interleave(2, dim=2).repeat_interleave(2, dim=3)  # every 2x2 block equal
    first = torch.ones(1, 2, dtype=torch.bool)
    with torch.no_grad():
        a, _ = half(big, first, half.initial_state(1))
        b, _ = small(frames, first, small.initial_state(1))
    torch.testing.assert_close(a, b)
    full = CVPTModel(CVPTConfig.from_name("tiny", NUM_ACTIONS, **SMALL))
    assert half.get_num_params() < full.get_num_params()
    with pytest.raises(ValueError, match="input_downsample=5 must be >= 1 and divide frame_size=144"):
        CVPTModel(CVPTConfig.from_name("tiny", NUM_ACTIONS, input_downsample=5))


def test_vpt_head_has_its_hidden_layer_and_old_configs_keep_the_linear_head() -> None:
    config = CVPTConfig.from_name("tiny", NUM_ACTIONS, **SMALL, head_hidden=16)
    head = CVPTModel(config).policy_head
    layers = [type(m).__name__ for m in head]
    assert layers == ["LayerNorm", "Linear", "ReLU", "LayerNorm", "Linear"]
    assert head[1].weight.shape == (16, 32) and head[-1].weight.shape == (17, 16)
    old = config.to_dict()
    del old["head_hidden"]  # an export written before the field existed
    assert isinstance(CVPTModel(CVPTConfig.from_dict(old)).policy_head, torch.nn.Linear)
    with pytest.raises(ValueError, match="head_hidden=-1"):
        CVPTModel(CVPTConfig.from_name("tiny", NUM_ACTIONS, **SMALL, head_hidden=-1))
