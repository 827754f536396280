"""The scripted privileged expert: plays from the full game state, never from pixels."""

from __future__ import annotations

from dataclasses import fields

import numpy as np

from zoo.envs.base import Step
from zoo.experts.scripted.config import ExpertConfig
from zoo.experts.scripted.goals import INSTRUCTIONS, EnvPlanner
from zoo.experts.scripted.world import PathCosts, View


class ScriptedExpert:
    """Plans every env's next action from ``step.state`` (map, mobs, inventory, vitals).

    Each env has its own planner and ``np.random.default_rng(seed)`` made in ``reset``, so an
    episode depends only on its seed, never on the batch it runs in. ``instruct`` turns an env
    goal-directed (an InstructableAgent): it then pursues one caption (``INSTRUCTIONS``) and
    only survives besides; ``reset`` returns the env to normal play.

    Args:
        num_envs: envs acted for.
        **tunables: overrides of ``ExpertConfig`` fields (thresholds and distances).
    """

    name = "scripted"
    needs_pixels = False

    def __init__(self, num_envs: int, **tunables) -> None:
        if num_envs < 1:
            raise ValueError(f"num_envs must be >= 1, got {num_envs}")
        known = {f.name for f in fields(ExpertConfig)}
        unknown = sorted(set(tunables) - known)
        if unknown:
            raise ValueError(
                f"unknown ScriptedExpert tunables {unknown}; expected some of {sorted(known)}"
            )
        self.num_envs = num_envs
        self.config = ExpertConfig(**tunables)
        self._costs = PathCosts(
            mine=self.config.mine_cost,
            bridge=self.config.bridge_cost,
            near_zombie=self.config.near_zombie_cost,
        )
        self._planners = [EnvPlanner(i, self.config) for i in range(num_envs)]

    def reset(self, seeds: np.ndarray, mask: np.ndarray | None = None) -> None:
        """Start new episodes (fresh memory and rng from ``seeds[i]``) in envs where ``mask``."""
        seeds = np.asarray(seeds)
        if seeds.shape != (self.num_envs,):
            raise ValueError(f"seeds has shape {seeds.shape}, expected ({self.num_envs},)")
        mask = np.ones(self.num_envs, bool) if mask is None else np.asarray(mask, bool)
        for i in np.flatnonzero(mask):
            self._planners[i] = EnvPlanner(int(seeds[i]), self.config)

    def instruct(self, instructions: list[str | None], mask: np.ndarray | None = None) -> None:
        """Give env i the goal ``instructions[i]`` where ``mask[i]`` (None: normal play)."""
        if len(instructions) != self.num_envs:
            raise ValueError(
                f"got {len(instructions)} instructions, expected {self.num_envs}: one per env"
            )
        unknown = sorted({t for t in instructions if t is not None and t not in INSTRUCTIONS})
        if unknown:
            raise ValueError(
                f"the scripted expert cannot follow {unknown}; known instructions: "
                f"{sorted(INSTRUCTIONS)}"
            )
        mask = np.ones(self.num_envs, bool) if mask is None else np.asarray(mask, bool)
        for i in np.flatnonzero(mask):
            self._planners[i].instruction = instructions[i]

    def act(self, step: Step) -> np.ndarray:
        """One action id per env, from ``step.state`` alone."""
        state = step.state
        n = state["map"].shape[0]
        if n != self.num_envs:
            raise ValueError(f"step.state holds {n} envs, expected {self.num_envs}")
        actions = np.zeros(n, np.int32)
        for i in range(n):
            actions[i] = self._planners[i].act(View(state, i, self._costs))
        return actions
