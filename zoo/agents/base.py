"""What plays in an env: experts, trained policies and baselines all implement ``Agent``."""

from __future__ import annotations

from typing import Protocol

import numpy as np

from zoo.envs.base import Step
from zoo.envs.constants import NUM_ACTIONS


class Agent(Protocol):
    """Acts for N envs at once; keeps per-env memory (plans, RNN/TrXL state) between calls."""

    name: str
    needs_pixels: bool  # False for agents that read only the state (the env may skip rendering)

    def reset(self, seeds: np.ndarray, mask: np.ndarray | None = None) -> None:
        """Forget env i's memory where ``mask[i]`` (all if None); ``seeds[i]`` seeds its randomness."""
        ...

    def act(self, step: Step) -> np.ndarray:
        """Return one action id per env, int array of shape (N,)."""
        ...


class InstructableAgent(Agent, Protocol):
    """An agent told what to do in words: C-Steve-1, the goal-directed scripted expert."""

    def instruct(self, instructions: list[str | None], mask: np.ndarray | None = None) -> None:
        """Set env i's instruction (a caption text; None: none) where ``mask[i]`` (all if None).

        Raises ValueError naming the known instructions for a text the agent cannot follow.
        """
        ...


class EpisodeStreams:
    """Each env's random stream, seeded by its episode seed, and which envs are at their first
    step: so a sampled episode depends on its seed alone, not on its env slot or batch size."""

    def __init__(self, num_envs: int) -> None:
        self.first = np.ones(num_envs, dtype=bool)
        self._rngs = [np.random.default_rng(0) for _ in range(num_envs)]

    def reset(self, seeds: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
        """Reseed env i from ``seeds[i]`` and mark its first step where ``mask[i]`` (all if None);
        return the indices reset."""
        envs = np.arange(len(self._rngs)) if mask is None else np.flatnonzero(mask)
        for i in envs:
            self._rngs[i] = np.random.default_rng(int(seeds[i]))
            self.first[i] = True
        return envs

    def uniforms(self, envs: np.ndarray | None = None) -> np.ndarray:
        """One U[0, 1) draw from each env's stream (``envs`` only, if given)."""
        rngs = self._rngs if envs is None else [self._rngs[i] for i in envs]
        return np.array([rng.random() for rng in rngs])

    def stepped(self) -> None:
        """Every env has played a step: none is at its first any more."""
        self.first[:] = False


class RandomAgent:
    """Uniform random actions; each env's stream depends only on its episode seed."""

    name = "random"
    needs_pixels = False

    def __init__(self, num_envs: int) -> None:
        self._rngs = [np.random.default_rng(0) for _ in range(num_envs)]

    def reset(self, seeds: np.ndarray, mask: np.ndarray | None = None) -> None:
        for i in range(len(self._rngs)) if mask is None else np.flatnonzero(mask):
            self._rngs[i] = np.random.default_rng(int(seeds[i]))

    def act(self, step: Step) -> np.ndarray:
        return np.array([rng.integers(NUM_ACTIONS) for rng in self._rngs], np.int32)
