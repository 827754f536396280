"""Settings of one RL run (``zoo rl train --config configs/rl/<agent>_<task>.yaml``).

One flat, strict config for the three agents (``zoo.strict_config``: every field once, types
checked); fields that only one agent reads say so. PPO values follow cleanrl's and Craftax's
defaults unless noted; the paper gives only C-VPT-RL's LoRA (alpha 16, r 16) and KL weight (0.1).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from zoo.strict_config import StrictConfig

if TYPE_CHECKING:
    from zoo.agents import AgentSpec

AGENTS = ("ppo_rnn", "cvpt_rl", "ppo_steve")
PRETRAINED = {"cvpt_rl": "cvpt", "ppo_steve": "csteve1"}  # the AgentSpec kind each starts from


@dataclass(frozen=True)
class RLConfig(StrictConfig):
    agent: str = "ppo_rnn"
    """``ppo_rnn`` (from scratch, pixels), ``cvpt_rl`` (C-VPT + LoRA + KL) or ``ppo_steve``
    (caption planner over frozen C-Steve-1)."""
    task: str = "T2"
    """A task of ``zoo.envs.tasks`` (T1-T4 or a single-step task)."""
    env: str = "craftax"
    """``craftax`` (batched, fast on CPU) or ``crafter`` (the paper's game for T2-T4)."""
    num_envs: int = 16
    """Parallel envs."""
    num_steps: int = 64
    """Agent steps per env per update (PPO-Steve: planner steps, each ``option_steps`` env
    steps); also the recurrent truncation length."""
    total_env_steps: int = 200_000
    """Env steps of the whole run (rounded down to whole updates)."""
    lr: float = 3e-4
    """Adam learning rate."""
    anneal_lr: bool = True
    """Decay the learning rate linearly to 0 over the run."""
    gamma: float = 0.99
    """Discount (per agent step)."""
    gae_lambda: float = 0.95
    """GAE lambda."""
    clip_eps: float = 0.2
    """Ratio clip, also used for the value update."""
    ent_coef: float = 0.01
    """Entropy bonus."""
    vf_coef: float = 0.5
    """Value loss weight."""
    kl_coef: float = 0.0
    """Weight of KL(pi || frozen pretrained policy) (C-VPT-RL; paper: 0.1)."""
    max_grad_norm: float = 0.5
    """Global gradient-norm clip."""
    update_epochs: int = 4
    """Passes over each rollout."""
    num_minibatches: int = 4
    """Minibatches per epoch, split along the env axis (whole sequences)."""
    hidden_size: int = 256
    """GRU width of PPO-RNN and of PPO-Steve's planner."""
    input_downsample: int = 2
    """PPO-RNN: average-pool the 144-px frames by this factor before the CNN."""
    checkpoint: str | None = None
    """C-VPT (``cvpt_rl``) or C-Steve-1 (``ppo_steve``) checkpoint or export folder."""
    cclip: str | None = None
    """PPO-Steve: the C-CLIP that embeds the 61 captions (C-Steve-1's own; None: the one its
    export records)."""
    prior: str | None = None
    """PPO-Steve: the CVAE prior turning caption embeddings into goals (its mean goal; None:
    the one its export records)."""
    cfg_scale: float | None = None
    """PPO-Steve: C-Steve-1's classifier-free guidance (None: what its export records, else
    the paper's)."""
    option_steps: int = 10
    """PPO-Steve: env steps per chosen caption (paper: 10)."""
    lora_rank: int = 16
    """C-VPT-RL: LoRA rank (paper 16)."""
    lora_alpha: float = 16.0
    """C-VPT-RL: LoRA alpha (paper 16)."""
    checkpoint_every: int = 10
    """Updates between checkpoints (and at the end); the newest 2 are kept."""
    seed: int = 0
    """Seeds the network init, the action sampling and every episode's world."""
    device: str = "cpu"
    """Torch device of the networks; only ``cpu`` for now (the rollout buffers and the
    frozen-feature observations live on the CPU, and no GPU run has checked the rest)."""

    def __post_init__(self) -> None:
        if self.agent not in AGENTS:
            raise ValueError(f"RLConfig.agent={self.agent!r}: expected one of {AGENTS}")
        for name in ("num_envs", "num_steps", "update_epochs", "num_minibatches",
                     "hidden_size", "input_downsample", "option_steps", "checkpoint_every"):
            if getattr(self, name) < 1:
                raise ValueError(f"RLConfig.{name} must be >= 1, got {getattr(self, name)}")
        if self.num_envs % self.num_minibatches:
            raise ValueError(
                f"RLConfig.num_envs ({self.num_envs}) must be divisible by num_minibatches "
                f"({self.num_minibatches}): minibatches split the env axis"
            )
        if self.num_updates < 1:
            raise ValueError(
                f"RLConfig.total_env_steps ({self.total_env_steps}) is less than one update "
                f"({self.env_steps_per_update} env steps)"
            )
        if self.device != "cpu":
            raise ValueError(
                f"RLConfig.device={self.device!r}: zoo rl runs on cpu only so far (its rollout "
                "buffers live on the CPU); set device: cpu"
            )
        needs = {"cvpt_rl": ("checkpoint",), "ppo_steve": ("checkpoint",)}
        missing = [k for k in needs.get(self.agent, ()) if getattr(self, k) is None]
        if missing:
            raise ValueError(f"RLConfig: agent {self.agent!r} needs {missing} set")

    def pretrained(self) -> AgentSpec:
        """The pretrained agent a run starts from (C-VPT-RL: the C-VPT it fine-tunes; PPO-Steve:
        the C-Steve-1 it plans over), described as ``zoo eval`` describes it, so its files and
        goal models pass the same checks (cclip and prior given together, or the export's)."""
        from zoo.agents import AgentSpec

        if self.agent not in PRETRAINED:
            raise ValueError(f"RLConfig.agent={self.agent!r} starts from no pretrained agent")
        return AgentSpec(PRETRAINED[self.agent], self.checkpoint, cfg_scale=self.cfg_scale,
                         cclip=self.cclip, prior=self.prior)

    @property
    def env_steps_per_update(self) -> int:
        per_action = self.option_steps if self.agent == "ppo_steve" else 1
        return self.num_envs * self.num_steps * per_action

    @property
    def num_updates(self) -> int:
        return self.total_env_steps // self.env_steps_per_update
