"""``TaskEnv``: a game env playing one task (edited start, progress, end on success)."""

from __future__ import annotations

import numpy as np

from zoo.envs.base import GameEnv, Step
from zoo.envs.tasks.editors import make_editor
from zoo.envs.tasks.progress import TaskProgress
from zoo.envs.tasks.specs import TaskSpec, get_task


class TaskEnv:
    """``env`` playing ``task``: the starting inventory after each reset, and (peaceful
    tasks) no mobs and full vitals after every step. Same interface as ``GameEnv``.

    ``progress`` tracks each env's ordered sub-tasks; with ``end_on_success`` an env reports
    ``done`` on the step its last sub-task completes (the episode has nothing left to score).
    ``seeds[i]`` is the seed env i was last reset with, so results can be matched to slots.
    ``completed[i]`` says whether env i's last step completed its current sub-task (the
    sparse, ordered task reward of the RL agents).
    The step limit is the wrapped env's own; ``make_task_env`` builds one with the task's.
    """

    def __init__(self, env: GameEnv, task: TaskSpec, end_on_success: bool = True) -> None:
        self._editor = make_editor(env, task)
        self.env, self.task = env, task
        self.num_envs, self.name = env.num_envs, env.name
        self.end_on_success = end_on_success
        self.progress = TaskProgress(task, env.num_envs)
        self.seeds = np.zeros(env.num_envs, np.int64)
        self.completed = np.zeros(env.num_envs, bool)
        self._last: Step | None = None

    @property
    def raw_state(self):
        return getattr(self.env, "raw_state", None)

    def reset(self, seeds: np.ndarray, mask: np.ndarray | None = None) -> Step:
        mask = np.ones(self.num_envs, bool) if mask is None else np.asarray(mask, bool)
        step = writable_step(self.env.reset(seeds, mask))
        if self._last is None:  # the env may hold other edits: export what its games hold
            self._editor.edit(step, ~mask, inventory=False)
        else:  # rows not reset keep what this wrapper last showed
            for k, v in step.state.items():
                v[~mask] = self._last.state[k][~mask]
            if step.frames is not None and self._last.frames is not None:
                step.frames[~mask] = self._last.frames[~mask]
        self._editor.edit(step, mask, inventory=True)
        self.seeds[mask] = np.asarray(seeds)[mask]
        self.progress.reset(step.state, mask)
        self._last = step
        return step

    def step(self, actions: np.ndarray) -> Step:
        step = writable_step(self.env.step(actions))
        if self.task.peaceful:
            self._editor.edit(step, np.ones(self.num_envs, bool), inventory=False)
        self.completed = self.progress.update(step.state)
        if self.end_on_success:
            step.done = step.done | self.progress.success
        self._last = step
        return step


def writable_step(step: Step) -> Step:
    """Own copies of the arrays (Craftax hands back read-only views of device buffers)."""
    step.state = {k: np.array(v) for k, v in step.state.items()}
    step.frames = None if step.frames is None else np.array(step.frames)
    return step


def make_task_env(
    task: TaskSpec | str,
    env_name: str,
    num_envs: int = 1,
    pixels: bool = True,
    max_steps: int | None = None,
) -> TaskEnv:
    """``num_envs`` envs of game ``env_name`` playing ``task`` (step limit: the task's)."""
    from zoo.envs import make_env

    task = get_task(task) if isinstance(task, str) else task
    env = make_env(env_name, num_envs, pixels=pixels, max_steps=max_steps or task.max_steps)
    return TaskEnv(env, task)
