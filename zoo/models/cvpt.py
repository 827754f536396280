"""C-VPT: IMPALA encoder -> Transformer-XL -> policy head (paper section 4.1, VPT's design).

``encoder: tiles`` swaps the IMPALA ResNet for ``TileEncoder`` (zoo/models/tiles.py), a cheaper
named option for CPU training."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import torch
from torch import nn

from zoo.models.impala import ImpalaEncoder
from zoo.models.tiles import TileEncoder
from zoo.models.trxl import TransformerXL, TrXLState


@dataclass(kw_only=True)
class CVPTConfig:
    """Sizes of a C-VPT policy. Presets ``tiny``/``base``/``large`` follow the paper's table;
    the action count is the game's, so whoever builds the model gives it."""

    name: str = "custom"
    """Preset this config came from (informational)."""
    d_model: int = 128
    """Transformer-XL width; also the encoder's output size."""
    d_ff: int = 512
    """Hidden size of each transformer feed-forward block."""
    n_heads: int = 4
    """Attention heads per layer."""
    n_layers: int = 2
    """Transformer-XL layers ("recurrence layers" in the paper)."""
    impala_width: int = 1
    """Multiplier of the IMPALA channels."""
    impala_channels: tuple[int, ...] = (16, 32, 32)
    """Base channels of the IMPALA stages (each stage halves the frame size)."""
    encoder: str = "impala"
    """Frame encoder: ``impala`` (the paper's ResNet) or ``tiles`` (``TileEncoder``: one token
    per tile of Crafter's grid, ~9x fewer FLOPs; a named CPU option, not the paper's)."""
    tile_size: int = 16
    """Pixels of one tile in the stored frame (``encoder: tiles``; Crafter's 144 px: 16)."""
    tile_channels: int = 32
    """Channels of each tile's embedding (``encoder: tiles``)."""
    encoder_hidden: int = 256
    """Dense layer between the flattened encoder features and d_model (VPT uses 256)."""
    memory_len: int = 64
    """Steps of recurrent memory per layer; also the attention span."""
    num_actions: int
    """Size of the policy head: the game's action count."""
    frame_size: int = 144
    """Frames are frame_size x frame_size RGB."""
    input_downsample: int = 1
    """Average-pool frames by this factor before the encoder. The paper uses 1 (144 px); 2
    (72 px, near the 64 px of Crafter's scoreboard agents) has a quarter of the pixels and
    trains much faster on a CPU."""
    dropout: float = 0.0
    """Dropout in attention and feed-forward blocks."""
    value_head: bool = False
    """Add a scalar value head (unused by behaviour cloning; for RL fine-tuning)."""
    head_hidden: int = 0
    """Width of a hidden layer in the policy head (0: one linear layer). VPT's head has one
    (LayerNorm, linear + ReLU, LayerNorm, then the logits); C-Steve-1's head conditioning
    needs it: over a single linear head a goal can only shift the logits by the same amount in
    every state."""

    @classmethod
    def from_name(cls, name: str, num_actions: int, **overrides: Any) -> CVPTConfig:
        """A preset by name for a game of ``num_actions`` actions, with any field overridden."""
        if name not in PRESETS:
            raise ValueError(f"unknown C-VPT preset {name!r}; expected one of {sorted(PRESETS)}")
        return cls(**{"name": name, "num_actions": num_actions, **PRESETS[name], **overrides})

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> CVPTConfig:
        """Inverse of ``to_dict``; unknown keys are an error (a config from another model)."""
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise ValueError(f"unknown CVPTConfig fields {unknown}; known fields: {sorted(known)}")
        values = dict(values)
        if "impala_channels" in values:
            values["impala_channels"] = tuple(values["impala_channels"])
        return cls(**values)

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-able values (lists for tuples)."""
        values = dataclasses.asdict(self)
        values["impala_channels"] = list(self.impala_channels)
        return values


PRESETS: dict[str, dict[str, Any]] = {
    # Paper: 3.2M / 15.9M / 64.3M parameters (tests check these within 5%).
    "tiny": {"d_model": 128, "d_ff": 512, "n_heads": 4, "n_layers": 2, "impala_width": 1},
    "base": {"d_model": 512, "d_ff": 2048, "n_heads": 4, "n_layers": 4, "impala_width": 1},
    "large": {"d_model": 1024, "d_ff": 4096, "n_heads": 8, "n_layers": 4, "impala_width": 4},
}
PAPER_PARAMS = {"tiny": 3.2e6, "base": 15.9e6, "large": 64.3e6}


class CVPTModel(nn.Module):
    """The C-VPT policy network; plain torch so it can be played without Lightning."""

    def __init__(self, config: CVPTConfig) -> None:
        super().__init__()
        self.config = config
        if config.input_downsample < 1 or config.frame_size % config.input_downsample:
            raise ValueError(
                f"input_downsample={config.input_downsample} must be >= 1 and divide "
                f"frame_size={config.frame_size}"
            )
        self.encoder = frame_encoder(config)
        self.trxl = TransformerXL(
            d_model=config.d_model,
            d_ff=config.d_ff,
            n_heads=config.n_heads,
            n_layers=config.n_layers,
            memory_len=config.memory_len,
            dropout=config.dropout,
        )
        self.policy_head = policy_head(config.d_model, config.head_hidden, config.num_actions)
        self.value = nn.Linear(config.d_model, 1) if config.value_head else None

    def get_num_params(self) -> int:
        return sum(p.numel() for p in self.parameters())

    def initial_state(self, batch: int, device: torch.device | str | None = None) -> TrXLState:
        device = next(self.parameters()).device if device is None else device
        return self.trxl.initial_state(batch, device)

    def encode_frames(self, frames: torch.Tensor) -> torch.Tensor:
        """uint8 frames (B, T, S, S, 3) or (B, T, 3, S, S) -> (B, T, d_model)."""
        s = self.config.frame_size
        shape = tuple(frames.shape)
        if frames.dim() == 5 and shape[2:] == (s, s, 3):
            frames = frames.permute(0, 1, 4, 2, 3)
        elif not (frames.dim() == 5 and shape[2:] == (3, s, s)):
            raise ValueError(
                f"frames must have shape (B, T, {s}, {s}, 3) or (B, T, 3, {s}, {s}), got {shape}"
            )
        if frames.dtype != torch.uint8:
            raise TypeError(f"frames must be uint8 (0-255, normalized inside), got {frames.dtype}")
        b, t = shape[:2]
        return self.encoder(frames.reshape(b * t, 3, s, s)).view(b, t, -1)

    def features(
        self, frames: torch.Tensor, first: torch.Tensor, state: TrXLState
    ) -> tuple[torch.Tensor, TrXLState]:
        """History-aware features (B, T, d_model), before any head (C-Steve-1 conditions here)."""
        return self.trxl(self.encode_frames(frames), first.bool(), state)

    def forward(
        self, frames: torch.Tensor, first: torch.Tensor, state: TrXLState
    ) -> tuple[torch.Tensor, TrXLState]:
        """Action logits (B, T, num_actions) and the state after this segment."""
        hidden, state = self.features(frames, first, state)
        return self.policy_head(hidden), state

    def value_head(self, hidden: torch.Tensor) -> torch.Tensor:
        """Value estimates (B, T) from ``features`` output; needs ``config.value_head``."""
        if self.value is None:
            raise RuntimeError("this model was built with value_head=False")
        return self.value(hidden).squeeze(-1)


def frame_encoder(config: CVPTConfig) -> nn.Module:
    """The encoder ``config.encoder`` names, mapping uint8 frames to (N, d_model)."""
    if config.encoder == "impala":
        return ImpalaEncoder(
            frame_size=config.frame_size,
            downsample=config.input_downsample,
            channels=tuple(config.impala_channels),
            width=config.impala_width,
            hidden=config.encoder_hidden,
            out_dim=config.d_model,
        )
    if config.encoder == "tiles":
        return TileEncoder(
            frame_size=config.frame_size,
            tile_size=config.tile_size,
            channels=config.tile_channels,
            hidden=config.encoder_hidden,
            out_dim=config.d_model,
            downsample=config.input_downsample,
        )
    raise ValueError(f"encoder={config.encoder!r}: expected 'impala' or 'tiles'")


def policy_head(width: int, hidden: int, actions: int) -> nn.Module:
    """Linear logits (hidden 0), or VPT's: LayerNorm -> Linear -> ReLU -> LayerNorm -> Linear."""
    if hidden < 0:
        raise ValueError(f"head_hidden={hidden} must be >= 0")
    if hidden == 0:
        return nn.Linear(width, actions)
    return nn.Sequential(
        nn.LayerNorm(width),
        nn.Linear(width, hidden),
        nn.ReLU(),
        nn.LayerNorm(hidden),
        nn.Linear(hidden, actions),
    )


__all__ = ["PAPER_PARAMS", "PRESETS", "CVPTConfig", "CVPTModel"]
