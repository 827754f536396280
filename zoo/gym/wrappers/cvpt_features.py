"""``CVPTFeatures``: the frozen C-VPT's Transformer-XL output as the observation.

The feature of step t is what C-VPT's policy head reads: the TrXL output over the current
frame and up to ``memory_len`` earlier steps of the same episode. The memory is cached per env
(one frame through the encoder per step, as ``CVPTPolicy`` plays) and an episode's first
observation stops attention to anything before it, so a feature never mixes two episodes. A
pixel observation becomes a ``Box(d_model)``; in a ``Dict`` the "pixels" entry is replaced by
"features" and the other entries are kept.
"""

from __future__ import annotations

from typing import Any

import gymnasium
import numpy as np
import torch
from gymnasium import spaces
from gymnasium.utils import RecordConstructorArgs
from gymnasium.vector import VectorEnv

from zoo.gym.wrappers.base import ModelWrapper, VectorModelWrapper, frames_of, load, pixel_space
from zoo.models.cvpt import CVPTModel
from zoo.models.trxl import TrXLState


class CVPTFeatureModel:
    """The batched feature extractor of ``CVPTFeatures`` (see the module docstring)."""

    def __init__(self, space: gymnasium.Space, num_envs: int, cvpt: CVPTModel) -> None:
        pixel_space(space, "CVPTFeatures")
        self.cvpt = cvpt
        width = cvpt.config.d_model
        box = spaces.Box(-np.inf, np.inf, (width,), np.float32)
        self._dict = isinstance(space, spaces.Dict)
        self.observation_space = (
            spaces.Dict({"features" if k == "pixels" else k: box if k == "pixels" else s
                         for k, s in space.spaces.items()})
            if self._dict else box
        )
        self.state = cvpt.initial_state(num_envs)
        self.features = np.zeros((num_envs, width), np.float32)

    @torch.inference_mode()
    def observe(
        self, obs: Any, reward: np.ndarray, starts: np.ndarray, seeds: np.ndarray | None,
        active: np.ndarray,
    ) -> tuple[Any, np.ndarray, dict[str, np.ndarray]]:
        rows = torch.as_tensor(np.flatnonzero(active))
        frames = torch.from_numpy(np.ascontiguousarray(frames_of(obs)[rows.numpy()]))
        first = torch.as_tensor(starts[rows.numpy()])
        memory, blocked = self.state
        state = TrXLState(memory[:, rows], blocked[rows])
        hidden, state = self.cvpt.features(frames[:, None], first[:, None], state)
        memory[:, rows], blocked[rows] = state.memory, state.blocked
        self.features[rows.numpy()] = hidden[:, 0].float().numpy()
        features = self.features.copy()
        if self._dict:
            obs = {("features" if k == "pixels" else k): features if k == "pixels" else v
                   for k, v in obs.items()}
        else:
            obs = features
        return obs, reward, {}


class CVPTFeatures(ModelWrapper, RecordConstructorArgs):
    """Observations become C-VPT's TrXL features (memory reset at each episode start).

    Args:
        env: an env observing 144-px frames (a Box or a Dict with "pixels").
        cvpt: a ``CVPTModel`` or the path of one (default: the shipped weights/cvpt_tiny_cpu).
    """

    def __init__(self, env: gymnasium.Env, cvpt: CVPTModel | str | None = None) -> None:
        RecordConstructorArgs.__init__(self, cvpt=cvpt)
        model = load(cvpt, "cvpt", "cvpt_tiny_cpu")
        super().__init__(env, CVPTFeatureModel(env.observation_space, 1, model))


class VectorCVPTFeatures(VectorModelWrapper, RecordConstructorArgs):
    """``CVPTFeatures`` on a vector env: one C-VPT batch per step for all envs."""

    def __init__(self, env: VectorEnv, cvpt: CVPTModel | str | None = None) -> None:
        RecordConstructorArgs.__init__(self, cvpt=cvpt)
        model = load(cvpt, "cvpt", "cvpt_tiny_cpu")
        super().__init__(env, CVPTFeatureModel(env.single_observation_space, env.num_envs, model))
