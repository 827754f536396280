"""Why an episode ended, read from the last two states: a diagnosis for the report.

Crafter ends an episode when health reaches 0 (or the player steps onto lava) or at the step
limit. Health falls for three reasons: a zombie's hit, a skeleton's arrow, and a need (food,
drink or energy) at 0. A BC agent's score is often capped by one of them (it dies before it
can sleep or mine), so the report counts which. The attribution is a rule, not the game's own
bookkeeping: a zombie or arrow next to the player in either state is blamed first, then a need
at 0; a death with neither is "other".
"""

from __future__ import annotations

import numpy as np

from zoo.envs.constants import Block
from zoo.envs.schema import State

DEATH_CAUSES: tuple[str, ...] = ("survived", "lava", "zombie", "arrow", "needs", "other")
_HEALTH, _NEEDS = 0, slice(1, 4)  # player_vitals = [health, food, drink, energy]


def _adjacent(state: State, i: int, kind: str) -> bool:
    """Whether an entity of ``kind`` (zombies, arrows) is within one tile of player i (8-way)."""
    alive = state[f"{kind}_status"][i, :, 0] > 0
    if not alive.any():
        return False
    gap = np.abs(state[f"{kind}_pos"][i][alive].astype(int) - state["player_pos"][i].astype(int))
    return bool((gap.max(axis=1) <= 1).any())


def death_cause(before: State, after: State, i: int) -> str:
    """Cause of the end of env i's episode: one of ``DEATH_CAUSES``.

    ``before`` is the batched state the last action was taken in, ``after`` the final one.
    """
    row, col = after["player_pos"][i].astype(int)
    if after["map"][i, row, col] == Block.LAVA:
        return "lava"
    if after["player_vitals"][i, _HEALTH] > 0:
        return "survived"
    if _adjacent(before, i, "zombies") or _adjacent(after, i, "zombies"):
        return "zombie"
    if _adjacent(before, i, "arrows") or _adjacent(after, i, "arrows"):
        return "arrow"
    if (before["player_vitals"][i, _NEEDS] == 0).any():
        return "needs"
    return "other"


def death_shares(causes: list[str]) -> dict[str, float]:
    """Percentage of episodes per cause, every cause listed (0.0 when none)."""
    unknown = sorted(set(causes) - set(DEATH_CAUSES))
    if unknown:
        raise ValueError(f"unknown death causes {unknown}; expected some of {DEATH_CAUSES}")
    n = max(len(causes), 1)
    return {cause: 100.0 * causes.count(cause) / n for cause in DEATH_CAUSES}
