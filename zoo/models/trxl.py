"""Transformer-XL with segment-level recurrent memory and episode-start masking.

Positional information is a learned relative bias: one scalar per head and per distance
0..memory_len, added to the attention logits (like T5's bias, without buckets). We chose it
over Dai et al.'s sinusoidal encoding with u/v biases because it is exact under caching,
adds only (memory_len + 1) * n_heads parameters (the paper's sizes then match without a
d x d position projection per layer), and it is what the attention span needs: every query
attends to itself and at most ``memory_len`` earlier steps. With that sliding-window span,
processing a sequence in segments of any length (training windows of 64, or one step at a
time with a rolling memory of the last ``memory_len`` hidden states) gives the same outputs
as processing it in one pass.

A per-step ``first`` flag (True at an episode's first step) stops attention to anything
before that step, inside the segment and into the memory.
"""

from __future__ import annotations

from typing import NamedTuple

import torch
from torch import nn
from torch.nn import functional as F


class TrXLState(NamedTuple):
    """What a TransformerXL carries between segments.

    memory: (n_layers, B, memory_len, d_model) inputs of each layer at the last memory_len
        steps (detached: no gradient flows into an earlier segment).
    blocked: (B, memory_len) True where a slot is empty or lies before the current episode.
    """

    memory: torch.Tensor
    blocked: torch.Tensor


class RelativeSelfAttention(nn.Module):
    """Multi-head attention over [memory, segment] with a learned per-distance bias."""

    def __init__(self, d_model: int, n_heads: int, memory_len: int, dropout: float) -> None:
        super().__init__()
        if d_model % n_heads:
            raise ValueError(f"d_model={d_model} must be divisible by n_heads={n_heads}")
        self.n_heads = n_heads
        self.dropout = dropout
        self.query = nn.Linear(d_model, d_model)
        self.key_value = nn.Linear(d_model, 2 * d_model)
        self.out = nn.Linear(d_model, d_model)
        self.relative_bias = nn.Embedding(memory_len + 1, n_heads)
        nn.init.zeros_(self.relative_bias.weight)

    def forward(
        self, x: torch.Tensor, context: torch.Tensor, distance: torch.Tensor, allowed: torch.Tensor
    ) -> torch.Tensor:
        """x: (B, T, d) queries; context: (B, S, d) keys/values (memory then segment);
        distance: (T, S) query minus key position, clamped to the span; allowed: (B, T, S)."""
        b, t, d = x.shape
        s = context.shape[1]
        h = self.n_heads
        q = self.query(x).view(b, t, h, d // h).transpose(1, 2)
        k, v = self.key_value(context).view(b, s, 2, h, d // h).permute(2, 0, 3, 1, 4)
        bias = self.relative_bias(distance).permute(2, 0, 1).to(q.dtype)  # (H, T, S)
        logits_mask = bias.unsqueeze(0).masked_fill(~allowed.unsqueeze(1), float("-inf"))
        y = F.scaled_dot_product_attention(
            q, k, v, attn_mask=logits_mask, dropout_p=self.dropout if self.training else 0.0
        )
        return self.out(y.transpose(1, 2).reshape(b, t, d))


class TrXLLayer(nn.Module):
    """Pre-norm transformer block whose attention also reads the memory of this layer."""

    def __init__(
        self, d_model: int, d_ff: int, n_heads: int, memory_len: int, dropout: float
    ) -> None:
        super().__init__()
        self.norm_attn = nn.LayerNorm(d_model)
        self.attn = RelativeSelfAttention(d_model, n_heads, memory_len, dropout)
        self.norm_ff = nn.LayerNorm(d_model)
        self.ff = nn.Sequential(
            nn.Linear(d_model, d_ff), nn.GELU(), nn.Dropout(dropout), nn.Linear(d_ff, d_model)
        )
        self.drop = nn.Dropout(dropout)

    def forward(
        self, x: torch.Tensor, memory: torch.Tensor, distance: torch.Tensor, allowed: torch.Tensor
    ) -> torch.Tensor:
        context = self.norm_attn(torch.cat([memory, x], dim=1))
        x = x + self.drop(self.attn(context[:, memory.shape[1] :], context, distance, allowed))
        return x + self.drop(self.ff(self.norm_ff(x)))


class TransformerXL(nn.Module):
    """Stack of TrXL layers; ``forward`` maps a segment and a state to outputs and a new state."""

    def __init__(
        self,
        d_model: int,
        d_ff: int,
        n_heads: int,
        n_layers: int,
        memory_len: int,
        dropout: float = 0.0,
    ) -> None:
        super().__init__()
        if memory_len < 1:
            raise ValueError(f"memory_len must be >= 1, got {memory_len}")
        self.d_model = d_model
        self.memory_len = memory_len
        self.layers = nn.ModuleList(
            TrXLLayer(d_model, d_ff, n_heads, memory_len, dropout) for _ in range(n_layers)
        )
        self.norm = nn.LayerNorm(d_model)

    def initial_state(self, batch: int, device: torch.device | str = "cpu") -> TrXLState:
        """Empty memory: every slot blocked, so the first step attends only to itself."""
        memory = torch.zeros(len(self.layers), batch, self.memory_len, self.d_model, device=device)
        blocked = torch.ones(batch, self.memory_len, dtype=torch.bool, device=device)
        return TrXLState(memory, blocked)

    def forward(
        self, x: torch.Tensor, first: torch.Tensor, state: TrXLState
    ) -> tuple[torch.Tensor, TrXLState]:
        """x: (B, T, d); first: (B, T) bool. Returns (B, T, d) and the state after the segment."""
        b, t, _ = x.shape
        m = self.memory_len
        if first.shape != (b, t):
            raise ValueError(f"first must have shape {(b, t)} (batch, time), got {tuple(first.shape)}")
        if state.memory.shape[1:3] != (b, m) or state.blocked.shape != (b, m):
            raise ValueError(
                f"state is for batch {state.memory.shape[1]} and memory {state.memory.shape[2]}, "
                f"expected batch {b} and memory {m}"
            )
        # Episode index of every query and key: keys from another episode are masked.
        episode_query = torch.cumsum(first.long(), dim=1)  # (B, T)
        episode_memory = torch.where(state.blocked, -1, 0)  # (B, M)
        episode_key = torch.cat([episode_memory, episode_query], dim=1)  # (B, M + T)
        positions = torch.arange(-m, t, device=x.device)
        distance = torch.arange(t, device=x.device)[:, None] - positions[None, :]  # (T, M + T)
        in_span = (distance >= 0) & (distance <= m)
        allowed = in_span[None] & (episode_key[:, None, :] == episode_query[:, :, None])
        distance = distance.clamp(0, m)

        memory = state.memory.to(x.dtype)
        new_memory = []
        for layer, layer_memory in zip(self.layers, memory, strict=True):
            new_memory.append(torch.cat([layer_memory, x], dim=1)[:, -m:].detach())
            x = layer(x, layer_memory, distance, allowed)
        blocked = (episode_key != episode_query[:, -1:])[:, -m:]
        return self.norm(x), TrXLState(torch.stack(new_memory), blocked)
