"""Play a trained C-VPT: a plain policy API with cached TrXL memory, and an ``Agent`` on top."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from zoo.agents.base import EpisodeStreams
from zoo.envs.base import Step
from zoo.models.cvpt import CVPTModel
from zoo.models.sampling import sample_actions
from zoo.models.trxl import TrXLState
from zoo.weights import load_model


class CVPTPolicy:
    """Steps N envs one frame at a time; the state is a rolling memory of the last M steps.

    One call costs one frame through the encoder and one query per layer against the memory,
    and gives the same logits as running the model on the whole history.
    """

    def __init__(
        self,
        model: CVPTModel,
        device: str | torch.device = "cpu",
        temperature: float = 1.0,
        greedy: bool = False,
        seed: int = 0,
    ) -> None:
        if temperature <= 0:
            raise ValueError(f"temperature must be > 0, got {temperature}")
        self.device = torch.device(device)
        self.model = model.to(self.device).eval()
        self.temperature = temperature
        self.greedy = greedy
        self._rng = np.random.default_rng(seed)

    @classmethod
    def load(cls, path: str | Path, device: str = "cpu", **kwargs) -> CVPTPolicy:
        """From a Lightning .ckpt of ``zoo fit`` or a ``zoo export`` folder, without Lightning."""
        return cls(load_model(path, "cvpt"), device, **kwargs)

    def initial_state(self, n: int) -> TrXLState:
        """Empty memory for n envs: their next step attends to nothing before it."""
        return self.model.initial_state(n, self.device)

    @torch.no_grad()
    def logits(
        self, frames: np.ndarray, state: TrXLState, first: np.ndarray | None = None
    ) -> tuple[torch.Tensor, TrXLState]:
        """Action logits (N, num_actions) for frames (N, 144, 144, 3) uint8.

        ``first[i]`` (N,) marks env i's first step of a new episode; None: no env starts one
        (an ``initial_state`` needs no flag, its memory is empty).
        """
        frames = np.asarray(frames)
        if first is None:
            first = np.zeros(len(frames), dtype=bool)
        frames_t = torch.tensor(frames, device=self.device).unsqueeze(1)  # copies: env frames may be read-only
        first_t = torch.as_tensor(np.asarray(first, dtype=bool), device=self.device).unsqueeze(1)
        logits, state = self.model(frames_t, first_t, state)
        return logits[:, 0].float(), state

    def act(
        self,
        frames: np.ndarray,
        state: TrXLState,
        first: np.ndarray | None = None,
        uniforms: np.ndarray | None = None,
    ) -> tuple[np.ndarray, TrXLState]:
        """Sample one action per env (argmax if ``greedy``): ``actions, state = act(frames, state)``.

        ``first[i]`` marks env i's first step of an episode: nothing before it is attended to.
        ``uniforms`` (N,) in [0, 1) drive the sampling (inverse CDF), so a caller can give
        each env its own seeded stream; by default they come from the policy's generator.
        """
        logits, state = self.logits(frames, state, first)
        u = self._rng.random(len(logits)) if uniforms is None else np.asarray(uniforms)
        return sample_actions(logits, self.temperature, self.greedy, u), state


class CVPTAgent:
    """``Agent`` for N envs: remembers each env's TrXL memory until ``reset`` marks a new episode."""

    name = "cvpt"
    needs_pixels = True

    def __init__(self, policy: CVPTPolicy, num_envs: int) -> None:
        self.policy = policy
        self.num_envs = num_envs
        self._state = policy.initial_state(num_envs)
        self._episodes = EpisodeStreams(num_envs)

    @classmethod
    def from_checkpoint(
        cls,
        path: str | Path,
        num_envs: int,
        device: str = "cpu",
        temperature: float = 1.0,
        greedy: bool = False,
    ) -> CVPTAgent:
        """Load a Lightning .ckpt from ``zoo fit`` or a folder from ``zoo export``."""
        policy = CVPTPolicy(load_model(path, "cvpt"), device, temperature, greedy)
        return cls(policy, num_envs)

    def reset(self, seeds: np.ndarray, mask: np.ndarray | None = None) -> None:
        self._episodes.reset(seeds, mask)

    def act(self, step: Step) -> np.ndarray:
        if step.frames is None:
            raise ValueError("CVPTAgent plays from pixels: make the env with pixels=True")
        episodes = self._episodes
        actions, self._state = self.policy.act(
            step.frames, self._state, episodes.first, episodes.uniforms()
        )
        episodes.stepped()
        return actions.astype(np.int32)
