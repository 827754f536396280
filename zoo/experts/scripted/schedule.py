"""Instruction schedules: the goal-directed expert told one caption after another.

``zoo data generate --instructions`` makes demonstrations of *following* an instruction, which
hindsight relabelling of normal play cannot give (there the order of the goals is the expert's
fixed tech tree, predictable from the time step alone). Each env pursues a caption drawn from the
schedule until its event happens (completed) or ``timeout`` actions have gone by (timed out),
then draws the next one (uniformly, or by the schedule's weights), never the same twice in a
row so every switch shows in the record.
The draws come from the episode's seed alone, so the data stays a function of (seed, episode).

Told something, the expert only stays alive besides (no sleep, no night shelter): it would die
in its first night. So at nightfall, or when tired, an env *rests*: the expert plays normally
(shelters, sleeps) with no instruction (recorded -1), and gets a new one once it is day again,
it is awake and its energy is above ``energy_low`` (the expert's own thresholds).

An instruction's *segment* is ``[start, stop, caption_id, outcome]``: actions start..stop-1
were taken pursuing it; ``outcome`` is "completed" (action stop-1 completed it), "timed_out",
"interrupted" (a rest began) or "ended" (the episode ended first).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from zoo.envs.constants import Achievement as Ach
from zoo.envs.constants import Block
from zoo.envs.schema import State
from zoo.envs.tasks import TASKS, achievement_events
from zoo.experts.scripted.goals import INSTRUCTIONS
from zoo.experts.scripted.policy import ScriptedExpert

COMPLETED_BY = {
    "obtain wood": Ach.COLLECT_WOOD,
    "obtain stone": Ach.COLLECT_STONE,
    "obtain coal": Ach.COLLECT_COAL,
    "obtain sapling": Ach.COLLECT_SAPLING,
    "obtain drink": Ach.COLLECT_DRINK,
    "obtain ripe plant": Ach.EAT_PLANT,
    "place plant on grass": Ach.PLACE_PLANT,
    "place table on grass": Ach.PLACE_TABLE,
    "place stone on grass": Ach.PLACE_STONE,
    "craft wood pickaxe": Ach.MAKE_WOOD_PICKAXE,
    "craft wood sword": Ach.MAKE_WOOD_SWORD,
    "craft stone pickaxe": Ach.MAKE_STONE_PICKAXE,
    "craft stone sword": Ach.MAKE_STONE_SWORD,
}
"""The achievement whose event (``instruction_events``) completes each followable caption."""

CAPTION_SETS = {
    "captions": tuple(INSTRUCTIONS),
    "subgoals": tuple(dict.fromkeys(s.instruction for t in TASKS.values() for s in t.subtasks)),
}
"""Named caption lists: every caption the expert follows; the task suites' sub-goals."""

COMPLETED, TIMED_OUT, INTERRUPTED, ENDED = "completed", "timed_out", "interrupted", "ended"
OUTCOMES = (COMPLETED, TIMED_OUT, INTERRUPTED, ENDED)
ENERGY = 3  # column of ``player_vitals``
_STREAM = 0x1257  # the schedule's random stream, apart from the planner's (seeded by the seed)


def read_schedule(spec: str) -> tuple[tuple[str, ...], tuple[float, ...] | None]:
    """The captions of ``spec`` and their draw weights: a name of ``CAPTION_SETS`` (uniform) or
    a text file with one caption per line, optionally ``caption | weight`` (blank lines and
    ``#`` comments skipped; weights None when no line gives one: uniform draws)."""
    if spec in CAPTION_SETS:
        return CAPTION_SETS[spec], None
    path = Path(spec)
    if not path.is_file():
        raise ValueError(
            f"instructions {spec!r}: expected {' or '.join(CAPTION_SETS)} or a file of captions"
        )
    captions, weights = [], []
    for number, line in enumerate(path.read_text().splitlines(), 1):
        text, _, weight = line.split("#", 1)[0].partition("|")
        if not text.strip():
            continue
        captions.append(text.strip())
        try:
            weights.append(float(weight) if weight.strip() else 1.0)
        except ValueError:
            raise ValueError(
                f"{path}:{number}: weight {weight.strip()!r} is not a number "
                "(expected 'caption | weight')"
            ) from None
    return tuple(captions), None if set(weights) <= {1.0} else tuple(weights)


