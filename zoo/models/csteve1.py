"""C-Steve-1: C-VPT conditioned on a C-CLIP goal embedding (paper §4.3, "Model Architecture").

Head conditioning (the paper's choice, from MrSteve): the goal enters after the Transformer-XL,
x'_t = x_t + W z_t + b, and the policy head reads x'. TrXL-input conditioning (STEVE-1's; the
paper's conditioning ablation) adds W z_t + b to the image features before the Transformer-XL
instead. W and b start at zero and LoRA's B matrices start at zero, so before training
C-Steve-1 is exactly the C-VPT it was built from, whatever the goal.

VPT's policy head has a hidden layer (ReLU, linear + ReLU, LayerNorm, then the action logits), so
a goal added before it changes the action distribution state by state. C-VPT's policy head is
one linear layer unless it was trained with ``CVPTConfig.head_hidden``; over a linear head,
head conditioning is W_head (W z + b): one logit offset per goal, the same in every state (an
action prior, not a plan). ``head_hidden`` > 0 here adds a hidden layer as a trainable residual
block before the frozen head,
x'' = x' + W_2 relu(W_1 LayerNorm(x') + b_1) + b_2 with W_2, b_2 zero at the start, so the
goal's effect can depend on the state and the untrained model is still the backbone.

FiLM conditioning (``film``; beyond the paper) also enters after the Transformer-XL, as a
per-feature scale and shift, x' = x * (1 + G z_t) + W z_t + b, with G zero at the start: over
the linear head the goal's effect is W_head (x * G z), which depends on the state through x,
while the Transformer-XL pass stays goal-free (guidance and PPO-Steve's features as for head).

Both read the goal linearly, so a goal that lies close to a mix of others (two captions whose
prior goals are at cosine 0.8) can only get a mix of their behaviours. ``goal_hidden`` > 0 feeds
the conditioning [z, relu(V z)] instead (V random, no bias, so a zero goal stays zero and the
unconditional policy is unchanged): a goal can then act apart from its neighbours.

Fine-tuning is LoRA on the Transformer-XL's linear layers (``peft``), plus the conditioning
layer (and the head block); the image encoder, the TrXL's base weights, norms and the policy head stay frozen
(``trainable_parameters`` names what trains).

Classifier-free guidance needs the policy without a goal: that is goal = 0 (training drops the
goal of 10% of pieces to zeros), i.e. x' = x + b. With head conditioning the Transformer-XL
never sees the goal, so the conditional and unconditional passes share one TrXL pass and one
memory, and guidance costs a second policy head only; with TrXL-input conditioning both passes
run the TrXL, batched together, each with its own memory (``guided_logits``).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Literal

import torch
from peft import LoraConfig, inject_adapter_in_model
from torch import nn

from zoo.models.cvpt import CVPTModel
from zoo.models.trxl import TrXLState

Conditioning = Literal["head", "trxl_input", "film"]
CONDITIONINGS: tuple[str, ...] = ("head", "trxl_input", "film")
AFTER_TRXL: tuple[str, ...] = ("head", "film")
"""Conditionings whose goal enters after a goal-free Transformer-XL pass."""


@dataclass
class CSteve1Config:
    """What C-Steve-1 adds to its C-VPT backbone."""

    goal_dim: int = 512
    """Width of the goal embedding (the C-CLIP embedding size)."""
    conditioning: Conditioning = "head"
    """``head``: added after the Transformer-XL (the paper's); ``trxl_input``: added before it
    (STEVE-1's); ``film``: a scale and shift after it (state-dependent over a linear head)."""
    head_hidden: int = 0
    """Width of the trainable hidden layer before the frozen linear policy head (0: none; then
    head conditioning is a state-independent logit offset per goal, see the module doc)."""
    goal_hidden: int = 0
    """Width of the goal's nonlinear features relu(V z) fed to the conditioning beside z (0:
    the goal enters linearly)."""
    lora_rank: int = 16
    """Rank of the LoRA updates on the Transformer-XL (0: no LoRA, conditioning only)."""
    lora_alpha: float = 16.0
    """LoRA scale numerator (updates are scaled by alpha / rank)."""
    lora_dropout: float = 0.0
    """Dropout on the LoRA branch's input."""
    lora_targets: list[str] = field(
        default_factory=lambda: ["query", "key_value", "out", "ff.0", "ff.3"]
    )
    """Names (suffixes) of the TrXL linear layers that get LoRA: attention query, key/value,
    output, and both feed-forward layers."""

    def __post_init__(self) -> None:
        if self.conditioning not in CONDITIONINGS:
            raise ValueError(f"conditioning={self.conditioning!r}: expected one of {CONDITIONINGS}")
        if self.goal_dim < 1 or min(self.lora_rank, self.head_hidden, self.goal_hidden) < 0:
            raise ValueError(
                f"goal_dim={self.goal_dim} must be >= 1, lora_rank={self.lora_rank}, "
                f"head_hidden={self.head_hidden} and goal_hidden={self.goal_hidden} >= 0"
            )

    @property
    def goal_after_trxl(self) -> bool:
        """The Transformer-XL never sees the goal: guidance shares its pass, and its features
        are goal-free (PPO-Steve's planner reads them)."""
        return self.conditioning in AFTER_TRXL

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_hparams(cls, hparams: dict) -> CSteve1Config:
        """The config of a C-Steve-1 training run from its hyper-parameters (None: default)."""
        names = (
            "goal_dim",
            "conditioning",
            "head_hidden",
            "goal_hidden",
            "lora_rank",
            "lora_alpha",
            "lora_dropout",
            "lora_targets",
        )
        values = {name: hparams[name] for name in names if hparams.get(name) is not None}
        if "lora_targets" in values:
            values["lora_targets"] = list(values["lora_targets"])
        return cls(**values)


class CSteve1Model(nn.Module):
    """A C-VPT network with goal conditioning and LoRA; plain torch (played without Lightning)."""

    def __init__(self, backbone: CVPTModel, config: CSteve1Config) -> None:
        super().__init__()
        self.config = config
        self.backbone = backbone
        self.cvpt_config = backbone.config
        self.goal_net = None
        if config.goal_hidden > 0:  # default (random) init: relu(V z) is nonzero from the start
            self.goal_net = nn.Sequential(
                nn.Linear(config.goal_dim, config.goal_hidden, bias=False), nn.ReLU()
            )
        width = config.goal_dim + config.goal_hidden
        self.condition = nn.Linear(width, backbone.config.d_model)
        nn.init.zeros_(self.condition.weight)
        nn.init.zeros_(self.condition.bias)
        self.film_scale = None
        if config.conditioning == "film":
            self.film_scale = nn.Linear(width, backbone.config.d_model, bias=False)
            nn.init.zeros_(self.film_scale.weight)
        self.head_block = _head_block(backbone.config.d_model, config.head_hidden)
        if config.lora_rank > 0:
            lora = LoraConfig(
                r=config.lora_rank,
                lora_alpha=config.lora_alpha,
                lora_dropout=config.lora_dropout,
                target_modules=list(config.lora_targets),
            )
            inject_adapter_in_model(lora, backbone.trxl)
        for name, param in self.named_parameters():
            trains = name.startswith(_TRAINED) or "lora_" in name
            param.requires_grad_(trains)

    def trainable_parameters(self) -> dict[str, nn.Parameter]:
        """The LoRA, conditioning and head-block parameters: all that fine-tuning changes."""
        return {name: p for name, p in self.named_parameters() if p.requires_grad}

    def initial_state(self, batch: int, device: torch.device | str | None = None) -> TrXLState:
        return self.backbone.initial_state(batch, device)

    def _goal_features(self, goal: torch.Tensor, like: torch.Tensor) -> torch.Tensor:
        """What the conditioning reads: z, or [z, relu(V z)] with ``goal_hidden``."""
        expected = (*like.shape[:2], self.config.goal_dim)
        if tuple(goal.shape) != expected:
            raise ValueError(
                f"goal must have shape {expected} (batch, time, goal_dim), got {tuple(goal.shape)}"
            )
        goal = goal.to(self.condition.weight.dtype)
        return goal if self.goal_net is None else torch.cat([goal, self.goal_net(goal)], -1)

    def _goal_term(self, goal: torch.Tensor, like: torch.Tensor) -> torch.Tensor:
        return self.condition(self._goal_features(goal, like)).to(like.dtype)

    def _after_trxl(self, hidden: torch.Tensor, goal: torch.Tensor) -> torch.Tensor:
        """Goal-conditioned features from goal-free TrXL features (head or FiLM)."""
        if self.film_scale is None:
            return hidden + self._goal_term(goal, hidden)
        features = self._goal_features(goal, hidden)
        shift = self.condition(features).to(hidden.dtype)
        return hidden + shift + hidden * self.film_scale(features).to(hidden.dtype)

    def forward(
        self, frames: torch.Tensor, first: torch.Tensor, goal: torch.Tensor, state: TrXLState
    ) -> tuple[torch.Tensor, TrXLState]:
        """Action logits (B, T, A) given frames (B, T, S, S, 3) uint8, first (B, T) and goal
        (B, T, goal_dim) (zeros: no goal), and the state after the segment."""
        x = self.backbone.encode_frames(frames)
        if self.config.conditioning == "trxl_input":
            x = x + self._goal_term(goal, x)
        hidden, state = self.backbone.trxl(x, first.bool(), state)
        if self.config.goal_after_trxl:
            hidden = self._after_trxl(hidden, goal)
        return self.head(hidden), state

    def head(self, hidden: torch.Tensor) -> torch.Tensor:
        """Action logits from (conditioned) TrXL features: the head block, then C-VPT's head."""
        if self.head_block is not None:
            hidden = hidden + self.head_block(hidden)
        return self.backbone.policy_head(hidden)

    def guided_logits(
        self,
        frames: torch.Tensor,
        first: torch.Tensor,
        goal: torch.Tensor,
        state: TrXLState,
        scale: float,
    ) -> tuple[torch.Tensor, TrXLState]:
        """Classifier-free guidance: (1 + scale) * cond - scale * uncond logits, one forward.

        ``state`` is the TrXL state of the batch (B envs) for head or FiLM conditioning, and of the
        doubled batch (B conditional, then B unconditional rows) for TrXL-input conditioning:
        ``guidance_state`` makes the right one.
        """
        if self.config.goal_after_trxl:
            hidden, state = self.backbone.features(frames, first, state)
            return self.guided_head(hidden, goal, scale), state
        x = self.backbone.encode_frames(frames)
        x = torch.cat([x + self._goal_term(goal, x), x + self._goal_term(torch.zeros_like(goal), x)])
        hidden, state = self.backbone.trxl(x, torch.cat([first, first]).bool(), state)
        cond, uncond = self.head(hidden).chunk(2)
        return combine_guidance(cond, uncond, scale), state

    def guided_head(self, hidden: torch.Tensor, goal: torch.Tensor, scale: float) -> torch.Tensor:
        """Guided logits (B, T, A) from goal-free TrXL features (B, T, d) and goals (B, T, D)
        (head or FiLM conditioning): the goal only enters here, so a caller that needs the
        features too (PPO-Steve's planner) runs the Transformer-XL once."""
        if not self.config.goal_after_trxl:
            raise ValueError("guided_head needs head or FiLM conditioning; use guided_logits")
        cond = self.head(self._after_trxl(hidden, goal))
        uncond = self.head(self._after_trxl(hidden, torch.zeros_like(goal)))
        return combine_guidance(cond, uncond, scale)

    def guidance_state(self, batch: int, device: torch.device | str | None = None) -> TrXLState:
        """Empty TrXL memory for ``guided_logits`` on ``batch`` envs."""
        rows = batch if self.config.goal_after_trxl else 2 * batch
        return self.initial_state(rows, device)


_TRAINED = ("condition.", "film_scale.", "head_block.", "goal_net.")
"""Parameter name prefixes that fine-tuning trains (besides LoRA's)."""


def _head_block(width: int, hidden: int) -> nn.Sequential | None:
    """LayerNorm -> Linear -> ReLU -> Linear (zero-initialised output), or None for 0."""
    if hidden == 0:
        return None
    block = nn.Sequential(
        nn.LayerNorm(width), nn.Linear(width, hidden), nn.ReLU(), nn.Linear(hidden, width)
    )
    nn.init.zeros_(block[-1].weight)
    nn.init.zeros_(block[-1].bias)
    return block


def combine_guidance(cond: torch.Tensor, uncond: torch.Tensor, scale: float) -> torch.Tensor:
    """The paper's guided logits: (1 + scale) * cond - scale * uncond (scale 0: conditional)."""
    return (1.0 + scale) * cond - scale * uncond


__all__ = ["AFTER_TRXL", "CONDITIONINGS", "Conditioning", "CSteve1Config", "CSteve1Model", "combine_guidance"]
