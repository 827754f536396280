"""A frame encoder on Crafter's tile grid: a cheaper alternative to the IMPALA ResNet.

Crafter draws every frame on a grid of square tiles (144 px = 9 x 9 tiles of 16 px: a 9 x 7
local view over a 9 x 2 inventory), and each tile is one texture: a material, a creature, the
player facing one way, or an inventory item with its count. ``TileEncoder`` embeds each tile
with one strided convolution (a patch embedding whose patch is the tile, as a ViT's), mixes
neighbouring tiles with one pre-activation residual block of 3 x 3 convolutions, and maps the
flattened grid through a dense layer, as the IMPALA encoder's head does. At the paper's tiny
widths (32 channels, a 256 dense layer) it counts 9.3x fewer forward FLOPs per frame on 144-px
frames than IMPALA does at 72 px (tests/zoo/models/test_tiles.py pins both counts). It is a named option (``CVPTConfig.encoder``), never the
paper configs' default.
"""

from __future__ import annotations

import torch
from torch import nn
from torch.nn import functional as F

from zoo.models.impala import ResidualBlock


class TileEncoder(nn.Module):
    """Maps uint8 frames (N, 3, S, S) to (N, out_dim): one token per ``tile_size``-px tile.

    ``downsample`` > 1 average-pools the frames first; the patch is then ``tile_size //
    downsample`` px, so each token still covers exactly one tile."""

    def __init__(
        self,
        frame_size: int,
        tile_size: int,
        channels: int,
        hidden: int,
        out_dim: int,
        downsample: int = 1,
    ) -> None:
        super().__init__()
        if tile_size < 1 or frame_size % tile_size:
            raise ValueError(
                f"tile_size={tile_size} must divide frame_size={frame_size} (Crafter's 144-px "
                f"frames are 9 x 9 tiles of 16 px)"
            )
        if tile_size % downsample:
            raise ValueError(
                f"input_downsample={downsample} must divide tile_size={tile_size}, so that a "
                f"patch is still one tile"
            )
        self.downsample = downsample
        self.patch = tile_size // downsample
        self.grid = frame_size // tile_size
        self.embed = nn.Conv2d(3, channels, kernel_size=self.patch, stride=self.patch)
        self.mix = ResidualBlock(channels)
        self.hidden = nn.Linear(channels * self.grid * self.grid, hidden)
        self.out = nn.Linear(hidden, out_dim)

    def forward(self, frames: torch.Tensor) -> torch.Tensor:
        n, size = frames.shape[0], self.grid
        weight = self.embed.weight.permute(0, 2, 3, 1).flatten(1)  # a patch's (y, x, channel)
        tokens = F.linear(self._patches(frames), weight / 255.0, self.embed.bias)
        x = tokens.view(n, size, size, -1).permute(0, 3, 1, 2)  # (N, C, grid, grid)
        x = self.mix(x).flatten(1)
        return self.out(F.relu(self.hidden(F.relu(x))))

    def _patches(self, frames: torch.Tensor) -> torch.Tensor:
        """(N * grid * grid, patch * patch * 3) pixel values 0-255 in the compute dtype.

        ``embed`` is applied as one matmul over these rows with its weight scaled by 1/255:
        the same function as the strided convolution on frames / 255, but the patches are cut
        from the uint8 frames and cast once (under bf16 autocast straight to bf16, where 0-255
        are exact), which on a CPU is cheaper than converting, dividing and convolving the
        144-px float frame (docs/results/cvpt.md has the A/B)."""
        n, patch, size = frames.shape[0], self.patch, self.grid
        x = frames
        if self.downsample > 1:
            x = F.avg_pool2d(x.float(), self.downsample)
        device = frames.device.type
        dtype = (torch.get_autocast_dtype(device) if torch.is_autocast_enabled(device)
                 else torch.float32)
        # Rows in (y, x, channel) order: from channel-last frames (the datasets' layout, of
        # which ``encode_frames`` passes a view) each patch row is 16 x 3 contiguous bytes.
        rows = torch.empty((n, size, size, patch, patch, 3), dtype=dtype, device=frames.device)
        rows.copy_(x.reshape(n, 3, size, patch, size, patch).permute(0, 2, 4, 3, 5, 1))
        return rows.view(n * size * size, patch * patch * 3)  # cut and cast in one pass
