"""``InstructionGoal``: C-Steve-1's goal embedding of a text instruction in the observation.

The goal is what ``zoo eval`` gives C-Steve-1 for that text (paper §4.3, "Inference"): C-CLIP's
text embedding through the CVAE prior, unit-normed. It is drawn once per episode from a
generator seeded with the episode seed and the text, as ``CSteve1Agent`` draws it, so a Gymnasium
agent sees the very goal C-Steve-1 gets in the same episode of ``zoo eval``. The observation
becomes a ``Dict`` with "goal" beside the env's own entries (a Box observation is kept as
"pixels" if it is a frame, else as "obs").
"""

from __future__ import annotations

import zlib
from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces
from gymnasium.utils import RecordConstructorArgs
from gymnasium.vector import VectorEnv

from zoo.agents.csteve1_agent import GoalEncoder
from zoo.gym.wrappers.base import ModelWrapper, VectorModelWrapper, load
from zoo.models.cclip import CCLIPModel
from zoo.models.prior import CVAEPrior


def _key(space: gymnasium.Space) -> str:
    image = isinstance(space, spaces.Box) and space.dtype == np.uint8 and len(space.shape) == 3
    return "pixels" if image else "obs"


class GoalModel:
    """The batched goal source of ``InstructionGoal`` (see the module docstring)."""

    def __init__(
        self, space: gymnasium.Space, num_envs: int, instruction: str, goals: GoalEncoder
    ) -> None:
        if isinstance(space, spaces.Dict) and "goal" in space.spaces:
            raise ValueError("the observation already has a 'goal' entry")
        self.goals, self.instruction = goals, instruction
        self._text_seed = zlib.crc32(instruction.encode())
        box = spaces.Box(-1.0, 1.0, (goals.goal_dim,), np.float32)
        parts = dict(space.spaces) if isinstance(space, spaces.Dict) else {_key(space): space}
        self._key = None if isinstance(space, spaces.Dict) else _key(space)
        self.observation_space = spaces.Dict({**parts, "goal": box})
        self.goal = np.zeros((num_envs, goals.goal_dim), np.float32)

    def observe(
        self, obs: Any, reward: np.ndarray, starts: np.ndarray, seeds: np.ndarray | None,
        active: np.ndarray,
    ) -> tuple[Any, np.ndarray, dict[str, np.ndarray]]:
        begin = np.flatnonzero(starts & active)
        if len(begin) and seeds is None:
            raise ValueError("InstructionGoal needs info['episode_seed']: wrap a CrafterDojo env")
        for i in begin:
            seed = int(seeds[i]) ^ self._text_seed
            self.goal[i] = self.goals.from_text([self.instruction], seed=seed)[0].float().numpy()
        parts = dict(obs) if self._key is None else {self._key: obs}
        return {**parts, "goal": self.goal.copy()}, reward, {}


def _encoder(cclip: Any, prior: Any, sample_prior: bool) -> GoalEncoder:
    return GoalEncoder(
        load(cclip, "cclip", "cclip_cpu"), load(prior, "prior", "prior_cpu"), sample_prior
    )


class InstructionGoal(ModelWrapper, RecordConstructorArgs):
    """Adds "goal": the C-Steve-1 goal of ``instruction`` for this episode.

    Args:
        env: a CrafterDojo env (its ``info["episode_seed"]`` seeds the goal).
        instruction: text, e.g. "place table on grass" (a CrafterCaption caption or free text).
        cclip, prior: models or paths (default: the shipped weights/cclip_cpu, prior_cpu).
        sample_prior: draw from the prior (as ``zoo eval``); False uses its mean goal.
    """

    def __init__(
        self, env: gymnasium.Env, instruction: str, cclip: CCLIPModel | str | None = None,
        prior: CVAEPrior | str | None = None, sample_prior: bool = True,
    ) -> None:
        RecordConstructorArgs.__init__(
            self, instruction=instruction, cclip=cclip, prior=prior, sample_prior=sample_prior
        )
        goals = _encoder(cclip, prior, sample_prior)
        super().__init__(env, GoalModel(env.observation_space, 1, instruction, goals))


class VectorInstructionGoal(VectorModelWrapper, RecordConstructorArgs):
    """``InstructionGoal`` on a vector env."""

    def __init__(
        self, env: VectorEnv, instruction: str, cclip: CCLIPModel | str | None = None,
        prior: CVAEPrior | str | None = None, sample_prior: bool = True,
    ) -> None:
        RecordConstructorArgs.__init__(
            self, instruction=instruction, cclip=cclip, prior=prior, sample_prior=sample_prior
        )
        goals = _encoder(cclip, prior, sample_prior)
        super().__init__(
            env, GoalModel(env.single_observation_space, env.num_envs, instruction, goals)
        )
