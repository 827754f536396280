"""What a generation mode adds to the play loop of ``ShardGenerator.run``, one class per mode.

The loop itself is observation -> agent -> step -> store. A DAgger dataset stores the expert's
labels instead of the played actions and counts how often the learner agreed
(``DaggerLabels``); an instructed dataset tells the expert a schedule of captions and stores
the caption each action pursued (``Instructions``). Each has the same hooks as the plain
mode (``PlayedActions``, ``NoInstructions``), so the loop calls them without asking which
mode it is in.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from zoo.data.noop import noop_flags
from zoo.envs.base import Step
from zoo.experts.scripted.schedule import (
    InstructionSchedule,
    InstructionScheduler,
    add_tallies,
    tally_outcomes,
)


class PlayedActions:
    """Expert play: the played actions are stored; a noop is an action that changed nothing."""

    def start(self, slot: int) -> None:
        """Env ``slot`` starts an episode."""

    def labels(self, actions: np.ndarray, step: Step, after: Step) -> tuple[np.ndarray, np.ndarray]:
        """The actions to store for one step of every env, and their noop flags."""
        return actions, noop_flags(actions, step.state, after.state)

    def finish(self, slot: int) -> dict:
        """What env ``slot``'s finished episode adds to its summary."""
        return {}

    def entry(self, episodes: Sequence[dict]) -> dict:
        """What a shard's episodes add to its manifest entry."""
        return {}


class DaggerLabels(PlayedActions):
    """DAgger: the learner/expert mixture (``zoo.agents.dagger.DaggerMixture``) played; the
    expert's label of each visited state is stored. A step counts as a noop only when the
    played action changed nothing and was the label too, so states where the learner idles
    keep the expert's way out."""

    def __init__(self, mixture, num_envs: int) -> None:
        self.mixture = mixture
        self.agreed = np.zeros(num_envs, np.int64)  # the learner's action was the label
        self.drove = np.zeros(num_envs, np.int64)  # the expert acted

    def start(self, slot: int) -> None:
        self.agreed[slot] = self.drove[slot] = 0

    def labels(self, actions: np.ndarray, step: Step, after: Step) -> tuple[np.ndarray, np.ndarray]:
        labels = self.mixture.labels
        self.agreed += self.mixture.learner_actions == labels
        self.drove += self.mixture.expert_drove
        return labels, noop_flags(actions, step.state, after.state) & (labels == actions)

    def finish(self, slot: int) -> dict:
        return {"dagger": (int(self.agreed[slot]), int(self.drove[slot]))}

    def entry(self, episodes: Sequence[dict]) -> dict:
        steps = max(sum(e["length"] for e in episodes), 1)
        return {"dagger": {
            "learner_agreement": sum(e["dagger"][0] for e in episodes) / steps,
            "expert_share": sum(e["dagger"][1] for e in episodes) / steps,
        }}


class NoInstructions:
    """Normal play: no caption is pursued (id -1 everywhere)."""

    def __init__(self, num_envs: int) -> None:
        self._none = np.full(num_envs, -1, np.int16)

    def reset(self, seeds: np.ndarray, mask: np.ndarray | None = None) -> None:
        """Envs where ``mask`` (all if None) start episodes seeded by ``seeds``."""

    def commanded(self) -> np.ndarray:
        """The caption id each env's next action pursues."""
        return self._none

    def update(self, state: dict, after: dict) -> None:
        """One step was played from ``state`` to ``after``."""

    def finish(self, slot: int) -> list | None:
        """Env ``slot``'s finished episode's instruction segments (None: none)."""
        return None

    def entry(self, episodes: Sequence[dict]) -> dict:
        return {}


class Instructions(NoInstructions):
    """The scripted expert told a schedule of captions (``InstructionScheduler``); each step
    records the caption its action pursued."""

    def __init__(self, schedule: InstructionSchedule, agent, num_envs: int) -> None:
        super().__init__(num_envs)
        self.schedule = schedule
        self.scheduler = InstructionScheduler(schedule, agent)

    def reset(self, seeds: np.ndarray, mask: np.ndarray | None = None) -> None:
        self.scheduler.reset(seeds, mask)

    def commanded(self) -> np.ndarray:
        return self.scheduler.ids

    def update(self, state: dict, after: dict) -> None:
        self.scheduler.update(state, after)

    def finish(self, slot: int) -> list | None:
        return self.scheduler.finish(slot)

    def entry(self, episodes: Sequence[dict]) -> dict:
        tallies = [tally_outcomes(e["instructions"], self.schedule) for e in episodes]
        return {"instructions": add_tallies(tallies)}
