"""Episodes that start from the task suites' starting inventories (``zoo data generate
--start-states tasks``), so that one goal is demonstrated from several points of the tech tree.

Each episode draws one of the distinct inventories of ``TASKS`` (the empty one included: a
normal start) uniformly from its seed, and the suites' own editors give it to the player after
the reset; peace (T1) is a task rule, not a start, and is left out.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from zoo.envs.base import GameEnv, Step
from zoo.envs.tasks.editors import make_editor
from zoo.envs.tasks.env import writable_step
from zoo.envs.tasks.specs import TASKS, TaskSpec

START_STATES = ("default", "tasks")
"""``default``: the game's own start; ``tasks``: the task suites' starting inventories."""
_STREAM = 0x57A27  # the start's draw, apart from the env's and the agent's use of the seed


def task_starts() -> tuple[TaskSpec, ...]:
    """One task per distinct starting inventory of the suites, in registry order."""
    starts: dict[tuple, TaskSpec] = {}
    for task in TASKS.values():
        starts.setdefault(tuple(task.inventory_vector().tolist()), replace(task, peaceful=False))
    return tuple(starts.values())


def start_index(seed: int, count: int) -> int:
    """Which of ``count`` starts the episode seeded ``seed`` begins from."""
    return int(np.random.default_rng([int(seed), _STREAM]).integers(count))


class TaskStartEnv:
    """``env`` whose episodes begin with a starting inventory of the task suites (drawn per
    episode from its seed, ``start_index``). Same interface as ``GameEnv``."""

    def __init__(self, env: GameEnv) -> None:
        self.env, self.num_envs, self.name = env, env.num_envs, env.name
        self.starts = task_starts()
        # an empty inventory is the game's own start: nothing to edit
        self._editors = [
            make_editor(env, task) if task.inventory else None for task in self.starts
        ]

    @property
    def raw_state(self):
        return getattr(self.env, "raw_state", None)

    def reset(self, seeds: np.ndarray, mask: np.ndarray | None = None) -> Step:
        mask = np.ones(self.num_envs, bool) if mask is None else np.asarray(mask, bool)
        step = writable_step(self.env.reset(seeds, mask))
        chosen = np.array([start_index(s, len(self.starts)) for s in np.asarray(seeds)])
        for k, editor in enumerate(self._editors):
            if editor is not None and (mask & (chosen == k)).any():
                editor.edit(step, mask & (chosen == k), inventory=True)
        return step

    def step(self, actions: np.ndarray) -> Step:
        return self.env.step(actions)
