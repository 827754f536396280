"""The networks PPO trains, behind one small interface.

Every policy has ``preprocess(obs)`` (what the rollout stores per step: frames, or frozen
features so the update never reruns a frozen encoder), ``initial_state(n)``, ``step`` (one
step of N envs, no gradient) and ``evaluate`` (a whole stored segment from the state the
rollout started it with, with gradients), ``select_state`` (the envs of a minibatch) and
``reference_parameters`` (frozen copies only the KL term reads: not part of the acting policy,
so ``count_parameters`` leaves them out of its total).
Re-running the segment from its stored start state gives the rollout's own outputs (the GRU is
deterministic; the Transformer-XL is segment-exact by design, ``zoo/models/trxl.py``), so the
first epoch's ratio is exactly 1.

- ``RecurrentActorCritic``: encoder -> GRU -> policy and value heads. PPO-RNN puts an IMPALA
  CNN on the pixels in front of it; PPO-Steve's planner a dense layer on its feature vector.
- ``CVPTRLPolicy``: C-VPT with ``peft`` LoRA on its Transformer-XL and a new value head; the
  encoder and policy head stay frozen and a frozen copy of the pretrained Transformer-XL and
  head gives the reference logits of the KL term (VPT's fine-tuning, paper appendix).
"""

from __future__ import annotations

import copy
from typing import Any, NamedTuple

import numpy as np
import torch
from peft import LoraConfig, inject_adapter_in_model
from torch import nn

from zoo.models.cvpt import CVPTModel
from zoo.models.impala import ImpalaEncoder
from zoo.models.trxl import TrXLState


class StepOut(NamedTuple):
    logits: torch.Tensor  # (N, A)
    value: torch.Tensor  # (N,)
    state: Any
    ref_logits: torch.Tensor | None = None  # (N, A), policies with a KL reference only


class FrameEncoder(nn.Module):
    """uint8 frames (N, S, S, 3) -> (N, out_dim) with an IMPALA CNN."""

    def __init__(self, frame_size: int, downsample: int, out_dim: int) -> None:
        super().__init__()
        self.cnn = ImpalaEncoder(
            frame_size=frame_size, channels=(16, 32, 32), width=1, hidden=256, out_dim=out_dim,
            downsample=downsample,
        )

    def forward(self, frames: torch.Tensor) -> torch.Tensor:
        return self.cnn(frames.permute(0, 3, 1, 2))


