"""Each rule fires on a constructed state/action sequence and stays silent on a near miss.

Episodes are built from zoo.envs.schema.empty_state(T) (time as the batch axis): a grass
world, the player at (32, 32) facing east, full vitals, daylight. The step under test is
t = 4, the first with a full clip (o_0..o_5).
"""

from __future__ import annotations

import numpy as np
import pytest

from zoo.captions.rules import EpisodeView, Window, all_rules, scan_episode
from zoo.envs.constants import Action, Block, Item
from zoo.envs.schema import empty_state

T, STEP = 8, 4
HOME = (32, 32)
EAST = (32, 33)


def blank() -> tuple[np.ndarray, dict]:
    state = empty_state(T)
    state["map"][:] = Block.GRASS
    state["player_pos"][:] = HOME
    state["player_dir"][:] = Action.MOVE_RIGHT
    state["player_vitals"][:] = 9
    state["light_level"][:] = 1.0
    actions = np.full(T, int(Action.NOOP), np.int64)
    actions[-1] = -1
    return actions, state


def fires(actions: np.ndarray, state: dict, rule: str, t: int = STEP) -> list[str]:
    return all_rules()[rule].check(Window(EpisodeView(actions, state), t))


def walk_east(state: dict, start_col: int = 32) -> None:
    """Player walks east one tile per step from the first step on."""
    for t in range(T):
        state["player_pos"][t] = (32, start_col + t)


def put_mob(state: dict, kind: str, positions: list[tuple[int, int]], slot: int = 0) -> None:
    for t, pos in enumerate(positions):
        state[f"{kind}_pos"][t, slot] = pos
        state[f"{kind}_status"][t, slot] = (1, 5, 0)


# --- Achievement -------------------------------------------------------------------------


def test_harvest_wood_fires_on_inventory_gain_and_not_without_do():
    actions, s = blank()
    actions[STEP] = Action.DO
    s["map"][:, 32, 33] = Block.TREE
    s["inventory"][STEP + 1 :, Item.WOOD] = 1
    assert fires(actions, s, "harvest") == ["obtain wood"]
    actions[STEP] = Action.NOOP
    assert fires(actions, s, "harvest") == []


def test_harvest_stone_at_cap_counts_the_mined_tile():
    actions, s = blank()
    actions[STEP] = Action.DO
    s["inventory"][:, Item.STONE] = 9
    s["map"][: STEP + 1, 32, 33] = Block.STONE
    s["map"][STEP + 1 :, 32, 33] = Block.PATH
    assert fires(actions, s, "harvest") == ["obtain stone"]
    s["map"][:, 32, 33] = Block.STONE  # pickaxe missing: nothing mined
    assert fires(actions, s, "harvest") == []


def test_harvest_drink_needs_water_in_front():
    actions, s = blank()
    actions[STEP] = Action.DO
    s["player_vitals"][:, 2] = 5
    s["player_vitals"][STEP + 1 :, 2] = 6
    s["map"][:, 32, 33] = Block.WATER
    assert fires(actions, s, "harvest") == ["obtain drink"]
    s["map"][:, 32, 33] = Block.GRASS
    assert fires(actions, s, "harvest") == []


def test_harvest_ripe_plant_only_when_ripe():
    actions, s = blank()
    actions[STEP] = Action.DO
    s["map"][: STEP + 1, 32, 33] = Block.RIPE_PLANT
    s["map"][STEP + 1 :, 32, 33] = Block.PLANT
    assert fires(actions, s, "harvest") == ["obtain ripe plant"]
    s["map"][:, 32, 33] = Block.PLANT
    assert fires(actions, s, "harvest") == []


def test_place_names_item_and_material_and_skips_failed_placement():
    actions, s = blank()
    actions[STEP] = Action.PLACE_STONE
    s["map"][: STEP + 1, 32, 33] = Block.WATER
    s["map"][STEP + 1 :, 32, 33] = Block.STONE
    assert fires(actions, s, "place") == ["place stone on water"]
    s["map"][STEP + 1 :, 32, 33] = Block.WATER
    assert fires(actions, s, "place") == []


