"""One batched model step behind both a ``gymnasium.Wrapper`` and a ``VectorWrapper``.

A foundation-model wrapper is a ``BatchedModel``: ``observe`` takes N observations, rewards
and which of them start an episode, and returns new observations, rewards and info. The single
env wrapper calls it with N = 1; the vector wrapper with all N envs in one model call. The
vector wrapper follows the env's autoreset mode: under ``NEXT_STEP`` an env whose episode ended
on the last step starts one now; under ``DISABLED`` episodes start only where
``reset(options={"reset_mask": ...})`` says. ``SAME_STEP`` is refused, as Gymnasium's own vector
observation wrappers refuse it (the final observation hides in ``info`` and would go
unprocessed).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Protocol

import gymnasium
import numpy as np
import torch
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv, VectorWrapper
from gymnasium.vector.utils import batch_space

from zoo.envs.schema import FRAME_SHAPE
from zoo.gym.vector import masked_info, reset_mask

SHIPPED = Path(__file__).resolve().parents[3] / "weights"
"""The repository's shipped exports (weights/README.md), the wrappers' default models."""


def load(model: Any, kind: str, default: str) -> torch.nn.Module:
    """``model`` itself, or loaded (``zoo.weights.load_model``) from a path, or the shipped
    ``weights/<default>`` when None; in eval mode."""
    if model is None or isinstance(model, str | Path):
        from zoo.weights import load_model

        model = load_model(SHIPPED / default if model is None else model, kind)
    return model.eval()


def pixel_space(space: spaces.Space, who: str) -> None:
    """Check that observations carry 144-px frames (as a Box, or under "pixels")."""
    box = space["pixels"] if isinstance(space, spaces.Dict) and "pixels" in space.spaces else space
    if not (isinstance(box, spaces.Box) and box.shape == FRAME_SHAPE and box.dtype == np.uint8):
        raise ValueError(
            f"{who} reads the 144x144 frames the models were trained on; this env observes "
            f"{space}: make it with size=144"
        )


def frames_of(obs: Any) -> np.ndarray:
    return obs["pixels"] if isinstance(obs, dict) else obs


class BatchedModel(Protocol):
    observation_space: spaces.Space
    """What one env's observation becomes."""

    def observe(
        self, obs: Any, reward: np.ndarray, starts: np.ndarray, seeds: np.ndarray | None,
        active: np.ndarray,
    ) -> tuple[Any, np.ndarray, dict[str, np.ndarray]]:
        """Process the envs where ``active``; ``starts`` marks first observations of an episode
        (reward 0), ``seeds`` is ``info["episode_seed"]`` (None if the env gives none)."""
        ...


def _batch(obs: Any) -> Any:
    return {k: np.asarray(v)[None] for k, v in obs.items()} if isinstance(obs, dict) else np.asarray(obs)[None]


def _row(tree: Any) -> Any:
    return {k: v[0] for k, v in tree.items()} if isinstance(tree, dict) else tree[0]


def _seeds(info: dict[str, Any], batched: bool) -> np.ndarray | None:
    seed = info.get("episode_seed")
    return None if seed is None else np.asarray(seed).reshape(-1) if batched else np.array([seed])


_ONE, _NONE = np.ones(1, bool), np.zeros(1, bool)


class ModelWrapper(gymnasium.Wrapper):
    """A ``BatchedModel`` on one env."""

    def __init__(self, env: gymnasium.Env, model: BatchedModel) -> None:
        super().__init__(env)
        self.model = model
        self.observation_space = model.observation_space

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        obs, info = self.env.reset(seed=seed, options=options)
        obs, _, extra = self.model.observe(
            _batch(obs), np.zeros(1, np.float32), _ONE, _seeds(info, False), _ONE
        )
        return _row(obs), {**info, **_row(extra)}

    def step(self, action: Any):
        obs, reward, terminated, truncated, info = self.env.step(action)
        obs, reward, extra = self.model.observe(
            _batch(obs), np.array([reward], np.float32), _NONE, _seeds(info, False), _ONE
        )
        return _row(obs), float(reward[0]), terminated, truncated, {**info, **_row(extra)}


class VectorModelWrapper(VectorWrapper):
    """A ``BatchedModel`` on all envs of a vector env at once (see the module docstring)."""

    def __init__(self, env: VectorEnv, model: BatchedModel) -> None:
        super().__init__(env)
        self._mode = env.metadata.get("autoreset_mode", AutoresetMode.NEXT_STEP)
        if self._mode == AutoresetMode.SAME_STEP:
            raise ValueError(
                f"{type(self).__name__} needs autoreset_mode NEXT_STEP or DISABLED, got SAME_STEP"
            )
        self.model = model
        self.single_observation_space = model.observation_space
        self.observation_space = batch_space(model.observation_space, self.num_envs)
        self._ended = np.zeros(self.num_envs, bool)
        self._every = np.ones(self.num_envs, bool)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        mask = reset_mask(options, self.num_envs)  # read first: AsyncVectorEnv pops it
        obs, info = self.env.reset(seed=seed, options=None if options is None else dict(options))
        zeros = np.zeros(self.num_envs, np.float32)
        obs, _, extra = self.model.observe(obs, zeros, mask, _seeds(info, True), mask)
        self._ended[mask] = False
        return obs, {**info, **masked_info(extra, mask)}

    def step(self, actions: Any):
        obs, reward, terminated, truncated, info = self.env.step(actions)
        starts = self._ended if self._mode == AutoresetMode.NEXT_STEP else ~self._every
        obs, reward, extra = self.model.observe(
            obs, np.asarray(reward, np.float32), starts, _seeds(info, True), self._every
        )
        self._ended = np.asarray(terminated) | np.asarray(truncated)
        return obs, reward, terminated, truncated, {**info, **masked_info(extra, self._every)}
