"""IMPALA ResNet frame encoder (Espeholt et al. 2018, as used by VPT and cleanrl)."""

from __future__ import annotations

import torch
from torch import nn
from torch.nn import functional as F


class ResidualBlock(nn.Module):
    """Two 3x3 convs with a skip connection; pre-activation as in the IMPALA paper."""

    def __init__(self, channels: int) -> None:
        super().__init__()
        self.conv0 = nn.Conv2d(channels, channels, kernel_size=3, padding=1)
        self.conv1 = nn.Conv2d(channels, channels, kernel_size=3, padding=1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x + self.conv1(F.relu(self.conv0(F.relu(x))))


class ConvSequence(nn.Module):
    """conv -> maxpool(3, stride 2) -> 2 residual blocks: halves the spatial size."""

    def __init__(self, in_channels: int, out_channels: int) -> None:
        super().__init__()
        self.conv = nn.Conv2d(in_channels, out_channels, kernel_size=3, padding=1)
        self.pool = nn.MaxPool2d(kernel_size=3, stride=2, padding=1)
        self.res0 = ResidualBlock(out_channels)
        self.res1 = ResidualBlock(out_channels)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.res1(self.res0(self.pool(self.conv(x))))


class ImpalaEncoder(nn.Module):
    """Maps uint8 frames (N, 3, H, W) to (N, out_dim) embeddings.

    Channels are ``channels`` times ``width`` (the paper's "IMPALA width"); the flattened
    feature map goes through a dense ``hidden`` layer and then to ``out_dim`` (the TrXL width).
    ``downsample`` > 1 average-pools the frames first (cheaper convolutions, fewer features).
    """

    def __init__(
        self,
        frame_size: int,
        channels: tuple[int, ...],
        width: int,
        hidden: int,
        out_dim: int,
        downsample: int = 1,
    ) -> None:
        super().__init__()
        self.downsample = downsample
        in_channels = 3
        stages = []
        size = frame_size // downsample
        for base in channels:
            stages.append(ConvSequence(in_channels, base * width))
            in_channels = base * width
            size = (size + 1) // 2
        self.stages = nn.Sequential(*stages)
        self.hidden = nn.Linear(in_channels * size * size, hidden)
        self.out = nn.Linear(hidden, out_dim)

    def forward(self, frames: torch.Tensor) -> torch.Tensor:
        x = frames.float() / 255.0
        if self.downsample > 1:
            x = F.avg_pool2d(x, self.downsample)
        x = self.stages(x).flatten(1)
        return self.out(F.relu(self.hidden(F.relu(x))))
