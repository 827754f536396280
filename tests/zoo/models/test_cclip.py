"""C-CLIP model: shapes, input checks, 224->144 weight loading, layer ids, and that it can learn."""

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from zoo.models.cclip import CCLIPConfig, CCLIPModel, build_cclip
from zoo.models.contrastive import multi_positive_infonce

CAPTIONS = [
    "obtain wood",
    "go to sleep",
    "craft wood pickaxe",
    "kill cow",
    "move to north",
    "flee from zombie",
    "dig a tunnel",
    "place table on grass",
]


@pytest.fixture(scope="module")
def smoke_model() -> CCLIPModel:
    torch.manual_seed(0)
    return build_cclip("smoke").eval()


def random_clips(batch: int, seed: int = 0) -> torch.Tensor:
    generator = torch.Generator().manual_seed(seed)
    return torch.randint(0, 256, (batch, 6, 144, 144, 3), dtype=torch.uint8, generator=generator)


def test_encode_video_and_text_shapes_dtypes_and_unit_norm(smoke_model):
    with torch.no_grad():
        video = smoke_model.encode_video(random_clips(3))
        text = smoke_model.encode_text(CAPTIONS[:5])
    assert video.shape == (3, 64) and video.dtype == torch.float32
    assert text.shape == (5, 64) and text.dtype == torch.float32
    torch.testing.assert_close(video.norm(dim=-1), torch.ones(3))
    torch.testing.assert_close(text.norm(dim=-1), torch.ones(5))


def test_numpy_and_tensor_clips_give_the_same_embedding(smoke_model):
    clips = random_clips(2)
    with torch.no_grad():
        torch.testing.assert_close(
            smoke_model.encode_video(clips.numpy()), smoke_model.encode_video(clips)
        )


def test_frame_order_changes_the_video_embedding(smoke_model):
    clips = random_clips(2)
    with torch.no_grad():
        forward = smoke_model.encode_video(clips)
        backward = smoke_model.encode_video(clips.flip(1))
    assert not torch.allclose(forward, backward, atol=1e-4)


def test_tokens_and_strings_encode_the_same(smoke_model):
    tokens = smoke_model.tokenize(CAPTIONS[:3])
    assert tokens.shape == (3, 32) and tokens.dtype == torch.int64
    with torch.no_grad():
        torch.testing.assert_close(
            smoke_model.encode_text(tokens), smoke_model.encode_text(CAPTIONS[:3])
        )


@pytest.mark.parametrize(
    "shape, dtype, message",
    [
        ((6, 144, 144, 3), torch.uint8, "shape"),
        ((2, 5, 144, 144, 3), torch.uint8, "shape"),
        ((2, 6, 64, 64, 3), torch.uint8, "shape"),
        ((2, 6, 3, 144, 144), torch.uint8, "shape"),
        ((2, 6, 144, 144, 3), torch.float32, "uint8"),
    ],
)
def test_wrong_clip_raises_clear_value_error(smoke_model, shape, dtype, message):
    with pytest.raises(ValueError, match=message):
        smoke_model.encode_video(torch.zeros(shape, dtype=dtype))


def test_encode_text_rejects_a_bare_string(smoke_model):
    with pytest.raises(ValueError, match="list of caption strings"):
        smoke_model.encode_text("go to sleep")


def test_presets_and_unknown_names():
    assert CCLIPConfig.from_name("vit_b16").vision_width == 768
    assert CCLIPConfig.from_name("smoke", text_layers=3).text_layers == 3
    with pytest.raises(ValueError, match="unknown C-CLIP preset"):
        CCLIPConfig.from_name("vit_huge")
    with pytest.raises(ValueError, match="unknown C-CLIP config fields"):
        CCLIPConfig.from_name("smoke", depth=3)


def test_vit_b16_preset_has_a_9x9_patch_grid():
    model = build_cclip("vit_b16", vision_layers=1, text_layers=1)
    assert tuple(model.clip.visual.grid_size) == (9, 9)
    assert model.clip.visual.positional_embedding.shape == (82, 768)


