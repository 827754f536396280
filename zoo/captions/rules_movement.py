"""Movement rules: Stay, Move, Approach, Flee, Explore, judged over the clip o_{t-4..t+1}.

Distances are Manhattan distances on the grid (mobs and the player move one tile per step).
North is up the map (row - 1), east is right (col + 1).
"""

from __future__ import annotations

import numpy as np

from zoo.captions.rules import HOSTILE_MOBS, NO_MOB, Window, direction_offset, register_rule
from zoo.envs.constants import Action

STAY = "stay"
MOVE = "move to {dir}"
APPROACH = "approach {mob}"
FLEE = "flee from {mob}"
EXPLORE = "go explore"

DIRECTIONS = {
    "north": int(Action.MOVE_UP),
    "south": int(Action.MOVE_DOWN),
    "east": int(Action.MOVE_RIGHT),
    "west": int(Action.MOVE_LEFT),
}
APPROACHABLE = ("cow", "zombie", "skeleton")
FLEEABLE = (*HOSTILE_MOBS, "arrow")


@register_rule("stay", "movement", STAY)
def stay(w: Window) -> list[str]:
    """Every action of the clip (t-4..t) was NOOP, the player stayed on one tile through
    t+1 and was awake throughout (sleeping is captioned "go to sleep", not "stay")."""
    actions = w.episode.actions[w.start : w.t + 1]
    if (actions != Action.NOOP).any():
        return []
    positions = w.episode.pos[w.start : w.t + 2]
    if (positions != positions[0]).any():
        return []
    if any(w.asleep(dt) for dt in range(-w.params.history, 2)):
        return []
    return [STAY]


@register_rule("move", "movement", MOVE, [{"dir": d} for d in DIRECTIONS])
def move(w: Window) -> list[str]:
    """Action t moved the player one tile in direction {dir}, and over the clip (t-4 -> t+1)
    the player travelled at least `move_min_displacement` tiles that way, with that axis
    dominating the net displacement."""
    for name, action in DIRECTIONS.items():
        if w.action != action:
            continue
        offset = np.array(direction_offset(action))
        if not np.array_equal(w.pos(1) - w.pos(), offset):
            return []
        net = w.pos(1) - w.pos(-w.params.history)
        along = int(net @ offset)
        across = int(abs(net).sum()) - abs(along)
        if along >= w.params.move_min_displacement and along > across:
            return [MOVE.format(dir=name)]
    return []


@register_rule("approach", "movement", APPROACH, [{"mob": m} for m in APPROACHABLE])
def approach(w: Window) -> list[str]:
    """The player moved at t and got closer to the nearest {mob}; over the clip the distance
    shrank by at least `approach_min_gain` and ends at most `approach_radius` tiles."""
    if not w.episode.moved[w.t]:
        return []
    out = []
    for mob in APPROACHABLE:
        start, now, end = w.nearest(mob, -w.params.history), w.nearest(mob), w.nearest(mob, 1)
        if (
            start < NO_MOB  # present all along: a mob appearing nearby is not approached
            and end < now
            and end <= w.params.approach_radius
            and start - end >= w.params.approach_min_gain
        ):
            out.append(APPROACH.format(mob=mob))
    return out


@register_rule("flee", "movement", FLEE, [{"mob": m} for m in FLEEABLE])
def flee(w: Window) -> list[str]:
    """The player moved away from danger at t.

    zombie/skeleton (hostile): the nearest one was within `flee_radius` at the clip's start,
    the player's move at t increased the distance and over the clip it grew by at least
    `flee_min_gain`. arrow: an arrow flying straight at the player at t (within
    `arrow_radius`) no longer has the player in its line at t+1 (a side step), and the player
    took no damage.
    """
    if not w.episode.moved[w.t]:
        return []
    out = []
    for mob in HOSTILE_MOBS:
        start, now, end = w.nearest(mob, -w.params.history), w.nearest(mob), w.nearest(mob, 1)
        gone = end >= NO_MOB  # killed or despawned, not outrun
        near = start <= w.params.flee_radius
        if near and not gone and end > now and end - start >= w.params.flee_min_gain:
            out.append(FLEE.format(mob=mob))
    vitals0, vitals1 = w.state("player_vitals"), w.state("player_vitals", 1)
    if vitals1[0] >= vitals0[0]:
        after = w.pos(1)
        for arrow in w.incoming_arrows():
            if after[0] != arrow[0] and after[1] != arrow[1]:
                out.append(FLEE.format(mob="arrow"))
                break
    return out


@register_rule("explore", "movement", EXPLORE)
def explore(w: Window) -> list[str]:
    """Travel into new ground: the player changed tile on at least `explore_min_moves` of the
    clip's steps, got at least `explore_min_displacement` tiles away from where the clip
    started, and the tile reached at t+1 was not visited in the previous `explore_memory`
    steps."""
    p = w.params
    if not w.episode.moved[w.t] or w.episode.moved[w.start : w.t + 1].sum() < p.explore_min_moves:
        return []
    if int(abs(w.pos(1) - w.pos(-p.history)).sum()) < p.explore_min_displacement:
        return []
    seen = w.episode.pos[max(0, w.t - p.explore_memory) : w.t + 1]
    if (seen == w.pos(1)).all(axis=1).any():
        return []
    return [EXPLORE]