@dataclass(frozen=True)
class InstructionSchedule:
    """What the expert is told in a dataset (stored nested in the manifest's ``config`` as
    ``instructions``).

    Args:
        captions: the captions drawn from (uniformly), each one the expert follows.
        caption_ids: their CrafterCaption ids (zoo/captions/captions.yaml), which the shards
            record per step.
        timeout: actions spent on an instruction before the next one is drawn.
        weights: each caption's draw weight (None: uniform draws, and older manifests compare
            equal); a DAgger round can ask more often for what its learner gets wrong.
    """

    captions: tuple[str, ...]
    caption_ids: tuple[int, ...]
    timeout: int = 300
    weights: tuple[float, ...] | None = None

    def __post_init__(self) -> None:
        # tuples, also when read back from a manifest's JSON lists
        object.__setattr__(self, "captions", tuple(self.captions))
        object.__setattr__(self, "caption_ids", tuple(int(i) for i in self.caption_ids))
        if not self.captions:
            raise ValueError("an instruction schedule needs at least one caption")
        unknown = [c for c in self.captions if c not in COMPLETED_BY]
        if unknown:
            raise ValueError(
                f"the scripted expert cannot follow {unknown}; it follows {sorted(COMPLETED_BY)}"
            )
        if len(set(self.captions)) != len(self.captions):
            raise ValueError(f"captions appear twice in {list(self.captions)}")
        if len(self.caption_ids) != len(self.captions) or min(self.caption_ids) < 0:
            raise ValueError(
                f"need one caption id >= 0 per caption, got {list(self.caption_ids)} for "
                f"{len(self.captions)} captions"
            )
        if self.timeout < 1:
            raise ValueError(f"the instruction timeout must be >= 1 action, got {self.timeout}")
        if self.weights is not None:
            object.__setattr__(self, "weights", tuple(float(w) for w in self.weights))
            if len(self.weights) != len(self.captions) or min(self.weights) <= 0:
                raise ValueError(
                    f"need one weight > 0 per caption, got {list(self.weights)} for "
                    f"{len(self.captions)} captions"
                )

    def draw(self, rng: np.random.Generator, exclude: int | None = None) -> int:
        """A caption index drawn by weight, never ``exclude`` (when there is another).
        Uniform schedules draw as they always did, so their datasets stay byte-identical."""
        count = len(self.captions)
        if self.weights is None:
            if exclude is None:
                return int(rng.integers(count))
            k = int(rng.integers(count - 1))
            return k + (k >= exclude)
        p = np.asarray(self.weights)
        if exclude is not None:
            p = p.copy()
            p[exclude] = 0.0
        return int(rng.choice(count, p=p / p.sum()))


def instruction_events(prev: State, cur: State) -> np.ndarray:
    """(N, 22) bool: the events that complete an instruction between two batched states.

    The task suites' events (repeats and the item cap included), except that placing stone
    counts each time a grass tile turns to stone: a flag flip only counts once, and bridging
    water on the way is not "place stone on grass".
    """
    events = achievement_events(prev, cur)
    on_grass = (prev["map"] == Block.GRASS) & (cur["map"] == Block.STONE)
    events[:, Ach.PLACE_STONE] = on_grass.any(axis=(1, 2))
    return events