def test_craft_needs_the_tool_to_appear():
    actions, s = blank()
    actions[STEP] = Action.MAKE_IRON_SWORD
    s["inventory"][:, Item.WOOD] = 3
    s["inventory"][STEP + 1 :, Item.WOOD] = 2
    s["inventory"][STEP + 1 :, Item.IRON_SWORD] = 1
    assert fires(actions, s, "craft") == ["craft iron sword"]
    s["inventory"][:, Item.WOOD] = 3
    s["inventory"][:, Item.IRON_SWORD] = 0
    assert fires(actions, s, "craft") == []


def test_kill_when_target_vanishes_not_when_it_steps_aside():
    actions, s = blank()
    actions[STEP] = Action.DO
    put_mob(s, "zombies", [EAST] * (STEP + 1))
    assert fires(actions, s, "kill") == ["kill zombie"]
    put_mob(s, "zombies", [EAST] * (STEP + 1) + [(31, 33)] * (T - STEP - 1))
    s["zombies_status"][STEP + 1 :, 0, 1] = 4  # hit for one point, stepped aside
    assert fires(actions, s, "kill") == []


def test_kill_with_a_same_kind_bystander_next_to_the_target():
    actions, s = blank()
    actions[STEP] = Action.DO
    put_mob(s, "zombies", [EAST] * (STEP + 1))
    s["zombies_status"][STEP, 0, 1] = 1  # one hit from death
    put_mob(s, "zombies", [(31, 33)] * T, slot=1)  # unhurt, next to the target throughout
    assert fires(actions, s, "kill") == ["kill zombie"]
    put_mob(s, "zombies", [EAST] * (STEP + 1) + [(33, 33)] * (T - STEP - 1))
    s["zombies_status"][STEP, 0, 1] = 2
    s["zombies_status"][STEP + 1 :, 0, 1] = 1  # the hit cost it a point: it survived
    assert fires(actions, s, "kill") == []


def test_sleep_fires_when_falling_asleep():
    actions, s = blank()
    actions[STEP] = Action.SLEEP
    s["player_sleeping"][STEP + 1 :] = True
    assert fires(actions, s, "sleep") == ["go to sleep"]
    s["player_sleeping"][:] = False  # energy full: the action does nothing
    assert fires(actions, s, "sleep") == []


# --- Movement ----------------------------------------------------------------------------


def test_stay_needs_five_noops_in_place():
    actions, s = blank()
    assert fires(actions, s, "stay") == ["stay"]
    actions[2] = Action.DO
    assert fires(actions, s, "stay") == []


def test_stay_is_not_sleeping():
    actions, s = blank()
    s["player_sleeping"][:] = True
    assert fires(actions, s, "stay") == []


def test_move_names_the_direction_and_needs_actual_motion():
    actions, s = blank()
    actions[:-1] = Action.MOVE_RIGHT
    walk_east(s)
    assert fires(actions, s, "move") == ["move to east"]
    s["player_pos"][:] = HOME  # walking into a wall
    assert fires(actions, s, "move") == []


def test_move_north_is_up_the_map():
    actions, s = blank()
    actions[:-1] = Action.MOVE_UP
    for t in range(T):
        s["player_pos"][t] = (32 - t, 32)
    assert fires(actions, s, "move") == ["move to north"]


def test_approach_ends_near_the_mob():
    actions, s = blank()
    actions[:-1] = Action.MOVE_RIGHT
    walk_east(s)  # col 32 at t=0 .. 37 at t=5
    put_mob(s, "cows", [(32, 38)] * T)
    assert fires(actions, s, "approach") == ["approach cow"]
    put_mob(s, "cows", [(32, 50)] * T)  # got closer, but never near
    assert fires(actions, s, "approach") == []


def test_flee_from_hostile_mob_only():
    actions, s = blank()
    actions[:-1] = Action.MOVE_RIGHT
    walk_east(s)  # col 32 at t=0 .. 37 at t=5
    chase = [(32, c) for c in (30, 31, 32, 32, 33, 33, 34, 34)]  # follows, falling behind
    put_mob(s, "zombies", chase)
    assert fires(actions, s, "flee") == ["flee from zombie"]
    s["zombies_status"][:] = 0
    put_mob(s, "cows", chase)  # running from a cow is not fleeing
    assert fires(actions, s, "flee") == []


