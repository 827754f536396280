"""Packed hindsight relabelling for C-Steve-1: which later step's clip is each step's goal.

STEVE-1's packed relabelling cuts an episode into pieces of a random length in
[min_gap, max_gap]; every step of a piece is given the C-CLIP embedding of the clip at the
piece's last step as its goal, so the policy learns to act towards what the expert did reach a
few steps later. In Crafter distinct events follow each other within a few steps (place table,
craft wood pickaxe, craft wood sword in 3 steps), so a piece of random length often ends after
the next event and its goal shows a later one. The paper's event-based variant ("Dataset
Generation", §4.3) samples goals inside event segments: maximal runs of consecutive steps with
the same CrafterCaption caption.

Our reading of it, step by step, from the first step t of a piece:
1. the window of goal steps is [t + min_gap - 1, t + max_gap - 1], cut at the episode's end
   (so a goal is 1..max_gap steps ahead, counting the step itself);
2. ``event``: the first event segment that reaches into the window is the goal's segment, and
   the goal is drawn uniformly from its steps inside the window. A segment after the window
   is never used (it would break the gap); a window without any caption falls back to step 3.
   ``event_any``: the goal's segment is drawn uniformly from all segments reaching into the
   window, so an event also labels the steps that lead up to it (below);
3. ``plain`` (and the fallback): the goal is drawn uniformly from the window (STEVE-1);
4. every step t..g gets goal g; the next piece starts at g + 1. With ``uncond_per: piece``
   each piece is unconditional with probability ``uncond_prob`` (classifier-free guidance needs
   the policy without a goal); with ``uncond_per: sequence`` (STEVE-1's: its data loader zeroes
   a whole training chunk's goals) no piece is, and ``drop_sequence_goals`` zeroes whole
   training sequences instead.
Taking the *first* segment in the window is what keeps one goal from spanning two events: the
steps before "place table" are labelled with the table, not with the pickaxe made just after.
Its cost (docs/results/csteve1.md, C-Steve-1): "craft stone pickaxe" then labels only steps
where a table already stands, so the goal means "craft now" and a task that starts without a
table is outside what it was trained on. ``event_any`` keeps goals inside event segments but
lets the pickaxe also label the run-up that places the table.

Step t's goal clip is o_{g-4..g+1} (``zoo goals embed``), which holds the outcome of action g.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

RelabelMode = Literal["event", "event_any", "plain"]
RELABEL_MODES: tuple[str, ...] = ("event", "event_any", "plain")
UncondPer = Literal["piece", "sequence"]
UNCOND_PER: tuple[str, ...] = ("piece", "sequence")
NO_CAPTION = -1


@dataclass(frozen=True)
class RelabelParams:
    """The paper's C-Steve-1 table: min/max steps between goals 1/10, unconditional 0.1."""

    mode: RelabelMode = "event"
    """``event``: goals in the first caption segment of the window (the paper's); ``event_any``:
    in any segment of the window; ``plain``: STEVE-1's packing."""
    min_gap: int = 1
    """Fewest steps a goal is ahead of the first step that gets it (the step itself counts)."""
    max_gap: int = 10
    """Most steps a goal is ahead of the first step that gets it."""
    uncond_prob: float = 0.1
    """Share of pieces (or sequences) trained without a goal (classifier-free guidance)."""
    uncond_per: UncondPer = "piece"
    """What ``uncond_prob`` draws: ``piece`` (each 1-10-step relabelled piece) or ``sequence``
    (a whole training sequence, STEVE-1's)."""

    def __post_init__(self) -> None:
        if self.mode not in RELABEL_MODES:
            raise ValueError(f"relabel mode {self.mode!r}: expected one of {RELABEL_MODES}")
        if not 1 <= self.min_gap <= self.max_gap:
            raise ValueError(
                f"min_gap={self.min_gap} and max_gap={self.max_gap}: need 1 <= min_gap <= max_gap"
            )
        if not 0.0 <= self.uncond_prob <= 1.0:
            raise ValueError(f"uncond_prob={self.uncond_prob} must lie in [0, 1]")
        if self.uncond_per not in UNCOND_PER:
            raise ValueError(f"uncond_per={self.uncond_per!r}: expected one of {UNCOND_PER}")

    @property
    def piece_uncond_prob(self) -> float:
        """The chance that one relabelled piece goes without a goal."""
        return self.uncond_prob if self.uncond_per == "piece" else 0.0