class InstructionScheduler:
    """Tells ``expert`` what to pursue in each of its envs: switches an env's instruction on
    completion or timeout, and lets it rest at night or when tired (module docstring).

    ``reset`` at an episode's start, ``update`` with the states before and after every action,
    ``finish`` at its end (returns the episode's segments). ``ids`` is the caption id each env
    pursues now (-1 while it rests): what the action about to be taken is recorded with.
    """

    def __init__(self, schedule: InstructionSchedule, expert: ScriptedExpert) -> None:
        self.schedule = schedule
        self.expert = expert
        self.num_envs = num_envs = expert.num_envs
        self._ids = np.asarray(schedule.caption_ids, np.int16)
        self._targets = np.array([int(COMPLETED_BY[c]) for c in schedule.captions])
        self.index = np.zeros(num_envs, np.int64)  # into schedule.captions
        self.start = np.zeros(num_envs, np.int64)  # the action the current instruction began at
        self.step = np.zeros(num_envs, np.int64)  # actions taken in the episode
        self.resting = np.zeros(num_envs, bool)
        self._rngs: list[np.random.Generator | None] = [None] * num_envs  # made by reset
        self._segments: list[list[list]] = [[] for _ in range(num_envs)]

    @property
    def current(self) -> list[str | None]:
        """Each env's instruction (a caption text; None: resting), for ``instruct``."""
        captions = self.schedule.captions
        return [None if rest else captions[k] for k, rest in zip(self.index, self.resting)]

    @property
    def ids(self) -> np.ndarray:
        """(N,) int16: each env's instruction as a CrafterCaption id (-1: resting)."""
        return np.where(self.resting, -1, self._ids[self.index]).astype(np.int16)

    def reset(self, seeds: np.ndarray, mask: np.ndarray | None = None) -> None:
        """New episodes where ``mask``: a first instruction drawn from each one's seed."""
        mask = np.ones(self.num_envs, bool) if mask is None else np.asarray(mask, bool)
        for i in np.flatnonzero(mask):
            self._rngs[i] = np.random.default_rng([int(seeds[i]), _STREAM])
            self.index[i] = self.schedule.draw(self._rngs[i])
            self.start[i] = self.step[i] = 0
            self.resting[i] = False
            self._segments[i] = []
        self.expert.instruct(self.current, mask)

    def update(self, prev: State, cur: State) -> np.ndarray:
        """Account for one action of every env; (N,) bool: where what it is told changed."""
        told = ~self.resting
        events = instruction_events(prev, cur)
        completed = told & events[np.arange(self.num_envs), self._targets[self.index]]
        self.step += 1
        timed_out = told & ~completed & (self.step - self.start >= self.schedule.timeout)
        for i in np.flatnonzero(completed | timed_out):
            self._close(i, COMPLETED if completed[i] else TIMED_OUT)
            self.index[i] = self._next(i)
        tired, rested = self._rest_changes(cur)
        for i in np.flatnonzero(tired):
            self._close(i, INTERRUPTED)
        for i in np.flatnonzero(rested):
            self.start[i] = self.step[i]
            self.index[i] = self._next(i)
        self.resting = (self.resting | tired) & ~rested
        changed = completed | timed_out | tired | rested
        if changed.any():
            self.expert.instruct(self.current, changed)
        return changed

    def finish(self, i: int) -> list[list]:
        """Env ``i``'s episode is over: its segments, the last one "ended" (if it had actions).
        An env left without a next episode still steps: what it does later is not kept."""
        if not self.resting[i]:
            self._close(i, ENDED)
        segments, self._segments[i] = self._segments[i], []
        return segments

    def _rest_changes(self, cur: State) -> tuple[np.ndarray, np.ndarray]:
        """(N,) bool twice: where a rest begins (night, or energy at ``energy_low``) and where
        one is over (full day, awake, energy above ``energy_low``)."""
        cfg = self.expert.config
        light, energy = cur["light_level"], cur["player_vitals"][:, ENERGY]
        tired = ~self.resting & ((light < cfg.night_light) | (energy <= cfg.energy_low))
        awake = ~cur["player_sleeping"].astype(bool)
        rested = self.resting & (light >= cfg.dawn_light) & (energy > cfg.energy_low) & awake
        return tired, rested

    def _close(self, i: int, outcome: str) -> None:
        if self.step[i] > self.start[i]:
            caption_id = int(self._ids[self.index[i]])
            self._segments[i].append([int(self.start[i]), int(self.step[i]), caption_id, outcome])
        self.start[i] = self.step[i]

    def _next(self, i: int) -> int:
        """A caption other than the current one (when there is another)."""
        if len(self.schedule.captions) == 1:
            return 0
        return self.schedule.draw(self._rngs[i], int(self.index[i]))


def tally_outcomes(segments: list[list], schedule: InstructionSchedule) -> dict[str, dict]:
    """Per caption: how many segments ended in each outcome, and the actions the completed
    ones took (``completed_actions``; their mean is the time to complete)."""
    texts = dict(zip(schedule.caption_ids, schedule.captions))
    counts = {c: {**dict.fromkeys(OUTCOMES, 0), "completed_actions": 0} for c in schedule.captions}
    for start, stop, caption_id, outcome in segments:
        row = counts[texts[caption_id]]
        row[outcome] += 1
        if outcome == COMPLETED:
            row["completed_actions"] += stop - start
    return counts


def add_tallies(tallies: list[dict[str, dict]]) -> dict[str, dict]:
    """The sum of ``tally_outcomes`` results (of episodes, shards or datasets)."""
    total: dict[str, dict] = {}
    for tally in tallies:
        for caption, row in tally.items():
            into = total.setdefault(caption, dict.fromkeys(row, 0))
            for key, value in row.items():
                into[key] += value
    return total