def test_flee_not_when_walking_past_a_standing_zombie():
    actions, s = blank()
    actions[:-1] = Action.MOVE_RIGHT
    walk_east(s, start_col=30)  # passes (33, 31) at distance 1, then walks on
    put_mob(s, "zombies", [(33, 31)] * T)
    episode = EpisodeView(actions, s)
    assert [c for _, _, c in scan_episode(episode, {"flee": all_rules()["flee"]})] == []


def test_flee_from_skeleton_needs_it_to_shoot():
    actions, s = blank()
    actions[:-1] = Action.MOVE_RIGHT
    walk_east(s)
    put_mob(s, "skeletons", [(32, 30)] * T)  # skeletons keep their distance instead of chasing
    assert fires(actions, s, "flee") == []
    put_mob(s, "arrows", [(32, 31)] * 2)  # at t=1 an arrow flies at the player
    s["arrows_dir"][:, 0] = (0, 1)
    assert fires(actions, s, "flee") == ["flee from skeleton"]


def test_flee_from_arrow_is_a_side_step_out_of_its_line():
    actions, s = blank()
    actions[STEP] = Action.MOVE_UP
    s["player_pos"][STEP + 1 :] = (31, 32)
    put_mob(s, "arrows", [(32, 29)] * T)
    s["arrows_dir"][:, 0] = (0, 1)  # flying east, at the player
    assert fires(actions, s, "flee") == ["flee from arrow"]
    s["arrows_dir"][:, 0] = (0, -1)  # flying away: nothing to dodge
    assert fires(actions, s, "flee") == []


def test_explore_needs_unvisited_ground():
    actions, s = blank()
    actions[:-1] = Action.MOVE_RIGHT
    walk_east(s)
    assert fires(actions, s, "explore") == ["go explore"]
    for t in range(T):  # pacing back and forth over known tiles
        s["player_pos"][t] = (32, 32 + (t % 2))
    assert fires(actions, s, "explore") == []


# --- Construction ------------------------------------------------------------------------


def test_shelter_when_the_placement_closes_the_last_side():
    actions, s = blank()
    actions[STEP] = Action.PLACE_STONE
    for rc in ((31, 32), (33, 32), (32, 31)):
        s["map"][:, rc[0], rc[1]] = Block.STONE
    s["map"][STEP + 1 :, 32, 33] = Block.STONE
    assert fires(actions, s, "shelter") == ["place stone to build shelter"]
    s["map"][:, 31, 32] = Block.GRASS  # two sides open after placing, in daylight, no mob
    assert fires(actions, s, "shelter") == []


def test_shelter_three_sides_counts_at_night():
    actions, s = blank()
    actions[STEP] = Action.PLACE_TABLE
    for rc in ((33, 32), (32, 31)):
        s["map"][:, rc[0], rc[1]] = Block.WATER
    s["map"][STEP + 1 :, 32, 33] = Block.TABLE
    assert fires(actions, s, "shelter") == []
    s["light_level"][:] = 0.1
    assert fires(actions, s, "shelter") == ["place table to build shelter"]


def test_path_over_water_when_walking_onto_former_water():
    actions, s = blank()
    actions[STEP] = Action.MOVE_RIGHT
    s["player_pos"][STEP + 1 :] = EAST
    s["map"][:2, 32, 33] = Block.WATER
    s["map"][2:3, 32, 33] = Block.STONE
    s["map"][3:, 32, 33] = Block.PATH
    assert fires(actions, s, "path") == ["build path over water"]
    s["map"][:, 32, 33] = Block.PATH  # an old path
    assert fires(actions, s, "path") == []


def test_tunnel_needs_digging_forward_through_rock():
    actions, s = blank()
    actions[STEP] = Action.DO
    for rc in ((31, 32), (33, 32)):
        s["map"][:, rc[0], rc[1]] = Block.STONE
    s["map"][:2, 32, 32] = Block.STONE  # the tile the player now stands on was dug out
    s["map"][2:, 32, 32] = Block.PATH
    s["map"][: STEP + 1, 32, 33] = Block.STONE
    s["map"][STEP + 1 :, 32, 33] = Block.PATH
    assert fires(actions, s, "tunnel") == ["dig a tunnel"]
    s["map"][:, 32, 32] = Block.GRASS  # mining a wall from open ground
    assert fires(actions, s, "tunnel") == []


