"""Play a ``zoo rl train`` checkpoint (PPO-RNN, C-VPT-RL, PPO-Steve) as an ``Agent``, so
``zoo eval`` scores it on the same fixed episode seeds as every other agent.

The training log's success rates come from the run's own rollouts (other seeds, a policy that
changes while they run); this is the held-out number to put in a table.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from zoo.agents.base import EpisodeStreams
from zoo.models.sampling import sample_actions
from zoo.envs.base import Step
from zoo.rl.envs import CaptionExecutor, planner_observation
from zoo.weights.checkpoint_io import CheckpointError, read_torch_file


def find_rl_checkpoint(path: str | Path) -> Path:
    """``path`` itself (an ``update_*.pt``), or the newest checkpoint of a run folder."""
    path = Path(path)
    if path.is_dir():
        found = sorted((path / "checkpoints").glob("update_*.pt"))
        if not found:
            raise ValueError(f"{path} holds no checkpoints/update_*.pt of a `zoo rl train` run")
        return found[-1]
    return path


def load_rl_agent(path: str | Path, num_envs: int, temperature: float = 1.0, greedy: bool = False):
    """The agent of an ``update_*.pt`` or a run folder (its newest checkpoint): ``RLAgent`` for
    PPO-RNN and C-VPT-RL, ``PlannerAgent`` for PPO-Steve."""
    from zoo.rl.agents import build_pixel_policy, load_executor, planner_network
    from zoo.rl.config import RLConfig
    from zoo.rl.train import base_sha256, load_trainable

    path = find_rl_checkpoint(path)
    saved = read_torch_file(path, expected="a `zoo rl train` checkpoint (update_*.pt)")
    if not {"config", "trainable"} <= saved.keys():
        raise CheckpointError(f"{path} is not a `zoo rl train` checkpoint (no config/trainable)")
    config = RLConfig.from_dict(saved["config"], source=str(path))
    base = base_sha256(config)
    if config.agent != "ppo_steve":
        policy = build_pixel_policy(config)
        load_trainable(policy, saved, path, base)
        return RLAgent(policy, config.agent, num_envs, temperature, greedy)
    executor = CaptionExecutor(*load_executor(config))
    goals = len(executor.goals)
    planner = planner_network(executor.feature_dim + goals, config.hidden_size, goals)
    load_trainable(planner, saved, path, base)
    return PlannerAgent(planner, executor, config.option_steps, num_envs, temperature, greedy)


def _check_temperature(temperature: float) -> None:
    if temperature <= 0:
        raise ValueError(f"temperature must be > 0, got {temperature}")


class RLAgent:
    """A trained PPO policy for N envs; samples softmax(logits / temperature) from each env's
    seeded stream (or plays the argmax when ``greedy``), carries its recurrent state and
    resets it where an episode starts."""

    needs_pixels = True

    def __init__(self, policy, name: str, num_envs: int, temperature: float = 1.0,
                 greedy: bool = False) -> None:
        _check_temperature(temperature)
        self.policy = policy.eval()
        self.name, self.num_envs = name, num_envs
        self.temperature, self.greedy = temperature, greedy
        self._state = policy.initial_state(num_envs)
        self._episodes = EpisodeStreams(num_envs)

    def reset(self, seeds: np.ndarray, mask: np.ndarray | None = None) -> None:
        self._episodes.reset(seeds, mask)

    @torch.no_grad()
    def act(self, step: Step) -> np.ndarray:
        if step.frames is None:
            raise ValueError("RLAgent plays from pixels: make the env with pixels=True")
        x = self.policy.preprocess(step.frames)
        episodes = self._episodes
        out = self.policy.step(x, torch.as_tensor(episodes.first), self._state)
        self._state = out.state
        episodes.stepped()
        actions = sample_actions(out.logits, self.temperature, self.greedy, episodes.uniforms())
        return actions.astype(np.int32)


class PlannerAgent:
    """PPO-Steve as a fixed agent: every ``option_steps`` steps of an env (and at its episode
    start) the planner picks a caption from C-Steve-1's feature and the caption it picked last,
    and C-Steve-1 follows it. Unlike training's ``PlannerEnv``, a new episode starts a new option
    at once (no noop wait for the old option to run out). Both the caption and the action are
    sampled from each env's seeded stream; ``temperature`` scales the action logits only (the
    caption is drawn as in training)."""

    name = "ppo_steve"
    needs_pixels = True

    def __init__(self, planner, executor, option_steps: int, num_envs: int,
                 temperature: float = 1.0, greedy: bool = False) -> None:
        _check_temperature(temperature)
        self.planner, self.executor = planner.eval(), executor
        self.option_steps, self.num_envs = option_steps, num_envs
        self.temperature, self.greedy = temperature, greedy
        self.num_captions = len(executor.goals)
        executor.reset(num_envs)
        self._planner_state = planner.initial_state(num_envs)
        self._episodes = EpisodeStreams(num_envs)
        self._clock = np.zeros(num_envs, np.int64)
        self.choice = np.full(num_envs, -1)

    def reset(self, seeds: np.ndarray, mask: np.ndarray | None = None) -> None:
        envs = self._episodes.reset(seeds, mask)
        self._clock[envs], self.choice[envs] = 0, -1

    @torch.no_grad()
    def act(self, step: Step) -> np.ndarray:
        if step.frames is None:
            raise ValueError("PlannerAgent plays from pixels: make the env with pixels=True")
        episodes = self._episodes
        hidden = self.executor.observe(step.frames, episodes.first)
        due = np.flatnonzero(self._clock % self.option_steps == 0)
        if len(due):
            index = torch.as_tensor(due)
            obs = planner_observation(hidden, self.choice, self.num_captions)[index]
            out = self.planner.step(obs, torch.as_tensor(episodes.first[due]),
                                    self.planner.select_state(self._planner_state, index))
            self._planner_state[index] = out.state
            self.choice[due] = sample_actions(out.logits, 1.0, self.greedy, episodes.uniforms(due))
        logits = self.executor.logits(self.choice)
        actions = sample_actions(logits, self.temperature, self.greedy, episodes.uniforms())
        self._clock += 1
        episodes.stepped()
        return actions.astype(np.int32)
