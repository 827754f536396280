"""DAgger rollouts: the learner plays, the privileged expert labels every state it reaches.

Behaviour cloning only sees the states the expert's own play leads to; a learner that makes a
mistake (walks into a zombie at night) is then somewhere no label covers. DAgger (Ross et al.,
2011) plays the learner, asks the expert what it would have done in each visited state, and
trains on those labels. The scripted expert reads the game state, so it can label any state.

Its planner keeps a little memory (an exploration target, a plant to wall in, hysteresis flags
for resting, shelter and refilling). Every piece is either recomputed from the current state
at each step or checked against it before use (a guarded plant that is not there is
forgotten), and ``act`` is called at every step of the executed trajectory, so the memory
follows what was actually played, not what the expert would have played.

With an instruction schedule (goal-directed DAgger) the mixture is what the schedule tells:
the expert pursues the instruction and the learner, when it takes instructions (C-Steve-1), is
told the same one, so the labels show how to follow it from where the learner went astray.
"""

from __future__ import annotations

import numpy as np

from zoo.agents.base import Agent
from zoo.envs.base import Step

MIX_UNITS = ("episode", "step")
_MIX_SALT = 0xDA66E2  # keeps the mixture's draws apart from the agents' own seeded streams


class DaggerMixture:
    """Acts with the learner; labels with the expert; hands control to the expert with prob beta.

    With ``mix="episode"`` the draw is made once per episode (the expert plays that whole
    episode), with ``mix="step"`` at every step (Ross et al.'s beta-mixture). Both agents see
    every step, so the learner's memory and the expert's planner follow the executed play.
    After ``act``: ``labels`` (the expert's actions), ``learner_actions``, ``expert_drove``.

    Args:
        learner: the policy being improved (C-VPT, or C-Steve-1 told the expert's instruction).
        expert: the labeller (scripted expert).
        num_envs: envs both agents act for.
        beta: probability that the expert acts.
        mix: "episode" or "step", the unit the beta draw is made for.
    """

    name = "dagger"
    needs_pixels = True

    def __init__(
        self, learner: Agent, expert: Agent, num_envs: int, beta: float, mix: str = "episode"
    ) -> None:
        if not 0.0 <= beta <= 1.0:
            raise ValueError(f"beta must be in [0, 1], got {beta}")
        if mix not in MIX_UNITS:
            raise ValueError(f"mix must be one of {MIX_UNITS}, got {mix!r}")
        self.learner, self.expert, self.beta, self.mix = learner, expert, beta, mix
        n = self._num_envs = num_envs
        self._rngs = [np.random.default_rng(0) for _ in range(n)]
        self._episode_draw = np.zeros(n, bool)
        self.labels = np.zeros(n, np.int32)
        self.learner_actions = np.zeros(n, np.int32)
        self.expert_drove = np.zeros(n, bool)

    @property
    def num_envs(self) -> int:
        return self._num_envs

    @property
    def config(self):
        """The expert's ``ExpertConfig`` (an instruction schedule reads its rest thresholds)."""
        return self.expert.config

    def instruct(self, instructions: list[str | None], mask: np.ndarray | None = None) -> None:
        """Tell the expert, and a learner that takes instructions, env i's ``instructions[i]``
        where ``mask[i]`` (None: no instruction; the expert plays normally, C-Steve-1 with no
        goal)."""
        self.expert.instruct(instructions, mask)
        if hasattr(self.learner, "instruct"):
            self.learner.instruct(instructions, mask)

    def reset(self, seeds: np.ndarray, mask: np.ndarray | None = None) -> None:
        self.learner.reset(seeds, mask)
        self.expert.reset(seeds, mask)
        for i in range(self._num_envs) if mask is None else np.flatnonzero(mask):
            self._rngs[i] = np.random.default_rng([int(seeds[i]), _MIX_SALT])
            self._episode_draw[i] = self._rngs[i].random() < self.beta

    def act(self, step: Step) -> np.ndarray:
        self.labels = np.asarray(self.expert.act(step), np.int32)
        self.learner_actions = np.asarray(self.learner.act(step), np.int32)
        if self.mix == "step":
            self.expert_drove = np.array([rng.random() < self.beta for rng in self._rngs])
        else:
            self.expert_drove = self._episode_draw.copy()
        return np.where(self.expert_drove, self.labels, self.learner_actions)
