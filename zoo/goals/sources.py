"""Where C-Steve-1's training goals come from: hindsight relabelling (the paper's), the
instructions the expert was commanded (goal-directed CrafterPlay, ``zoo data generate
--instructions``), or a mix of the two.

Hindsight goals are reached, not asked for: an expert that plays its tech tree in a fixed order
makes them predictable from the time step alone. In goal-directed data every step of an
instruction's segment (``zoo.experts.scripted.schedule``) shows the expert pursuing that
caption, in whatever context the schedule put it, so the goal can be the instruction itself:
- ``caption`` (default): the caption's goal embedding, the unit-norm mean of the C-CLIP video
  embeddings of the clips where the caption fires in the ``zoo goals embed`` folder
  (``caption_goals``), which is what the prior stands in for at play time when it turns the
  caption's text into a goal; a segment that timed out keeps it too (it still shows the pursuit);
- ``prior``: one of the prior's goals for the caption's text, drawn per segment from samples
  made once (the datamodule's ``prior`` and ``cclip``): exactly what a user's typed
  instruction gives at play time, where a clip centroid of this data set may lie elsewhere
  (on goal-directed data the prior's "craft wood pickaxe" lies nearest "obtain sapling"'s
  centroid);
- ``completion``: the C-CLIP embedding of the clip at the action that completed the segment
  (its own outcome); segments that did not complete keep their hindsight goals.
``commanded`` uses them on every segment (``commanded_segments: completed``: only on segments
whose instruction was completed; the others keep hindsight goals, e.g. the expert's pursuits of
"obtain ripe plant", which a 500-step episode never completes and whose prior goal lies at
cosine 0.96 from "obtain drink"'s), ``mix`` on each segment with probability
``commanded_weight`` (one draw per segment, from (seed, epoch, episode)). Steps without an
instruction (the expert's rests) and captions that never fire in the embeddings keep their
hindsight goals. Which
steps are unconditional is the hindsight relabelling's draw whatever the source, so
``uncond_prob`` keeps its meaning.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from zoo.experts.scripted.schedule import COMPLETED
from zoo.goals.embed import GOAL_DTYPE, load_embedding_manifest, read_embedding_shard
from zoo.goals.relabel import Relabelling

GoalSource = Literal["hindsight", "commanded", "mix"]
GOAL_SOURCES: tuple[str, ...] = ("hindsight", "commanded", "mix")
CommandedGoal = Literal["caption", "prior", "completion"]
COMMANDED_GOALS: tuple[str, ...] = ("caption", "prior", "completion")
CommandedSegments = Literal["all", "completed"]
COMMANDED_SEGMENTS: tuple[str, ...] = ("all", "completed")
CAPTION_GOAL_STEP = -1
"""``goal_step`` of a step whose goal is a caption's embedding (no one clip is its goal)."""


@dataclass(frozen=True)
class GoalSourceParams:
    """Which goals C-Steve-1 trains on (see the module docstring)."""

    source: GoalSource = "hindsight"
    commanded_weight: float = 0.5
    """``mix``: the share of instruction segments given their commanded goal."""
    commanded_goal: CommandedGoal = "caption"
    """What a commanded goal is: the caption's embedding, a prior goal of its text, or the
    completing clip's embedding."""
    commanded_segments: CommandedSegments = "all"
    """Which segments get commanded goals: all, or only those whose instruction completed."""

    def __post_init__(self) -> None:
        if self.source not in GOAL_SOURCES:
            raise ValueError(f"goal_source={self.source!r}: expected one of {GOAL_SOURCES}")
        if self.commanded_goal not in COMMANDED_GOALS:
            raise ValueError(
                f"commanded_goal={self.commanded_goal!r}: expected one of {COMMANDED_GOALS}"
            )
        if self.commanded_segments not in COMMANDED_SEGMENTS:
            raise ValueError(
                f"commanded_segments={self.commanded_segments!r}: expected one of "
                f"{COMMANDED_SEGMENTS}"
            )
        if not 0.0 <= self.commanded_weight <= 1.0:
            raise ValueError(f"commanded_weight={self.commanded_weight} must lie in [0, 1]")

    @property
    def commanded_share(self) -> float:
        """The chance that one segment gets its commanded goal."""
        return {"hindsight": 0.0, "commanded": 1.0, "mix": self.commanded_weight}[self.source]


def caption_goals(root: str | Path) -> dict[int, np.ndarray]:
    """caption id -> its goal embedding: the unit-norm mean of the goal rows of the steps where
    it fires, over every shard of a ``zoo goals embed`` folder (captions that never fire are
    absent)."""
    root = Path(root)
    sums: dict[int, np.ndarray] = {}
    for entry in load_embedding_manifest(root)["shards"]:
        for record in read_embedding_shard(root / entry["file"]).values():
            captions, goals = record["caption"], record["goal"].astype(np.float32)
            for caption in np.unique(captions[captions >= 0]).tolist():
                total = goals[captions == caption].sum(axis=0)
                sums[caption] = sums[caption] + total if caption in sums else total
    return {
        caption: (total / max(float(np.linalg.norm(total)), 1e-12)).astype(GOAL_DTYPE)
        for caption, total in sorted(sums.items())
    }


def command_rng(seed: int, epoch: int, episode: int) -> np.random.Generator:
    """The per-segment draws of one episode in one epoch (apart from the relabelling's)."""
    return np.random.default_rng([seed, epoch, episode, 0xC0DE])


def episode_goals(
    goals: np.ndarray,
    labels: Relabelling,
    segments: list | None,
    params: GoalSourceParams,
    prototypes: dict[int, np.ndarray],
    rng: np.random.Generator,
) -> dict[str, np.ndarray]:
    """One episode's per-step ``goal`` (zeros where unconditional), ``goal_mask`` and
    ``goal_step``, from its goal embeddings ``goals`` (T, D), its hindsight ``labels`` and its
    instruction ``segments`` ([start, stop, caption_id, outcome], None: not goal-directed).
    ``prototypes`` maps a caption id to its goal (D,), or to goals (K, D) to draw one from."""
    goal_step = labels.goal_step.copy()
    goal = goals[goal_step]
    share = params.commanded_share
    for start, stop, caption_id, outcome in segments if share and segments else []:
        if rng.random() >= share:
            continue
        if params.commanded_segments == "completed" and outcome != COMPLETED:
            continue
        if params.commanded_goal in ("caption", "prior") and caption_id in prototypes:
            proto = prototypes[caption_id]
            goal[start:stop] = proto[rng.integers(len(proto))] if proto.ndim == 2 else proto
            goal_step[start:stop] = CAPTION_GOAL_STEP
        elif params.commanded_goal == "completion" and outcome == COMPLETED:
            goal[start:stop] = goals[stop - 1]
            goal_step[start:stop] = stop - 1
    goal[~labels.conditioned] = 0
    return {"goal": goal, "goal_mask": labels.conditioned, "goal_step": goal_step}


__all__ = [
    "CAPTION_GOAL_STEP",
    "COMMANDED_GOALS",
    "COMMANDED_SEGMENTS",
    "GOAL_SOURCES",
    "CommandedGoal",
    "CommandedSegments",
    "GoalSource",
    "GoalSourceParams",
    "caption_goals",
    "command_rng",
    "episode_goals",
]
