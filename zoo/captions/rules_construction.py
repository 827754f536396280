"""Construction rules: Shelter, Path, Tunnel (the expert's emergent building behaviours).

"Blocked" means no mob can walk there: anything but grass, sand and path (zombies and cows
walk only on those; arrows stop at solid blocks).
"""

from __future__ import annotations

import numpy as np

from zoo.captions.rules import HOSTILE_MOBS, PLACEABLE_ITEMS, Window, register_rule
from zoo.envs.constants import Action, Block

SHELTER = "place {item} to build shelter"
PATH = "build path over {material}"
TUNNEL = "dig a tunnel"

PATH_MATERIALS = {"water": int(Block.WATER), "lava": int(Block.LAVA)}
ROCK = frozenset(int(b) for b in (Block.STONE, Block.COAL, Block.IRON, Block.DIAMOND))


@register_rule("shelter", "construction", SHELTER, [{"item": i} for i in PLACEABLE_ITEMS])
def shelter(w: Window) -> list[str]:
    """A placement at t closed one of the player's sides and leaves it enclosed: all four
    neighbours blocked at t+1, or three of them while a hostile mob is within
    `shelter_threat_radius` or it is night (light below `night_light`)."""
    placed = w.placement()
    if placed is None:
        return []
    closed = w.blocked_sides(1)
    if closed == 4:
        return [SHELTER.format(item=placed.item)]
    threat = any(w.nearest(m, 1) <= w.params.shelter_threat_radius for m in HOSTILE_MOBS)
    night = float(w.state("light_level", 1)) < w.params.night_light
    if closed == 3 and (threat or night):
        return [SHELTER.format(item=placed.item)]
    return []


@register_rule("path", "construction", PATH, [{"material": m} for m in PATH_MATERIALS])
def path(w: Window) -> list[str]:
    """The player stepped at t onto a PATH tile that was water or lava within
    the previous `path_memory` steps: it was filled with stone (and mined back to path) and is
    now walked over. {material} is the most recent liquid the tile held."""
    if not w.episode.moved[w.t] or w.episode.tile(w.t + 1, w.pos(1)) != Block.PATH:
        return []
    r, c = (int(v) for v in w.pos(1))
    history = w.episode.map[max(0, w.t - w.params.path_memory) : w.t + 1, r, c]
    for block in history[::-1]:
        for name, liquid in PATH_MATERIALS.items():
            if block == liquid:
                return [PATH.format(material=name)]
    return []


@register_rule("tunnel", "construction", TUNNEL)
def tunnel(w: Window) -> list[str]:
    """Digging forward through rock: DO at t mined the facing stone/ore (it became PATH), the
    tile the player stands on was itself rock earlier in the clip (it dug in and stepped
    forward), and at least one side of the player, across the digging direction, is rock."""
    if w.action != Action.DO or w.asleep():
        return []
    target = w.facing_tile()
    if w.episode.tile(w.t, target) not in ROCK or w.episode.tile(w.t + 1, target) != Block.PATH:
        return []
    here = w.pos()
    if not any(w.episode.tile(t, here) in ROCK for t in range(w.start, w.t)):
        return []
    ahead = target - here
    sides = (here + np.array([ahead[1], ahead[0]]), here - np.array([ahead[1], ahead[0]]))
    if any(w.episode.tile(w.t, side) in ROCK for side in sides):
        return [TUNNEL]
    return []
