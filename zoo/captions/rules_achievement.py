"""Achievement rules: Harvest, Place, Craft, Kill, Sleep (they cover all 22 achievements).

Each fires on the step whose action produced the effect, judged from the state change, so
a blocked or no-effect action (mining stone without a pickaxe) is not captioned.
"""

from __future__ import annotations

import numpy as np

from zoo.captions.rules import PLACEABLE_ITEMS, Window, register_rule
from zoo.envs.constants import Action, Block, Item

HARVEST = "obtain {item}"
PLACE = "place {item} on {material}"
CRAFT = "craft {item}"
KILL = "kill {mob}"
SLEEP = "go to sleep"

# Inventory items gathered with DO; ores also leave PATH behind (seen even at the 9-item cap).
HARVEST_INVENTORY = {
    "wood": (Item.WOOD, None),
    "stone": (Item.STONE, Block.STONE),
    "coal": (Item.COAL, Block.COAL),
    "iron": (Item.IRON, Block.IRON),
    "diamond": (Item.DIAMOND, Block.DIAMOND),
    "sapling": (Item.SAPLING, None),
}
HARVEST_ITEMS = (*HARVEST_INVENTORY, "drink", "ripe plant")
VITAL_DRINK = 2

# Where each block may be put in Craftax-Classic (crafter forbids table/furnace on lava).
PLACE_MATERIALS = {
    "stone": ("grass", "sand", "path", "water", "lava"),
    "table": ("grass", "sand", "path", "lava"),
    "furnace": ("grass", "sand", "path", "lava"),
    "plant": ("grass",),
}
CRAFT_ACTIONS = {
    int(Action.MAKE_WOOD_PICKAXE): ("wood pickaxe", Item.WOOD_PICKAXE),
    int(Action.MAKE_STONE_PICKAXE): ("stone pickaxe", Item.STONE_PICKAXE),
    int(Action.MAKE_IRON_PICKAXE): ("iron pickaxe", Item.IRON_PICKAXE),
    int(Action.MAKE_WOOD_SWORD): ("wood sword", Item.WOOD_SWORD),
    int(Action.MAKE_STONE_SWORD): ("stone sword", Item.STONE_SWORD),
    int(Action.MAKE_IRON_SWORD): ("iron sword", Item.IRON_SWORD),
}
KILLABLE = ("cow", "zombie", "skeleton")


@register_rule("harvest", "achievement", HARVEST, [{"item": i} for i in HARVEST_ITEMS])
def harvest(w: Window) -> list[str]:
    """DO on the facing tile yielded a resource.

    wood/sapling: that inventory count rose. stone/coal/iron/diamond: the count rose, or the
    facing tile turned from that ore into PATH (mining at the 9-item cap). drink: the facing
    tile is WATER and the drink vital rose. ripe plant: the facing tile went RIPE_PLANT -> PLANT
    (the plant was eaten and regrows).
    """
    if w.action != Action.DO or w.asleep():
        return []
    inv0, inv1 = w.state("inventory"), w.state("inventory", 1)
    target = w.facing_tile()
    before, after = w.episode.tile(w.t, target), w.episode.tile(w.t + 1, target)
    out = []
    for name, (item, ore) in HARVEST_INVENTORY.items():
        mined = ore is not None and before == ore and after == Block.PATH
        if inv1[item] > inv0[item] or mined:
            out.append(HARVEST.format(item=name))
    vitals0, vitals1 = w.state("player_vitals"), w.state("player_vitals", 1)
    if before == Block.WATER and vitals1[VITAL_DRINK] > vitals0[VITAL_DRINK]:
        out.append(HARVEST.format(item="drink"))
    if before == Block.RIPE_PLANT and after == Block.PLANT:
        out.append(HARVEST.format(item="ripe plant"))
    return out


@register_rule(
    "place",
    "achievement",
    PLACE,
    [{"item": i, "material": m} for i in PLACEABLE_ITEMS for m in PLACE_MATERIALS[i]],
)
def place(w: Window) -> list[str]:
    """A place action changed the facing tile into the placed block; {material} is what it
    covered. Placements on materials outside PLACE_MATERIALS (none in either game) are skipped."""
    placed = w.placement()
    if placed is None:
        return []
    material = Block(placed.material).name.lower()
    if material not in PLACE_MATERIALS[placed.item]:
        return []
    return [PLACE.format(item=placed.item, material=material)]


@register_rule(
    "craft", "achievement", CRAFT, [{"item": name} for name, _ in CRAFT_ACTIONS.values()]
)
def craft(w: Window) -> list[str]:
    """A make action added the tool to the inventory, or spent wood (every recipe does) when
    the tool count was already at its cap."""
    made = CRAFT_ACTIONS.get(w.action)
    if made is None or w.asleep():
        return []
    name, item = made
    inv0, inv1 = w.state("inventory"), w.state("inventory", 1)
    if inv1[item] > inv0[item] or inv1[Item.WOOD] < inv0[Item.WOOD]:
        return [CRAFT.format(item=name)]
    return []


@register_rule("kill", "achievement", KILL, [{"mob": m} for m in KILLABLE])
def kill(w: Window) -> list[str]:
    """DO hit a mob standing on the facing tile at t, and at t+1 no mob of that kind could be
    it: a survivor is at most one tile from that tile (mobs move one tile per step) and has less
    health than the victim had (the hit costs at least 1; mobs never heal), so an unhurt
    same-kind bystander next to the tile does not hide the kill."""
    if w.action != Action.DO or w.asleep():
        return []
    target = w.facing_tile()
    out = []
    for mob in KILLABLE:
        key = f"{mob}s"
        status, positions = w.state(f"{key}_status"), w.state(f"{key}_pos")
        hit = (status[:, 0] > 0) & (positions == target).all(axis=1)
        if not hit.any():
            continue
        health = status[hit.argmax(), 1]  # one mob per tile
        status1, positions1 = w.state(f"{key}_status", 1), w.state(f"{key}_pos", 1)
        survived = any(
            status1[i, 1] < health and abs(positions1[i] - target).sum() <= 1
            for i in np.flatnonzero(status1[:, 0] > 0)
        )
        if not survived:
            out.append(KILL.format(mob=mob))
    return out


@register_rule("sleep", "achievement", SLEEP)
def sleep(w: Window) -> list[str]:
    """The sleep action put an awake player to sleep (energy below maximum)."""
    if w.action == Action.SLEEP and not w.asleep() and w.asleep(1):
        return [SLEEP]
    return []