@dataclass
class Relabelling:
    """Per step of one episode: its goal step, whether it has a goal, whether the goal is an event."""

    goal_step: np.ndarray  # (T,) int64, goal_step[t] >= t
    conditioned: np.ndarray  # (T,) bool, False on unconditional pieces
    from_event: np.ndarray  # (T,) bool, the goal was drawn inside an event segment


def _segments_in_window(captions: np.ndarray, lo: int, hi: int) -> list[tuple[int, int]]:
    """First and last step (inclusive) of each event segment's part inside [lo, hi], in order."""
    window = captions[lo : hi + 1]
    starts = np.flatnonzero((window != NO_CAPTION) & (window != np.r_[NO_CAPTION, window[:-1]]))
    ends = np.r_[starts[1:] - 1, len(window) - 1]
    segments = []
    for start, end in zip(starts, ends):
        while window[end] != window[start]:  # trailing steps without a caption
            end -= 1
        segments.append((lo + int(start), lo + int(end)))
    return segments


def _goal_segment(
    captions: np.ndarray, lo: int, hi: int, mode: RelabelMode, rng: np.random.Generator
) -> tuple[int, int] | None:
    """The event segment (its part in [lo, hi]) that holds the goal; None: draw in the window."""
    if mode == "plain":
        return None
    segments = _segments_in_window(captions, lo, hi)
    if not segments:
        return None
    if mode == "event":
        return segments[0]
    return segments[int(rng.integers(len(segments)))]


def relabel_episode(
    captions: np.ndarray, params: RelabelParams, rng: np.random.Generator
) -> Relabelling:
    """Goals for every step of one episode from its per-step captions (-1: no caption).

    The result depends only on ``captions``, ``params`` and ``rng``: one episode's goals never
    point into another episode.
    """
    captions = np.asarray(captions)
    if captions.ndim != 1:
        raise ValueError(f"captions must be one episode's (T,) caption ids, got {captions.shape}")
    length = len(captions)
    goal_step = np.empty(length, np.int64)
    conditioned = np.empty(length, bool)
    from_event = np.zeros(length, bool)
    t = 0
    while t < length:
        lo = min(t + params.min_gap - 1, length - 1)
        hi = min(t + params.max_gap - 1, length - 1)
        segment = _goal_segment(captions, lo, hi, params.mode, rng)
        start, end = segment if segment is not None else (lo, hi)
        goal = int(rng.integers(start, end + 1))
        goal_step[t : goal + 1] = goal
        conditioned[t : goal + 1] = rng.random() >= params.piece_uncond_prob
        from_event[t : goal + 1] = segment is not None
        t = goal + 1
    return Relabelling(goal_step, conditioned, from_event)


def drop_sequence_goals(sequence: dict[str, np.ndarray], uncond_prob: float, seed: int,
                        epoch: int) -> dict[str, np.ndarray]:
    """``sequence`` with every goal zeroed and masked, with probability ``uncond_prob``.

    The draw is a function of (seed, epoch, the sequence's first episode and step): the same
    in any worker or rank that packs it.
    """
    start = [int(sequence["episode"][0]), int(sequence["step"][0])]
    if np.random.default_rng([seed, epoch, *start, 0x0C06D]).random() >= uncond_prob:
        return sequence
    return {
        **sequence,
        "goal": np.zeros_like(sequence["goal"]),
        "goal_mask": np.zeros_like(sequence["goal_mask"]),
    }


def episode_rng(seed: int, epoch: int, episode: int) -> np.random.Generator:
    """The relabelling stream of one episode in one epoch: new goals every epoch, the same in
    any worker, rank or order the episode is read in."""
    return np.random.default_rng([seed, epoch, episode, 0x5EE7E])


__all__ = [
    "NO_CAPTION",
    "RELABEL_MODES",
    "RelabelMode",
    "RelabelParams",
    "Relabelling",
    "UNCOND_PER",
    "UncondPer",
    "drop_sequence_goals",
    "episode_rng",
    "relabel_episode",
]
