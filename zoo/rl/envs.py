"""What PPO steps: task envs with automatic resets and the task reward, and PPO-Steve's
planner env where one action is a caption that C-Steve-1 follows for ``option_steps`` steps.

Both hand out ``obs``, ``reward`` (N,), ``done`` (N,) and ``first`` (N,) (the observation
starts a new episode); finished episodes are reported as ``EpisodeStats``. Episode k of a run
is seeded ``episode_seed(seed, k)``, k counted in the order envs finish (lowest index first),
so a run is a function of its config and the counter survives a resume.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import torch

from zoo.envs.base import episode_seed
from zoo.envs.tasks import TaskEnv, make_task_env
from zoo.models.sampling import sample_actions


@dataclass
class EpisodeStats:
    """One finished episode: did every sub-task finish in order, how many did, its length."""

    success: bool
    subtasks_done: int
    length: int
    episode: int


@dataclass
class Transition:
    obs: np.ndarray | torch.Tensor
    reward: np.ndarray
    done: np.ndarray
    first: np.ndarray
    env_steps: int
    finished: list[EpisodeStats]
    model_seconds: float = 0.0
    """Time spent in networks inside the env (PPO-Steve's C-Steve-1), for the time split."""


class TaskVecEnv:
    """N envs of one task; +``reward_per_subtask`` for each sub-task done in order, nothing
    else (the paper: "rewards are given only upon completion of the sub-tasks in the correct
    order"); an env is reset on the step its episode ends."""

    def __init__(
        self, env: TaskEnv, seed: int, next_episode: int = 0, reward_per_subtask: float = 1.0
    ) -> None:
        self.env = env
        self.num_envs, self.seed = env.num_envs, seed
        self.next_episode = next_episode
        self.reward_per_subtask = reward_per_subtask
        self._episode = np.zeros(self.num_envs, np.int64)
        self._length = np.zeros(self.num_envs, np.int64)

    @classmethod
    def make(
        cls, task: str, env_name: str, num_envs: int, seed: int, next_episode: int = 0
    ) -> TaskVecEnv:
        """``num_envs`` pixel envs of game ``env_name`` playing ``task``."""
        return cls(make_task_env(task, env_name, num_envs, pixels=True), seed, next_episode)

    def _seeds(self, mask: np.ndarray) -> np.ndarray:
        seeds = np.zeros(self.num_envs, np.int64)
        for i in np.flatnonzero(mask):
            self._episode[i] = self.next_episode
            seeds[i] = episode_seed(self.seed, self.next_episode)
            self.next_episode += 1
        return seeds

    def reset(self) -> Transition:
        every = np.ones(self.num_envs, bool)
        step = self.env.reset(self._seeds(every), every)
        self._length[:] = 0
        zeros = np.zeros(self.num_envs, np.float32)
        return Transition(step.frames, zeros, ~every, every, 0, [])

    def step(self, actions: np.ndarray) -> Transition:
        step = self.env.step(np.asarray(actions, np.int32))
        reward = self.env.completed.astype(np.float32) * self.reward_per_subtask
        done = np.asarray(step.done, bool).copy()
        self._length += 1
        finished = [
            EpisodeStats(
                bool(self.env.progress.success[i]),
                int(self.env.progress.next[i]),
                int(self._length[i]),
                int(self._episode[i]),
            )
            for i in np.flatnonzero(done)
        ]
        frames = step.frames
        if done.any():
            frames = self.env.reset(self._seeds(done), done).frames
            self._length[done] = 0
        return Transition(frames, reward, done, done.copy(), self.num_envs, finished)


class CaptionExecutor:
    """Frozen C-Steve-1 (with classifier-free guidance) following one caption per env, a step at
    a time, and its goal-free Transformer-XL feature of the current frame (the planner's view).

    With head conditioning (the paper's) the goal enters after that feature, so one backbone
    pass per step serves both the planner's observation and the guided action.
    """

    def __init__(self, steve, goals: torch.Tensor) -> None:
        if not steve.model.config.goal_after_trxl:
            raise ValueError(
                "PPO-Steve reads C-Steve-1's goal-free feature, which needs head or FiLM "
                f"conditioning (the paper's: head); this checkpoint uses {steve.conditioning!r}"
            )
        if goals.ndim != 2 or goals.shape[1] != steve.goal_dim:
            raise ValueError(
                f"goals must be (num_captions, {steve.goal_dim}), got {tuple(goals.shape)}"
            )
        self.steve, self.goals = steve, goals.to(steve.device)
        self.hidden: torch.Tensor | None = None
        self._state = None

    @property
    def feature_dim(self) -> int:
        return self.steve.feature_dim

    def reset(self, n: int) -> None:
        """Empty memory for ``n`` envs."""
        self._state = self.steve.feature_state(n)

    @torch.no_grad()
    def observe(self, frames: np.ndarray, first: np.ndarray) -> torch.Tensor:
        """Feed the current frames (``first`` marks episode starts); the features (N, d_model)."""
        self.hidden, self._state = self.steve.features(frames, first, self._state)
        return self.hidden

    @torch.no_grad()
    def logits(self, captions: np.ndarray) -> torch.Tensor:
        """Guided action logits (N, A) at the last observed frames, towards caption ids (N,)."""
        goal = self.goals[torch.as_tensor(np.asarray(captions), device=self.goals.device)]
        return self.steve.logits_from_features(self.hidden, goal)


def planner_observation(hidden: torch.Tensor, last_choice: np.ndarray, num_captions: int):
    """The planner's input: the executor's feature and a one-hot of the caption chosen last
    (zeros where ``last_choice`` is -1: nothing chosen yet this episode)."""
    one_hot = torch.zeros(len(last_choice), num_captions)
    chosen = last_choice >= 0
    one_hot[np.flatnonzero(chosen), last_choice[chosen]] = 1.0
    return torch.cat([hidden.float().cpu(), one_hot], dim=1)


class PlannerEnv:
    """PPO-Steve's high level: an action is one of the caption ids, C-Steve-1 (frozen, with
    classifier-free guidance) follows that caption for ``option_steps`` env steps.

    Observation (the paper does not give the planner's; our choice): C-Steve-1's own
    goal-free Transformer-XL feature of the current frame (its history-aware summary of the
    pixels, learned from play data, frozen) concatenated with a one-hot of the caption the
    planner chose last (zeros at an episode start). It costs no extra forward pass (head
    conditioning adds the goal after this feature) and gives the planner nothing the pixel
    agents lack: no game state, no task progress.

    An env whose episode ends inside an option is reset at once and plays noop until the
    option ends, so every planner step is ``option_steps`` steps of every env (counted).
    """

    def __init__(
        self,
        tasks: TaskVecEnv,
        steve,
        goals: torch.Tensor,
        option_steps: int,
        seed: int,
    ) -> None:
        self.executor = CaptionExecutor(steve, goals)
        self.tasks = tasks
        self.num_envs, self.option_steps = tasks.num_envs, option_steps
        self.num_actions = len(goals)
        self._generator = torch.Generator().manual_seed(seed)
        self._last_choice = np.full(self.num_envs, -1)

    @property
    def next_episode(self) -> int:
        """The episode counter of the task envs underneath (what a checkpoint keeps)."""
        return self.tasks.next_episode

    @property
    def obs_dim(self) -> int:
        return self.executor.feature_dim + self.num_actions

    def _observation(self, first: np.ndarray) -> torch.Tensor:
        self._last_choice[first] = -1
        return planner_observation(self.executor.hidden, self._last_choice, self.num_actions)

    def reset(self) -> Transition:
        t = self.tasks.reset()
        self.executor.reset(self.num_envs)
        self.executor.observe(t.obs, t.first)
        return Transition(self._observation(t.first), t.reward, t.done, t.first, 0, [])

    @torch.no_grad()
    def step(self, captions: np.ndarray) -> Transition:
        captions = np.asarray(captions)
        reward = np.zeros(self.num_envs, np.float32)
        waiting = np.zeros(self.num_envs, bool)
        finished: list[EpisodeStats] = []
        env_steps, began, env_seconds = 0, time.perf_counter(), 0.0
        for _ in range(self.option_steps):
            actions = sample_actions(self.executor.logits(captions), generator=self._generator)
            actions[waiting] = 0  # noop until the option ends
            tick = time.perf_counter()
            t = self.tasks.step(actions)
            env_seconds += time.perf_counter() - tick
            reward += np.where(waiting, 0.0, t.reward)
            waiting |= t.done
            finished += t.finished
            env_steps += t.env_steps
            self.executor.observe(t.obs, t.first)
        self._last_choice = np.where(waiting, -1, captions)
        return Transition(
            self._observation(waiting), reward, waiting.copy(), waiting.copy(), env_steps, finished,
            time.perf_counter() - began - env_seconds,
        )
