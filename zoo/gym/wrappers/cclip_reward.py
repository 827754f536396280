"""``CClipReward``: MineCLIP's dense reward with C-CLIP, for any Gymnasium agent.

The reward added each step is ``scale * (s_t - s_{t-1})``, where s_t is the cosine similarity
between C-CLIP's embedding of the last 6 frames (o_{t-5..t}) and the instruction's text
embedding. Over an episode the added rewards sum to s_T - s_0, so the shaping cannot be farmed
by lingering near a similar-looking scene; it pays for getting closer. At an episode's start the
window holds its first frame 6 times (no frame of the previous episode leaks in) and the added
reward is 0.

Each step runs C-CLIP's image tower once per env (the window's other 5 frame features are
kept) and the small temporal head once per env, all envs in one batch: the
frame-features-then-windows split of ``zoo goals embed`` (``ClipEmbedder``), which gives the
same embeddings as ``encode_video`` on explicit clips (tests/zoo/gym checks it here too). The
tower is called on the new frames alone: ``encode_frames`` takes whole 6-frame clips, and
padding one env's frame to a clip would cost 6 tower passes instead of one.
"""

from __future__ import annotations

from typing import Any

import gymnasium
import numpy as np
import torch
import torch.nn.functional as F
from gymnasium.utils import RecordConstructorArgs
from gymnasium.vector import VectorEnv

from zoo.gym.wrappers.base import ModelWrapper, VectorModelWrapper, frames_of, load, pixel_space
from zoo.models.cclip import CCLIPModel


class CClipShaping:
    """The batched reward model of ``CClipReward`` (see the module docstring)."""

    def __init__(
        self, space: gymnasium.Space, num_envs: int, instruction: str, cclip: CCLIPModel,
        scale: float,
    ) -> None:
        pixel_space(space, "CClipReward")
        self.observation_space = space
        self.cclip, self.scale = cclip, scale
        with torch.inference_mode():
            self.text = cclip.encode_text([instruction])[0].float()
        dim = cclip.config.embed_dim
        self.window = torch.zeros(num_envs, cclip.config.num_frames, dim)
        self.similarity = np.zeros(num_envs, np.float32)

    def _tower(self, frames: np.ndarray) -> torch.Tensor:
        """(k, 144, 144, 3) uint8 -> (k, D): ``encode_frames``' per-frame features."""
        model = self.cclip
        images = torch.from_numpy(np.ascontiguousarray(frames)).permute(0, 3, 1, 2)
        images = (images.to(model.pixel_mean.dtype) - model.pixel_mean) / model.pixel_std
        return model.clip.encode_image(images).float()

    @torch.inference_mode()
    def observe(
        self, obs: Any, reward: np.ndarray, starts: np.ndarray, seeds: np.ndarray | None,
        active: np.ndarray,
    ) -> tuple[Any, np.ndarray, dict[str, np.ndarray]]:
        rows = np.flatnonzero(active)
        features = self._tower(frames_of(obs)[rows])  # (k, D)
        fresh = torch.as_tensor(starts[rows])[:, None, None]
        slid = torch.cat([self.window[rows, 1:], features[:, None]], dim=1)
        restarted = features[:, None].expand_as(slid)
        self.window[rows] = torch.where(fresh, restarted, slid)
        video = F.normalize(self.cclip.video_adapter(self.cclip.temporal(self.window[rows])), dim=-1)
        similarity = (video @ self.text).numpy()
        shaped = np.zeros(len(starts), np.float32)
        shaped[rows] = np.where(starts[rows], 0.0, self.scale * (similarity - self.similarity[rows]))
        self.similarity[rows] = similarity
        extra = {"cclip_reward": shaped, "cclip_similarity": self.similarity.copy()}
        return obs, reward + shaped, extra


class CClipReward(ModelWrapper, RecordConstructorArgs):
    """Adds ``scale *`` the change in C-CLIP video-text similarity to the reward; ``info`` gets
    ``cclip_reward`` (that term) and ``cclip_similarity``.

    Args:
        env: an env observing 144-px frames (a Box or a Dict with "pixels").
        instruction: the text the frames should come to match, e.g. "obtain coal".
        cclip: a ``CCLIPModel`` or the path of one (default: the shipped weights/cclip_cpu).
        scale: weight of the added term.
    """

    def __init__(
        self, env: gymnasium.Env, instruction: str, cclip: CCLIPModel | str | None = None,
        scale: float = 1.0,
    ) -> None:
        RecordConstructorArgs.__init__(self, instruction=instruction, cclip=cclip, scale=scale)
        model = load(cclip, "cclip", "cclip_cpu")
        super().__init__(env, CClipShaping(env.observation_space, 1, instruction, model, scale))


class VectorCClipReward(VectorModelWrapper, RecordConstructorArgs):
    """``CClipReward`` on a vector env: one C-CLIP batch per step for all envs."""

    def __init__(
        self, env: VectorEnv, instruction: str, cclip: CCLIPModel | str | None = None,
        scale: float = 1.0,
    ) -> None:
        RecordConstructorArgs.__init__(self, instruction=instruction, cclip=cclip, scale=scale)
        model = load(cclip, "cclip", "cclip_cpu")
        super().__init__(
            env, CClipShaping(env.single_observation_space, env.num_envs, instruction, model, scale)
        )
