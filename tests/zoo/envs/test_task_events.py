"""Repeats at the cap of 9: both games still count a collect, craft or drink whose item or
vital is full, so ``achievement_events`` must see it from what else the act changed. Each
case steps the real game into the situation (the achievement already unlocked, the item at 9,
the block in front of the player) and acts once."""

from __future__ import annotations

import numpy as np
import pytest

from zoo.envs.base import GameEnv
from zoo.envs.constants import ITEM_NAMES, Achievement, Action, Block, Item
from zoo.envs.schema import State, empty_state
from zoo.envs.tasks import achievement_events

GAMES = ["crafter", pytest.param("craftax", marks=pytest.mark.slow)]
A = Achievement

# (block faced, inventory, action, the achievement it repeats)
CASES = {
    "wood": (Block.TREE, {Item.WOOD: 9}, Action.DO, A.COLLECT_WOOD),
    "stone": (Block.STONE, {Item.STONE: 9, Item.WOOD_PICKAXE: 1}, Action.DO, A.COLLECT_STONE),
    "coal": (Block.COAL, {Item.COAL: 9, Item.WOOD_PICKAXE: 1}, Action.DO, A.COLLECT_COAL),
    "iron": (Block.IRON, {Item.IRON: 9, Item.STONE_PICKAXE: 1}, Action.DO, A.COLLECT_IRON),
    "diamond": (
        Block.DIAMOND, {Item.DIAMOND: 9, Item.IRON_PICKAXE: 1}, Action.DO, A.COLLECT_DIAMOND,
    ),
    "wood_pickaxe": (
        Block.TABLE, {Item.WOOD: 3, Item.WOOD_PICKAXE: 9}, Action.MAKE_WOOD_PICKAXE,
        A.MAKE_WOOD_PICKAXE,
    ),
    "wood_sword": (
        Block.TABLE, {Item.WOOD: 3, Item.WOOD_SWORD: 9, Item.WOOD_PICKAXE: 2},
        Action.MAKE_WOOD_SWORD, A.MAKE_WOOD_SWORD,
    ),
    "stone_pickaxe": (
        Block.TABLE, {Item.WOOD: 3, Item.STONE: 3, Item.STONE_PICKAXE: 9},
        Action.MAKE_STONE_PICKAXE, A.MAKE_STONE_PICKAXE,
    ),
    "drink": (Block.WATER, {}, Action.DO, A.COLLECT_DRINK),
    # the sibling of a full tool: its count rises, so the full pickaxe must not be credited
    "wood_sword_beside_a_full_pickaxe": (
        Block.TABLE, {Item.WOOD: 3, Item.WOOD_PICKAXE: 9}, Action.MAKE_WOOD_SWORD,
        A.MAKE_WOOD_SWORD,
    ),
}


@pytest.fixture
def game(request):
    """The session's shared env of the game named by the test's parameter."""
    return request.getfixturevalue(f"{request.param}_env")


def _set_up_crafter(game: GameEnv, block: Block, inventory: dict[Item, int], ach: Achievement) -> None:
    env = game.raw_state[0]
    player, world = env._player, env._world
    target = tuple(player.pos + np.array(player.facing))
    if world[target][1] is not None:
        world.remove(world[target][1])
    world[target] = block.name.lower()
    player.inventory.update({ITEM_NAMES[item]: n for item, n in inventory.items()})
    player.inventory["drink"] = 9
    player._thirst = 10  # mid-way, so a drink restarts it
    player.achievements[ach.name.lower()] = 1


def _set_up_craftax(game: GameEnv, block: Block, inventory: dict[Item, int], ach: Achievement) -> None:
    from craftax.craftax_classic.constants import DIRECTIONS

    s = game.raw_state
    row, col = (int(v) for v in s.player_position[0] + DIRECTIONS[int(s.player_direction[0])])
    inv = {ITEM_NAMES[item]: getattr(s.inventory, ITEM_NAMES[item]).at[0].set(n)
           for item, n in inventory.items()}
    game._states = s.replace(  # CraftaxEnv has no setter; the task editor does the same
        map=s.map.at[0, row, col].set(int(block)),
        mob_map=s.mob_map.at[0, row, col].set(False),
        inventory=s.inventory.replace(**inv),
        player_drink=s.player_drink.at[0].set(9),
        player_thirst=s.player_thirst.at[0].set(10.0),
        is_sleeping=s.is_sleeping.at[0].set(False),
        achievements=s.achievements.at[0, int(ach)].set(True),
    )