def test_pretrained_224_checkpoint_is_resized_into_a_144_model(tmp_path):
    torch.manual_seed(1)
    source = build_cclip("smoke", image_size=224)
    assert source.clip.visual.positional_embedding.shape == (197, 64)
    path = tmp_path / "clip_224.pt"
    torch.save(source.clip.state_dict(), path)

    target = build_cclip("smoke", pretrained_path=path)

    old = source.clip.visual.positional_embedding.detach()
    new = target.clip.visual.positional_embedding.detach()
    assert new.shape == (82, 64)
    torch.testing.assert_close(new[0], old[0])  # the class token's position is kept
    grid = old[1:].reshape(1, 14, 14, 64).permute(0, 3, 1, 2)
    expected = F.interpolate(grid, size=(9, 9), mode="bicubic", antialias=True, align_corners=False)
    torch.testing.assert_close(new[1:], expected.permute(0, 2, 3, 1).reshape(81, 64))
    torch.testing.assert_close(target.clip.visual.conv1.weight, source.clip.visual.conv1.weight)
    torch.testing.assert_close(
        target.clip.token_embedding.weight, source.clip.token_embedding.weight
    )
    assert target.pretrained_path == str(path)


def test_pretrained_checkpoint_of_other_sizes_is_rejected(tmp_path):
    path = tmp_path / "wide.pt"
    torch.save(build_cclip("smoke", vision_width=128).clip.state_dict(), path)
    with pytest.raises(ValueError, match="does not fit"):
        build_cclip("smoke", pretrained_path=path)
    with pytest.raises(FileNotFoundError, match="missing.pt"):
        build_cclip("smoke", pretrained_path=tmp_path / "missing.pt")


def test_tower_layer_ids(smoke_model):
    layer = smoke_model.tower_layer
    assert layer("clip.visual.conv1.weight") == (0, 3)
    assert layer("clip.visual.positional_embedding") == (0, 3)
    assert layer("clip.visual.transformer.resblocks.0.attn.in_proj_weight") == (1, 3)
    assert layer("clip.visual.transformer.resblocks.1.mlp.c_fc.bias") == (2, 3)
    assert layer("clip.visual.proj") == (3, 3)
    assert layer("clip.token_embedding.weight") == (0, 3)
    assert layer("clip.transformer.resblocks.1.ln_1.weight") == (2, 3)
    assert layer("clip.text_projection") == (3, 3)
    assert layer("clip.ln_final.bias") == (3, 3)
    assert layer("clip.logit_scale") is None
    assert layer("temporal.position_embedding") is None
    assert layer("video_adapter.residual_logit") is None


def test_smoke_model_overfits_eight_clips():
    """Eight clips of distinct solid colours: a randomly initialised ViT separates these at once,
    while pixel noise averages out over the patches (all noise clips embed alike at init)."""
    torch.manual_seed(0)
    model = build_cclip("smoke")
    colours = torch.randint(0, 256, (8, 6, 1, 1, 3), dtype=torch.uint8)
    clips = colours.expand(8, 6, 144, 144, 3).contiguous()
    tokens = model.tokenize(CAPTIONS)
    caption_ids = torch.arange(8)
    optimizer = torch.optim.AdamW(model.parameters(), lr=5e-4)
    losses = []
    for _ in range(20):
        loss = multi_positive_infonce(
            model.encode_video(clips), model.encode_text(tokens), caption_ids, model.logit_scale
        )
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        losses.append(loss.item())
    assert losses[0] > 1.5  # about ln(8) at init
    assert losses[-1] < 0.1 * losses[0]
    with torch.no_grad():
        similarity = model.encode_video(clips) @ model.encode_text(tokens).T
    assert (similarity.argmax(dim=1) == caption_ids).all()


def test_num_params_counts_every_parameter(smoke_model):
    assert smoke_model.num_params() == sum(np.prod(p.shape) for p in smoke_model.parameters())
