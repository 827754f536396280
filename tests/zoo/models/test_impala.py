"""IMPALA encoder: output size and the size of its flattened feature map."""

from __future__ import annotations

import torch

from zoo.models.impala import ImpalaEncoder


def test_encoder_maps_frames_to_embeddings() -> None:
    encoder = ImpalaEncoder(frame_size=144, channels=(4, 8, 8), width=2, hidden=32, out_dim=24)
    frames = torch.randint(0, 256, (3, 3, 144, 144), dtype=torch.uint8)
    out = encoder(frames)
    assert out.shape == (3, 24) and out.dtype == torch.float32
    # 144 -> 72 -> 36 -> 18 after three stride-2 pools; 8 * width channels
    assert encoder.hidden.in_features == 16 * 18 * 18
