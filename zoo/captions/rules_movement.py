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


def _track(w: Window, mob: str) -> np.ndarray | None:
    """(history + 2, 2) positions over t-history..t+1 of the {mob} nearest the player at the
    clip's start, followed as the live one of its kind nearest its last tile (mobs move at most
    one tile a step; crafter's export orders slots by distance, so slots are no identity).
    None when there is none at the start or it is lost (killed or despawned, not outrun)."""
    seen = w.episode.mobs(mob, w.start)
    if not len(seen):
        return None
    path = [seen[np.abs(seen - w.pos(-w.params.history)).sum(axis=1).argmin()]]
    for step in range(w.start + 1, w.t + 2):
        seen = w.episode.mobs(mob, step)
        gap = np.abs(seen - path[-1]).sum(axis=1)
        if not len(seen) or gap.min() > 1:
            return None
        path.append(seen[gap.argmin()])
    return np.array(path)


def _fled(w: Window, mob: str) -> bool:
    """The player ran from a pursuing hostile {mob}; see `flee`."""
    mob_path = _track(w, mob)
    if mob_path is None:
        return False
    player = w.episode.pos[w.start : w.t + 2]
    dist = np.abs(player - mob_path).sum(axis=1)
    before_mob_step = np.abs(player[1:] - mob_path[:-1]).sum(axis=1)
    stepped_away = (before_mob_step > dist[:-1]).all()
    pursued = (dist[1:] < before_mob_step).any() or (
        mob == "skeleton"
        and any(next(w.incoming_arrows(dt), None) is not None for dt in range(-w.params.history, 1))
    )
    return bool(
        dist[0] <= w.params.flee_radius
        and stepped_away
        and pursued
        and (np.diff(dist) >= 0).all()
        and dist[-1] > dist[-2]
        and dist[-1] - dist[0] >= w.params.flee_min_gain
    )


@register_rule("flee", "movement", FLEE, [{"mob": m} for m in FLEEABLE])
def flee(w: Window) -> list[str]:
    """The player moved away from danger at t.

    zombie/skeleton (hostile), following the one nearest the player at the clip's start:
    - threat: it was within `flee_radius` at the clip's start;
    - running away: on every step of the clip (t-4..t) the player changed tile, each step taking
      it farther from where the mob stood (walking towards or past a mob is not fleeing);
    - pursuit: the mob came after the player: at least once its own step brought it closer
      (a chase), or, for a skeleton, which keeps its distance and shoots, an arrow flew at the
      player during the clip (walking away from a mob that stands still is not fleeing);
    - escape: the distance never shrank over the clip, grew at t, and grew by at least
      `flee_min_gain` from the clip's start to t+1; a mob killed or despawned is not outrun.
    arrow: an arrow flying straight at the player at t (within `arrow_radius`) no longer has
    the player in its line at t+1 (a side step), and the player took no damage.
    """
    if not w.episode.moved[w.t]:
        return []
    out = [FLEE.format(mob=mob) for mob in HOSTILE_MOBS if _fled(w, mob)]
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