class RecurrentActorCritic(nn.Module):
    """encoder -> GRU (reset at episode starts) -> policy logits and value."""

    def __init__(self, encoder: nn.Module, feature_dim: int, hidden: int, num_actions: int):
        super().__init__()
        self.encoder = encoder
        self.gru = nn.GRUCell(feature_dim, hidden)
        self.policy = nn.Linear(hidden, num_actions)
        self.value = nn.Linear(hidden, 1)
        nn.init.orthogonal_(self.policy.weight, gain=0.01)
        nn.init.zeros_(self.policy.bias)
        self.hidden = hidden

    def preprocess(self, obs: np.ndarray | torch.Tensor) -> torch.Tensor:
        return torch.as_tensor(np.array(obs)) if isinstance(obs, np.ndarray) else obs.clone()

    def initial_state(self, n: int) -> torch.Tensor:
        return torch.zeros(n, self.hidden, device=self.policy.weight.device)

    def select_state(self, state: torch.Tensor, index: torch.Tensor) -> torch.Tensor:
        return state[index]

    def reference_parameters(self) -> list[nn.Parameter]:
        """None: PPO-RNN and PPO-Steve's planner have no KL reference."""
        return []

    def _unroll(
        self, x: torch.Tensor, first: torch.Tensor, h: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        n, t = first.shape
        features = self.encoder(x.flatten(0, 1)).view(n, t, -1)
        outs = []
        for k in range(t):
            h = self.gru(features[:, k], h * (~first[:, k]).to(h.dtype).unsqueeze(1))
            outs.append(h)
        return torch.stack(outs, 1), h

    def step(self, x: torch.Tensor, first: torch.Tensor, state: torch.Tensor) -> StepOut:
        out, h = self._unroll(x.unsqueeze(1), first.unsqueeze(1), state)
        return StepOut(self.policy(out[:, 0]), self.value(out[:, 0]).squeeze(-1), h)

    def evaluate(
        self, x: torch.Tensor, first: torch.Tensor, state: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        out, _ = self._unroll(x, first, state)
        return self.policy(out), self.value(out).squeeze(-1)


def _select_trxl(state: TrXLState, index: torch.Tensor) -> TrXLState:
    return TrXLState(state.memory[:, index], state.blocked[index])


class CVPTRLPolicy(nn.Module):
    """C-VPT fine-tuned by PPO through LoRA on its Transformer-XL (plus a value head)."""

    def __init__(
        self,
        cvpt: CVPTModel,
        lora_rank: int,
        lora_alpha: float,
        lora_targets: list[str] | tuple[str, ...] = ("query", "key_value", "out", "ff.0", "ff.3"),
    ) -> None:
        super().__init__()
        self.encoder = cvpt.encoder
        self.reference_trxl = copy.deepcopy(cvpt.trxl)
        self.reference_head = copy.deepcopy(cvpt.policy_head)
        self.trxl = cvpt.trxl
        self.policy_head = cvpt.policy_head
        inject_adapter_in_model(
            LoraConfig(r=lora_rank, lora_alpha=lora_alpha, target_modules=list(lora_targets)),
            self.trxl,
        )
        self.value = nn.Linear(cvpt.config.d_model, 1)
        nn.init.zeros_(self.value.weight)
        nn.init.zeros_(self.value.bias)
        for name, param in self.named_parameters():
            param.requires_grad_("lora_" in name or name.startswith("value."))
        self.frame_size = cvpt.config.frame_size

    @torch.no_grad()
    def preprocess(self, obs: np.ndarray) -> torch.Tensor:
        """Frozen encoder features (N, d_model): the update reruns only the Transformer-XL."""
        frames = torch.tensor(np.asarray(obs), device=self.value.weight.device)
        return self.encoder(frames.permute(0, 3, 1, 2))

    def initial_state(self, n: int) -> tuple[TrXLState, TrXLState]:
        device = self.value.weight.device
        return self.trxl.initial_state(n, device), self.reference_trxl.initial_state(n, device)

    def select_state(self, state: tuple[TrXLState, TrXLState], index: torch.Tensor):
        return tuple(_select_trxl(s, index) for s in state)

    def reference_parameters(self) -> list[nn.Parameter]:
        """The frozen pretrained Transformer-XL and head copies: they give the KL term's
        reference logits but never choose an action."""
        return [*self.reference_trxl.parameters(), *self.reference_head.parameters()]

    def step(self, x: torch.Tensor, first: torch.Tensor, state) -> StepOut:
        x, first = x.unsqueeze(1), first.unsqueeze(1)
        hidden, own = self.trxl(x, first, state[0])
        ref_hidden, ref = self.reference_trxl(x, first, state[1])
        return StepOut(
            self.policy_head(hidden[:, 0]),
            self.value(hidden[:, 0]).squeeze(-1),
            (own, ref),
            self.reference_head(ref_hidden[:, 0]),
        )

    def evaluate(self, x: torch.Tensor, first: torch.Tensor, state):
        hidden, _ = self.trxl(x, first, state[0])
        return self.policy_head(hidden), self.value(hidden).squeeze(-1)


class ParameterCounts(NamedTuple):
    """A policy's sizes; the share PPO trains is ``trainable / acting``."""

    trainable: int
    acting: int  # the policy that acts (with its value head): trainable and frozen parts
    reference: int  # frozen copies only the KL term reads (C-VPT-RL), outside ``acting``


def count_parameters(policy: RecurrentActorCritic | CVPTRLPolicy) -> ParameterCounts:
    """Trainable and acting-policy parameter counts, and the KL reference's size apart."""
    reference = policy.reference_parameters()
    skip = {id(p) for p in reference}
    acting = [p for p in policy.parameters() if id(p) not in skip]
    return ParameterCounts(
        sum(p.numel() for p in acting if p.requires_grad),
        sum(p.numel() for p in acting),
        sum(p.numel() for p in reference),
    )
