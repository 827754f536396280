"""What every env in the zoo returns and accepts, so agents run unchanged in either game."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from zoo.envs.constants import NUM_ACTIONS
from zoo.envs.schema import State


@dataclass
class Step:
    """One batched step of N envs.

    ``frames`` is None when the env was made with ``pixels=False`` (experts read ``state``).
    ``reward`` is crafter's: +1 per newly unlocked achievement, +-0.1 per health point.
    ``raw`` is the backend's own state (Craftax's EnvState pytree), for agents that need it.
    """

    frames: np.ndarray | None  # (N, 144, 144, 3) uint8
    state: State  # batched arrays, see zoo.envs.schema
    reward: np.ndarray  # (N,) float32
    done: np.ndarray  # (N,) bool
    raw: Any = None


class GameEnv(Protocol):
    """N envs stepped together; finished envs stay put until ``reset`` is called for them."""

    num_envs: int
    name: str

    def reset(self, seeds: np.ndarray, mask: np.ndarray | None = None) -> Step:
        """Start a new episode from ``seeds[i]`` in every env i where ``mask[i]`` (all if None)."""
        ...

    def step(self, actions: np.ndarray) -> Step:
        """Apply one action per env."""
        ...


def check_actions(actions: np.ndarray, num_envs: int) -> np.ndarray:
    """Validate a batch of action ids with a message that says what was expected."""
    actions = np.asarray(actions)
    if actions.shape != (num_envs,):
        raise ValueError(f"actions has shape {actions.shape}, expected ({num_envs},): one per env")
    if not np.issubdtype(actions.dtype, np.integer):
        raise ValueError(f"actions has dtype {actions.dtype}, expected integer action ids")
    if actions.size and (actions.min() < 0 or actions.max() >= NUM_ACTIONS):
        raise ValueError(f"action ids must lie in [0, {NUM_ACTIONS}), got {actions.tolist()}")
    return actions.astype(np.int32)


def check_seeds(seeds: np.ndarray, num_envs: int) -> np.ndarray:
    """Validate per-env episode seeds."""
    seeds = np.asarray(seeds)
    if seeds.shape != (num_envs,):
        raise ValueError(f"seeds has shape {seeds.shape}, expected ({num_envs},): one per env")
    return seeds.astype(np.int64)


def episode_seed(seed: int, episode: int) -> int:
    """Seed of episode ``episode`` of a run seeded ``seed``, for both env and agent.

    A function of (seed, episode) alone, so datasets and evaluations do not depend on batch
    size, worker count or the order episodes finish in.
    """
    if seed < 0 or episode < 0:
        raise ValueError(f"seed and episode index must be >= 0, got seed={seed}, episode={episode}")
    return int(np.random.SeedSequence([seed, episode]).generate_state(1, np.uint32)[0])