@pytest.mark.parametrize("case", list(CASES))
@pytest.mark.parametrize("game", GAMES, indirect=True)
def test_a_repeat_at_the_cap_is_an_event(game, case):
    block, inventory, action, ach = CASES[case]
    game.reset(np.array([1, 2]))
    (_set_up_crafter if game.name == "crafter" else _set_up_craftax)(game, block, inventory, ach)
    noop = np.zeros(2, np.int32)
    prev = {k: v.copy() for k, v in game.step(noop).state.items()}  # exports the edit
    cur = game.step(np.array([action, Action.NOOP], np.int32)).state
    full = [item for item in inventory if inventory[item] == 9]
    assert (cur["inventory"][0, full] == 9).all()  # at the cap: the count did not rise
    assert cur["player_vitals"][0, 2] == 9
    if game.name == "crafter":  # the game counted the act (Craftax's flag was already set)
        assert game.raw_state[0]._player.achievements[ach.name.lower()] == 2
    events = achievement_events(prev, cur)
    assert {Achievement(i).name for i in np.flatnonzero(events[0])} == {ach.name}
    assert not events[1].any()


def _pair(**inventory: int) -> tuple[State, State]:
    """Two one-env states: the inventory before, to be edited into the one after."""
    prev = empty_state(1)
    prev["map"][0] = Block.GRASS
    for name, count in inventory.items():
        prev["inventory"][0, Item[name.upper()]] = count
    return prev, {k: v.copy() for k, v in prev.items()}


@pytest.mark.parametrize("stone_cost", [0, 1])  # crafter's iron tools cost none, Craftax's one
def test_an_iron_tool_made_at_the_cap_is_an_event_in_either_recipe(stone_cost):
    prev, cur = _pair(wood=2, stone=2, coal=2, iron=2, iron_pickaxe=9, iron_sword=3)
    for item, count in (("wood", 1), ("coal", 1), ("iron", 1), ("stone", 2 - stone_cost)):
        cur["inventory"][0, Item[item.upper()]] = count
    events = achievement_events(prev, cur)[0]
    assert {Achievement(i).name for i in np.flatnonzero(events)} == {"MAKE_IRON_PICKAXE"}


def test_what_the_cap_hides_is_not_guessed():
    prev, cur = _pair(wood=3, wood_pickaxe=9, wood_sword=9)
    cur["inventory"][0, Item.WOOD] = 2  # one of the two, both full: no way to tell which
    assert not achievement_events(prev, cur).any()
    prev, cur = _pair(wood=3, wood_pickaxe=9)
    cur["inventory"][0, Item.WOOD] = 1
    cur["map"][0, 4, 4] = Block.TABLE  # a table (2 wood) is no tool
    assert {Achievement(i).name for i in np.flatnonzero(achievement_events(prev, cur)[0])} == {
        "PLACE_TABLE"
    }
    prev, cur = _pair()
    prev["player_counters"][0, 2] = 20.0
    prev["player_vitals"][0, 2] = 5
    cur["player_vitals"][0, 2] = 4  # thirst ran over: the counter restarts at 0, no drink
    assert not achievement_events(prev, cur).any()


@pytest.mark.parametrize(
    ("full", "made"), [("wood_pickaxe", "wood_sword"), ("wood_sword", "wood_pickaxe")]
)
def test_making_the_sibling_of_a_full_tool_is_that_sibling_alone(full, made):
    """A wood pickaxe at 9 and 3 wood; a wood sword is made (sword 0 -> 1, wood 3 -> 2). The
    cap rule credits the full tool only when no tool count rose: here the sword's did, so the
    event is MAKE_WOOD_SWORD, never also MAKE_WOOD_PICKAXE (and the same the other way)."""
    prev, cur = _pair(wood=3, **{full: 9})
    cur["inventory"][0, Item.WOOD] = 2
    cur["inventory"][0, Item[made.upper()]] = 1
    events = achievement_events(prev, cur)[0]
    assert {Achievement(i).name for i in np.flatnonzero(events)} == {f"MAKE_{made.upper()}"}
