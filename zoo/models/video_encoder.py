"""Parts that turn per-frame CLIP image embeddings into one video embedding (MineCLIP style)."""

from typing import Literal

import torch
from torch import nn

TemporalPooling = Literal["cls", "mean"]


class TemporalTransformer(nn.Module):
    """Transformer over the frame embeddings of a clip, pooled to one vector.

    Frame order matters for "craft" vs "place" style captions, so each frame gets a learned temporal
    position embedding before self-attention across frames.
    """

    def __init__(
        self,
        width: int,
        num_frames: int,
        layers: int,
        heads: int,
        pooling: TemporalPooling = "cls",
        mlp_ratio: float = 4.0,
    ) -> None:
        super().__init__()
        if pooling not in ("cls", "mean"):
            raise ValueError(f"pooling must be 'cls' or 'mean', got {pooling!r}")
        self.pooling = pooling
        self.num_frames = num_frames
        num_tokens = num_frames + (1 if pooling == "cls" else 0)
        self.cls_token = nn.Parameter(torch.zeros(width)) if pooling == "cls" else None
        self.position_embedding = nn.Parameter(torch.randn(num_tokens, width) * 0.02)
        layer = nn.TransformerEncoderLayer(
            d_model=width,
            nhead=heads,
            dim_feedforward=int(width * mlp_ratio),
            dropout=0.0,
            activation="gelu",
            batch_first=True,
            norm_first=True,
        )
        self.transformer = nn.TransformerEncoder(
            layer, num_layers=layers, enable_nested_tensor=False
        )
        self.norm = nn.LayerNorm(width)

    def forward(self, frame_embeddings: torch.Tensor) -> torch.Tensor:
        """(B, T, width) frame embeddings -> (B, width) clip embedding."""
        batch, frames, _ = frame_embeddings.shape
        if frames != self.num_frames:
            raise ValueError(f"expected {self.num_frames} frame embeddings per clip, got {frames}")
        tokens = frame_embeddings
        if self.cls_token is not None:
            cls = self.cls_token.expand(batch, 1, -1).to(tokens.dtype)
            tokens = torch.cat([cls, tokens], dim=1)
        tokens = self.transformer(tokens + self.position_embedding.to(tokens.dtype))
        pooled = tokens[:, 0] if self.cls_token is not None else tokens.mean(dim=1)
        return self.norm(pooled)


class ResidualAdapter(nn.Module):
    """MLP adapter mixed with its input by a learned gate, sigmoid(4) ~ 0.98 of the input at init.

    Starting close to the identity keeps the pretrained embedding space intact early in training.
    """

    def __init__(self, width: int, layers: int, init_residual_logit: float = 4.0) -> None:
        super().__init__()
        if layers < 1:
            raise ValueError(f"adapter needs at least one layer, got {layers}")
        blocks: list[nn.Module] = []
        for index in range(layers):
            blocks.append(nn.Linear(width, width))
            if index < layers - 1:
                blocks.append(nn.ReLU())
        self.mlp = nn.Sequential(*blocks)
        self.residual_logit = nn.Parameter(torch.tensor(init_residual_logit))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        gate = torch.sigmoid(self.residual_logit)
        return gate * x + (1.0 - gate) * self.mlp(x)
