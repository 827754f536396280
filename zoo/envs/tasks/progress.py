"""Ordered sub-task progress of N envs, from the states they pass through."""

from __future__ import annotations

import numpy as np

from zoo.envs.schema import State
from zoo.envs.tasks.events import achievement_events
from zoo.envs.tasks.specs import TaskSpec


class TaskProgress:
    """Ordered sub-task completion of N envs playing one task, fed one state per step.

    ``done_at[i, k]`` is the step (1-based, steps since reset) at which env i completed
    sub-task k, -1 if not yet; ``next[i]`` is the index of its current sub-task.
    """

    def __init__(self, task: TaskSpec, num_envs: int) -> None:
        self.task = task
        self.num_envs = num_envs
        self.done_at = np.full((num_envs, len(task.subtasks)), -1, np.int64)
        self.next = np.zeros(num_envs, np.int64)
        self.steps = np.zeros(num_envs, np.int64)
        self._targets = np.array([int(s.achievement) for s in task.subtasks])
        self._prev: State | None = None

    def reset(self, state: State, mask: np.ndarray | None = None) -> None:
        """Start over in envs where ``mask`` (all if None) from their reset ``state``."""
        mask = np.ones(self.num_envs, bool) if mask is None else np.asarray(mask, bool)
        self.done_at[mask] = -1
        self.next[mask] = 0
        self.steps[mask] = 0
        if self._prev is None:
            self._prev = {k: v.copy() for k, v in state.items()}
        else:
            for k, v in state.items():
                self._prev[k][mask] = v[mask]

    def update(self, state: State) -> np.ndarray:
        """Read the state after one step of every env; returns (N,) bool: sub-task completed."""
        if self._prev is None:
            raise RuntimeError("TaskProgress.update called before reset")
        self.steps += 1
        events = achievement_events(self._prev, state)
        completed = np.zeros(self.num_envs, bool)
        active = np.flatnonzero(self.next < len(self._targets))
        hit = events[active, self._targets[self.next[active]]]
        for i in active[hit]:
            self.done_at[i, self.next[i]] = self.steps[i]
            self.next[i] += 1
            completed[i] = True
        self._prev = {k: v.copy() for k, v in state.items()}
        return completed

    @property
    def success(self) -> np.ndarray:
        """(N,) bool: every sub-task done, in order."""
        return self.next >= len(self._targets)

    def current_instructions(self) -> list[str | None]:
        """Each env's current sub-task caption (None once the task is done)."""
        subs = self.task.subtasks
        return [subs[k].instruction if k < len(subs) else None for k in self.next]


# --- the env wrapper ------------------------------------------------------------------------
