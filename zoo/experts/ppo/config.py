"""PPO-RNN settings for the Craftax-Classic-Symbolic expert (paper §3.1 and Appendix B).

Values come from the paper's table "Hyperparameters for expert policy training" where it gives
them and from Craftax's ``ppo_rnn.py`` defaults otherwise; each field's docstring says which.
A YAML file must list every field once: a missing or unknown key is an error naming the key
and the file, so a config on disk is always the complete record of a run.
"""

from __future__ import annotations

from dataclasses import dataclass

from zoo.strict_config import StrictConfig


@dataclass(frozen=True)
class PPOConfig(StrictConfig):
    """One PPO-RNN run; frozen (hashable) so compiled training functions can be cached by it."""

    num_envs: int = 4096
    """Parallel Craftax envs (paper table: 4096; Craftax's default is 1024)."""

    num_steps: int = 64
    """Env steps per env per update, the rollout (and GRU truncation) length (paper table: 64)."""

    total_timesteps: int = 1_000_000_000
    """Env steps over the whole run (paper table: 1e9; the paper's text says 10B for its final
    agent). Rounded down to whole updates of ``num_envs * num_steps`` steps."""

    lr: float = 2e-4
    """Adam learning rate (paper table: 2e-4, also Craftax's default)."""

    anneal_lr: bool = True
    """Decay the learning rate linearly to 0 over the run (Craftax's default)."""

    adam_eps: float = 1e-5
    """Adam epsilon (Craftax's default)."""

    gamma: float = 0.99
    """Discount factor (paper table: 0.99)."""

    gae_lambda: float = 0.8
    """GAE lambda (Craftax's default)."""

    clip_eps: float = 0.2
    """PPO ratio clip, also used to clip the value update (Craftax's default)."""

    ent_coef: float = 0.01
    """Entropy bonus coefficient (Craftax's default)."""

    vf_coef: float = 0.5
    """Value loss coefficient (Craftax's default)."""

    max_grad_norm: float = 1.0
    """Global gradient-norm clip (paper table: 1.0)."""

    update_epochs: int = 4
    """Passes over each rollout (paper table "Epochs": 4)."""

    num_minibatches: int = 8
    """Minibatches per epoch, split along the env axis so each keeps whole sequences (paper
    table "Batch Size": 8, which is Craftax's NUM_MINIBATCHES)."""

    layer_size: int = 512
    """Width of the dense layers and of the GRU state (Craftax's default)."""

    death_penalty: float = -10.0
    """Reward added on the step an episode ends by death (health 0 or lava), not at the time
    limit (paper §3.1: keeps the agent surviving after it has unlocked everything)."""

    max_episode_steps: int = 10_000
    """Episode time limit (Crafter's and Craftax-Classic's: 10,000)."""

    updates_per_block: int = 10
    """Updates run inside one jitted call; metrics are logged once per block."""

    checkpoint_every_updates: int = 100
    """Save a checkpoint every this many updates (a multiple of ``updates_per_block``) and at
    the end."""

    keep_checkpoints: int = 3
    """Checkpoints kept in the run directory; older ones are deleted."""

    seed: int = 0
    """Seeds network init, worlds and action sampling."""

    @property
    def batch_size(self) -> int:
        """Env steps collected per update."""
        return self.num_envs * self.num_steps

    @property
    def num_updates(self) -> int:
        return self.total_timesteps // self.batch_size

    def __post_init__(self) -> None:
        positive = (
            "num_envs", "num_steps", "update_epochs", "num_minibatches", "layer_size",
            "max_episode_steps", "updates_per_block", "checkpoint_every_updates",
            "keep_checkpoints",
        )
        for name in positive:
            if getattr(self, name) < 1:
                raise ValueError(f"PPOConfig.{name} must be >= 1, got {getattr(self, name)}")
        if self.num_envs % self.num_minibatches:
            raise ValueError(
                f"PPOConfig.num_envs ({self.num_envs}) must be divisible by num_minibatches "
                f"({self.num_minibatches}): minibatches split the env axis"
            )
        if self.checkpoint_every_updates % self.updates_per_block:
            raise ValueError(
                f"PPOConfig.checkpoint_every_updates ({self.checkpoint_every_updates}) must be a "
                f"multiple of updates_per_block ({self.updates_per_block})"
            )
        if self.num_updates < 1:
            raise ValueError(
                f"PPOConfig.total_timesteps ({self.total_timesteps}) is less than one update "
                f"(num_envs * num_steps = {self.batch_size})"
            )