# --- Combat ------------------------------------------------------------------------------


def test_attacked_by_zombie_needs_damage_and_an_adjacent_zombie():
    actions, s = blank()
    s["player_vitals"][STEP + 1 :, 0] = 7
    put_mob(s, "zombies", [EAST] * T)
    s["zombies_status"][STEP + 1, 0, 2] = 5  # the hit resets its cooldown
    assert fires(actions, s, "attacked_by") == ["attacked by zombie"]
    s["zombies_status"][:] = 0  # lost health to hunger, nobody near
    assert fires(actions, s, "attacked_by") == []


def test_attacked_by_skeleton_is_an_arrow_hit():
    actions, s = blank()
    s["player_vitals"][STEP + 1 :, 0] = 7
    put_mob(s, "arrows", [(32, 31)] * T)
    s["arrows_dir"][:, 0] = (0, 1)
    assert fires(actions, s, "attacked_by") == ["attacked by skeleton"]
    s["arrows_dir"][:, 0] = (1, 0)  # flies past
    assert fires(actions, s, "attacked_by") == []


def test_attacked_by_zombie_not_while_its_attack_cools_down():
    actions, s = blank()
    s["player_vitals"][STEP + 1 :, 0] = 8  # starving: one point lost, a zombie next to us
    put_mob(s, "zombies", [EAST] * T)
    s["zombies_status"][:, 0, 2] = np.arange(T)[::-1]  # 7, 6, ...: cooling down, no attack
    assert fires(actions, s, "attacked_by") == []
    s["zombies_status"][STEP + 1, 0, 2] = 5  # cooldown reset at t+1: it attacked at t
    assert fires(actions, s, "attacked_by") == ["attacked by zombie"]


def test_attacked_by_skeleton_point_blank():
    actions, s = blank()
    s["player_vitals"][STEP + 1 :, 0] = 7
    put_mob(s, "skeletons", [EAST] * T)  # adjacent: its arrow spawns and hits in one step
    s["skeletons_status"][STEP + 1, 0, 2] = 4  # reload set at t+1: it shot at t
    assert fires(actions, s, "attacked_by") == ["attacked by skeleton"]
    s["skeletons_status"][:, 0, 2] = 0  # it did not shoot: hunger took the health
    assert fires(actions, s, "attacked_by") == []


def test_block_attack_from_zombie_when_block_lies_between():
    actions, s = blank()
    actions[STEP] = Action.PLACE_STONE
    s["map"][STEP + 1 :, 32, 33] = Block.STONE
    put_mob(s, "zombies", [(32, 37)] * 2 + [(32, 36)] * 2 + [(32, 35)] * 4)
    assert fires(actions, s, "block_attack") == ["block attack from zombie with stone"]
    put_mob(s, "zombies", [(32, 28)] * T)  # zombie behind the player
    assert fires(actions, s, "block_attack") == []


def test_block_attack_from_skeleton_in_line():
    actions, s = blank()
    actions[STEP] = Action.PLACE_TABLE
    s["map"][STEP + 1 :, 32, 33] = Block.TABLE
    put_mob(s, "skeletons", [(32, 36)] * T)
    assert fires(actions, s, "block_attack") == ["block attack from skeleton with table"]
    put_mob(s, "skeletons", [(35, 34)] * T)  # not in the player's row or column
    assert fires(actions, s, "block_attack") == []


def test_scan_visits_only_steps_with_a_full_clip():
    actions, s = blank()
    hits = list(scan_episode(EpisodeView(actions, s)))
    assert {t for t, _, _ in hits} == {4, 5, 6}  # t needs 4 states before it and state t+1
    assert {c for _, _, c in hits} == {"stay"}


def test_episode_view_rejects_mismatched_lengths():
    actions, s = blank()
    with pytest.raises(ValueError, match="has 8 steps, expected 7"):
        EpisodeView(actions[:-1], s)
