"""Combat rules: Attacked By and Block Attack.

Zombies hit from an adjacent tile; skeletons hit with arrows that fly straight and hurt the
player when their next tile is the player's. Both games resolve the player's action first,
then the mobs, so an attack at step t is judged against the player's tile at t+1.

An attack resets the attacker's cooldown (column 2 of ``*_status``) to a fixed value that it
otherwise only counts down from, so cooldown == that value at t+1 means "attacked at t".
"""

from __future__ import annotations

import numpy as np

from zoo.captions.rules import PLACEABLE_ITEMS, Window, register_rule
from zoo.envs.constants import SKELETON_RELOAD, ZOMBIE_ATTACK_COOLDOWN

ATTACKED_BY = "attacked by {mob}"
BLOCK_ATTACK = "block attack from {mob} with {item}"

ATTACKERS = ("zombie", "skeleton")
HEALTH = 0
COOLDOWN = 2  # column of *_status


def _manhattan(a: np.ndarray, b: np.ndarray) -> int:
    return int(np.abs(np.asarray(a, np.int64) - np.asarray(b, np.int64)).sum())


def _attacked_adjacent(w: Window, mob: str, reset: int) -> bool:
    """A live {mob} next to the player at t+1 has the cooldown an attack at t leaves.

    Neither game moves a mob on the step it attacks, and the player has already moved, so the
    attacker stands next to the player's tile at t+1.
    """
    key = f"{mob}s"
    status, positions = w.state(f"{key}_status", 1), w.state(f"{key}_pos", 1)
    player = w.pos(1)
    return any(
        status[i, COOLDOWN] == reset and _manhattan(positions[i], player) == 1
        for i in np.flatnonzero(status[:, 0] > 0)
    )


@register_rule("attacked_by", "combat", ATTACKED_BY, [{"mob": m} for m in ATTACKERS])
def attacked_by(w: Window) -> list[str]:
    """Health dropped between t and t+1 and an attack explains it.

    zombie: an adjacent zombie attacked at t (its cooldown reset), so health lost to hunger or
    thirst next to a zombie still cooling down is not an attack. skeleton: an arrow at t was
    headed into the player's tile at t or t+1 (position + heading lands on it), or an adjacent
    skeleton shot at t (its reload reset): Craftax-Classic spawns that arrow on the skeleton's
    tile and moves it into the player within the same step, so it is never seen in flight.
    """
    if w.state("player_vitals", 1)[HEALTH] >= w.state("player_vitals")[HEALTH]:
        return []
    out = []
    if _attacked_adjacent(w, "zombie", ZOMBIE_ATTACK_COOLDOWN):
        out.append(ATTACKED_BY.format(mob="zombie"))
    status, arrows, heading = w.state("arrows_status"), w.state("arrows_pos"), w.state("arrows_dir")
    targets = (w.pos(), w.pos(1))
    in_flight = any(
        any(np.array_equal(arrows[i].astype(np.int64) + heading[i], p) for p in targets)
        for i in np.flatnonzero(status[:, 0] > 0)
    )
    if in_flight or _attacked_adjacent(w, "skeleton", SKELETON_RELOAD):
        out.append(ATTACKED_BY.format(mob="skeleton"))
    return out


@register_rule(
    "block_attack",
    "combat",
    BLOCK_ATTACK,
    [{"mob": m, "item": i} for m in ATTACKERS for i in PLACEABLE_ITEMS],
)
def block_attack(w: Window) -> list[str]:
    """A block placed at t stands between the player and an attack under way.

    zombie: a zombie within `block_radius` at t that did not retreat over the clip, and the
    placed tile lies on a shortest grid path from it to the player (distance zombie->block is
    one less than zombie->player). skeleton: an arrow flying at the player (within
    `arrow_radius`) has the placed tile on its line before the player, or a skeleton within
    `block_radius` in the player's row or column has it between them.
    """
    placed = w.placement()
    if placed is None:
        return []
    block, player = np.array(placed.tile), w.pos()
    out = []
    near_zombie = w.nearest("zombie") <= w.params.block_radius
    closing = w.nearest("zombie") <= w.nearest("zombie", -w.params.history)
    if near_zombie and closing:
        for zombie in w.episode.mobs("zombie", w.t):
            if _manhattan(zombie, block) == _manhattan(zombie, player) - 1:
                out.append(BLOCK_ATTACK.format(mob="zombie", item=placed.item))
                break
    shooters = list(w.incoming_arrows())
    shooters += [
        s
        for s in w.episode.mobs("skeleton", w.t)
        if _manhattan(s, player) <= w.params.block_radius and (s == player).any()
    ]
    for source in shooters:
        in_line = (source == block).any()
        if in_line and _manhattan(source, block) == _manhattan(source, player) - 1:
            out.append(BLOCK_ATTACK.format(mob="skeleton", item=placed.item))
            break
    return out
