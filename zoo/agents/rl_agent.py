"""Play a ``zoo rl train`` checkpoint (PPO-RNN, C-VPT-RL) as an ``Agent``, so ``zoo eval`` scores
it on the same fixed episode seeds as every other agent.

The training log's success rates come from the run's own rollouts (other seeds, a policy that
changes while they run); this is the held-out number to put in a table.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from zoo.agents.cvpt_agent import sample_actions
from zoo.envs.base import Step


def find_rl_checkpoint(path: str | Path) -> Path:
    """``path`` itself (an ``update_*.pt``), or the newest checkpoint of a run folder."""
    path = Path(path)
    if path.is_dir():
        found = sorted((path / "checkpoints").glob("update_*.pt"))
        if not found:
            raise ValueError(f"{path} holds no checkpoints/update_*.pt of a `zoo rl train` run")
        return found[-1]
    return path


def is_rl_checkpoint(path: str | Path) -> bool:
    path = Path(path)
    if path.is_dir():
        return (path / "config.yaml").is_file() and any((path / "checkpoints").glob("update_*.pt"))
    return path.is_file() and path.suffix == ".pt" and path.name.startswith("update_")


class RLAgent:
    """A trained PPO policy for N envs; samples softmax(logits / temperature) from each env's
    seeded stream (or plays the argmax when ``greedy``), carries its recurrent state and
    resets it where an episode starts."""

    needs_pixels = True

    def __init__(self, policy, name: str, num_envs: int, temperature: float = 1.0,
                 greedy: bool = False) -> None:
        if temperature <= 0:
            raise ValueError(f"temperature must be > 0, got {temperature}")
        self.policy = policy.eval()
        self.name, self.num_envs = name, num_envs
        self.temperature, self.greedy = temperature, greedy
        self._state = policy.initial_state(num_envs)
        self._first = np.ones(num_envs, dtype=bool)
        self._rngs = [np.random.default_rng(0) for _ in range(num_envs)]

    @classmethod
    def load(cls, path: str | Path, num_envs: int, **kwargs) -> RLAgent:
        """From an ``update_*.pt`` or a run folder (its newest checkpoint)."""
        from zoo.rl.agents import build_pixel_policy
        from zoo.rl.config import RLConfig
        from zoo.rl.train import base_sha256, load_trainable

        path = find_rl_checkpoint(path)
        saved = torch.load(path, map_location="cpu", weights_only=False)
        if not isinstance(saved, dict) or not {"config", "trainable"} <= saved.keys():
            raise ValueError(f"{path} is not a `zoo rl train` checkpoint (no config/trainable)")
        config = RLConfig.from_dict(saved["config"], source=str(path))
        policy = build_pixel_policy(config)
        load_trainable(policy, saved, path, base_sha256(config))
        return cls(policy, config.agent, num_envs, **kwargs)

    def reset(self, seeds: np.ndarray, mask: np.ndarray | None = None) -> None:
        for i in range(self.num_envs) if mask is None else np.flatnonzero(mask):
            self._rngs[i] = np.random.default_rng(int(seeds[i]))
            self._first[i] = True

    @torch.no_grad()
    def act(self, step: Step) -> np.ndarray:
        if step.frames is None:
            raise ValueError("RLAgent plays from pixels: make the env with pixels=True")
        x = self.policy.preprocess(step.frames)
        out = self.policy.step(x, torch.as_tensor(self._first), self._state)
        self._state, self._first[:] = out.state, False
        uniforms = np.array([rng.random() for rng in self._rngs])
        actions = sample_actions(out.logits, self.temperature, self.greedy, uniforms)
        return actions.astype(np.int32)
