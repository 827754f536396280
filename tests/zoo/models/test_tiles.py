"""The tile-grid encoder: one token per Crafter tile, its FLOPs by hand, its config errors, and a
C-VPT built on it that runs, reloads and learns like the IMPALA one."""

from __future__ import annotations

import pytest
import torch
from torch.utils.flop_counter import FlopCounterMode

from zoo.envs.constants import NUM_ACTIONS
from zoo.models.cvpt import CVPTConfig, CVPTModel
from zoo.models.tiles import TileEncoder


def _tokens(encoder: TileEncoder, frames: torch.Tensor) -> torch.Tensor:
    """The embedding grid (N, C, 9, 9), read off the residual block's input."""
    seen = []
    handle = encoder.mix.register_forward_hook(lambda m, i, o: seen.append(i[0]))
    with torch.no_grad():
        encoder(frames)
    handle.remove()
    return seen[0]


@pytest.mark.parametrize("downsample", [1, 2])
def test_each_token_sees_exactly_one_tile(downsample: int) -> None:
    """Repainting the 16-px tile at row 3, column 5 changes that token and no other, whatever
    the input pooling: a patch that straddled tiles would mix two textures."""
    torch.manual_seed(0)
    encoder = TileEncoder(144, 16, channels=4, hidden=8, out_dim=16, downsample=downsample)
    frames = torch.randint(0, 256, (1, 3, 144, 144), dtype=torch.uint8)
    painted = frames.clone()
    painted[:, :, 48:64, 80:96] = 255 - painted[:, :, 48:64, 80:96]
    changed = (_tokens(encoder, frames) != _tokens(encoder, painted)).any(dim=1)[0]
    expected = torch.zeros(9, 9, dtype=torch.bool)
    expected[3, 5] = True
    assert torch.equal(changed, expected)


@pytest.mark.parametrize("downsample", [1, 2])
def test_the_patch_matmul_is_the_strided_convolution_of_the_scaled_frame(downsample: int) -> None:
    """``embed`` runs as one matmul over uint8 patches with its weight / 255; it must be the
    convolution the parameters describe, ``conv(pool(frames / 255))``, in fp32 and in bf16."""
    torch.manual_seed(0)
    encoder = TileEncoder(144, 16, channels=4, hidden=8, out_dim=16, downsample=downsample)
    frames = torch.randint(0, 256, (3, 3, 144, 144), dtype=torch.uint8)
    x = frames.float() / 255.0
    if downsample > 1:
        x = torch.nn.functional.avg_pool2d(x, downsample)
    want = encoder.embed(x)
    torch.testing.assert_close(_tokens(encoder, frames), want, atol=1e-5, rtol=1e-5)
    with torch.autocast("cpu", dtype=torch.bfloat16):
        got = _tokens(encoder, frames)
        conv = encoder.embed(x)
    assert got.dtype == torch.bfloat16
    torch.testing.assert_close(got.float(), conv.float(), atol=0.05, rtol=0.02)


def test_forward_flops_by_hand() -> None:
    """2 x outputs x inputs per layer, 144-px frames pooled to 72 (tile 16 -> 8-px patch):
    embed 81 tokens x 4 ch x (3 x 8 x 8) x 2 = 124,416; residual 3x3 convs 4 -> 4 on the 9 x 9
    grid 81 x 4 x 36 x 2 = 23,328 each; dense 324 -> 8: 5,184; 8 -> 16: 256. 176,512 per frame."""
    encoder = TileEncoder(144, 16, channels=4, hidden=8, out_dim=16, downsample=2)
    counter = FlopCounterMode(display=False)
    with counter:
        encoder(torch.zeros(2, 3, 144, 144, dtype=torch.uint8))
    assert counter.get_total_flops() == 2 * (124_416 + 2 * 23_328 + 5_184 + 256)


def test_costs_a_fraction_of_impala_per_frame() -> None:
    """At the tiny preset's widths the tile encoder (32 channels) on 144-px frames counts
    8,359,936 forward FLOPs per frame (embed 81 x 32 x 768 x 2 = 3,981,312; two residual convs
    81 x 32 x 288 x 2 = 1,492,992 each; dense 2,592 -> 256: 1,327,104; 256 -> 128: 65,536)
    against IMPALA's 77,535,232 at 72 px (the shipped recipe's input): 9.27x fewer."""
    counts = {}
    for name, overrides in {"impala": dict(input_downsample=2),
                            "tiles": dict(encoder="tiles")}.items():
        model = CVPTModel(CVPTConfig.from_name("tiny", NUM_ACTIONS, **overrides))
        counter = FlopCounterMode(display=False)
        with counter:
            model.encoder(torch.zeros(1, 3, 144, 144, dtype=torch.uint8))
        counts[name] = counter.get_total_flops()
    assert counts["tiles"] == 3_981_312 + 2 * 1_492_992 + 1_327_104 + 65_536
    assert counts["impala"] / counts["tiles"] == pytest.approx(9.27, abs=0.01)


def test_bad_tile_settings_name_the_field() -> None:
    with pytest.raises(ValueError, match="tile_size=10 must divide frame_size=144"):
        CVPTModel(CVPTConfig.from_name("tiny", NUM_ACTIONS, encoder="tiles", tile_size=10))
    with pytest.raises(ValueError, match="input_downsample=3 must divide tile_size=16"):
        CVPTModel(CVPTConfig.from_name("tiny", NUM_ACTIONS, encoder="tiles", input_downsample=3))
    with pytest.raises(ValueError, match="encoder='vit': expected 'impala' or 'tiles'"):
        CVPTModel(CVPTConfig.from_name("tiny", NUM_ACTIONS, encoder="vit"))


def test_a_tile_cvpt_round_trips_its_config_and_gives_logits() -> None:
    config = CVPTConfig.from_name("tiny", NUM_ACTIONS, encoder="tiles", tile_channels=8)
    assert CVPTConfig.from_dict(config.to_dict()) == config
    model = CVPTModel(config).eval()
    frames = torch.randint(0, 256, (2, 3, 144, 144, 3), dtype=torch.uint8)
    first = torch.ones(2, 3, dtype=torch.bool)
    logits, _ = model(frames, first, model.initial_state(2))
    assert logits.shape == (2, 3, NUM_ACTIONS) and logits.dtype == torch.float32
