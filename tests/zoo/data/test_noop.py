"""Noop detection, runs and the read-time filter (the paper's 'runs < 20 removed')."""

from __future__ import annotations

import numpy as np

from zoo.data.noop import filter_noops, noop_counts, noop_flags, noop_runs
from zoo.data.sequences import filter_noop_chunks
from zoo.envs.constants import Achievement, Action, Block, Item, Mob
from zoo.envs.schema import empty_state


def _chunk(noop: np.ndarray, runs: np.ndarray | None = None) -> dict:
    n = len(noop)
    state = empty_state(n)
    state["timestep"][:] = np.arange(n)
    return {
        "frames": np.zeros((n, 2, 2, 3), np.uint8),
        "actions": np.arange(n, dtype=np.int64),
        "rewards": np.zeros(n, np.float32),
        "noop": noop,
        "noop_run": noop_runs(noop) if runs is None else runs,
        "state": state,
        "meta": {"episode": 0},
    }


def test_noop_runs_hand_computed():
    noop = np.array([0, 1, 1, 0, 1, 0, 0, 1, 1, 1], bool)
    assert noop_runs(noop).tolist() == [0, 2, 2, 0, 1, 0, 0, 3, 3, 3]
    assert noop_runs(np.zeros(0, bool)).tolist() == []


def test_filter_removes_run_of_19_keeps_run_of_20():
    noop = np.array([False] * 3 + [True] * 19 + [False] * 2 + [True] * 20 + [False], bool)
    out = filter_noops(_chunk(noop), min_run=20)
    expect = [0, 1, 2, 22, 23, *range(24, 44), 44]
    assert out["step_index"].tolist() == expect
    assert out["actions"].tolist() == expect
    assert out["state"]["timestep"].tolist() == expect
    # the only gap is the removed run of 19, just before step 22
    assert np.flatnonzero(out["cut"]).tolist() == [3]
    assert out["noop"].sum() == 20 and out["meta"] == {"episode": 0}


def test_the_data_modules_filter_stage_keeps_runs_of_its_min_run():
    """``min_noop_run`` reaches the filter: with 5, a run of 5 noops stays, one of 4 goes."""
    noop = np.array([False] * 2 + [True] * 5 + [False] + [True] * 4 + [False], bool)
    (out,) = filter_noop_chunks([_chunk(noop)], 5)
    assert out["step_index"].tolist() == [0, 1, 2, 3, 4, 5, 6, 7, 12]
    assert np.flatnonzero(out["cut"]).tolist() == [8]  # step 12 follows the dropped run


def test_filter_cut_flag_at_chunk_start():
    noop = np.array([True] * 5 + [False] * 3, bool)
    out = filter_noops(_chunk(noop))
    assert out["step_index"].tolist() == [5, 6, 7]
    assert out["cut"].tolist() == [True, False, False]


def test_run_across_chunk_boundary_uses_episode_length():
    # a run of 25 noops split 10 | 15 over two chunks must be kept in both
    noop = np.array([False] * 6 + [True] * 25 + [False] * 5, bool)
    runs = noop_runs(noop)
    first, second = slice(0, 16), slice(16, 36)
    a = filter_noops(_chunk(noop[first], runs[first]))
    b = filter_noops(_chunk(noop[second], runs[second]))
    assert len(a["actions"]) == 16 and len(b["actions"]) == 20
    assert not a["cut"].any() and not b["cut"].any()
    # computed per chunk instead, both pieces would be (wrongly) dropped
    assert len(filter_noops(_chunk(noop[first]))["actions"]) == 6


def test_noop_counts_exclude_final_observation():
    noop = np.array([True] * 3 + [False] + [True] * 20 + [False], bool)
    actions = np.array([0] * 24 + [-1])
    counts = noop_counts(noop, noop_runs(noop), actions, min_run=20)
    assert counts == {"steps": 24, "noop_steps": 23, "kept_steps": 21, "kept_noop_steps": 20}


def _pair(n: int):
    before = empty_state(n)
    before["player_pos"][:] = (10, 10)
    before["player_dir"][:] = int(Action.MOVE_RIGHT)  # facing (10, 11)
    before["map"][:] = int(Block.GRASS)
    before["player_vitals"][:] = (9, 5, 5, 9)
    after = {k: v.copy() for k, v in before.items()}
    return before, after


def test_noop_flags_on_constructed_states():
    cases = {}
    before, after = _pair(5)
    cases[0] = (Action.NOOP, True)
    cases[1] = (Action.PLACE_TABLE, True)  # inventory unchanged: nothing placed
    cases[2] = (Action.MOVE_LEFT, False)
    after["player_dir"][2] = int(Action.MOVE_LEFT)  # turned
    cases[3] = (Action.MOVE_RIGHT, True)  # blocked, already facing right
    cases[4] = (Action.MOVE_UP, True)
    before["player_sleeping"][4] = True  # any step while asleep
    actions = np.array([int(cases[i][0]) for i in range(5)])
    expected = [cases[i][1] for i in range(5)]
    assert noop_flags(actions, before, after).tolist() == expected


def test_do_off_grass_is_a_noop_only_when_it_changes_nothing():
    # Off grass, since DO facing grass is a sapling try and never a noop whatever changed.
    # Each acting case changes one thing only, so every term of the rule is needed.
    before, after = _pair(10)
    before["map"][:, 10, 11] = after["map"][:, 10, 11] = int(Block.SAND)
    # 0: facing sand, nothing changes
    before["map"][1, 10, 11] = after["map"][1, 10, 11] = int(Block.TREE)
    after["inventory"][1, Item.WOOD] = 1  # 1: collected wood
    for i, mob in ((2, Mob.COW), (3, Mob.ZOMBIE), (4, Mob.SKELETON)):
        before["mob_map"][i, 10, 11] = int(mob)  # 2-4: hits it
    before["map"][5, 10, 11] = after["map"][5, 10, 11] = int(Block.WATER)
    after["player_vitals"][5, 2] = 6  # 5: drank
    after["player_vitals"][6, 1] = 6  # 6: ate
    # 7: broke a sapling
    before["map"][7, 10, 11], after["map"][7, 10, 11] = int(Block.PLANT), int(Block.GRASS)
    after["achievements"][8, Achievement.EAT_PLANT] = True  # 8: unlocked an achievement
    before["mob_map"][9, 10, 11] = int(Mob.ARROW)  # 9: an arrow cannot be hit: noop
    actions = np.full(10, int(Action.DO))
    assert noop_flags(actions, before, after).tolist() == [True] + [False] * 8 + [True]


def test_sleep_is_a_noop_unless_it_puts_the_player_to_sleep():
    before, after = _pair(3)
    before["player_vitals"][0, 3] = 3
    after["player_sleeping"][0] = True  # 0: tired, falls asleep
    # 1: energy full (9), stays awake
    before["player_sleeping"][2] = after["player_sleeping"][2] = True  # 2: already asleep
    actions = np.full(3, int(Action.SLEEP))
    assert noop_flags(actions, before, after).tolist() == [False, True, True]


def test_a_failed_sapling_try_is_not_a_noop():
    # DO on grass pays a sapling 1 time in 10; the other 9 are tries, kept for imitation
    before, after = _pair(2)
    before["map"][1, 10, 11] = after["map"][1, 10, 11] = int(Block.STONE)  # no pickaxe: no effect
    actions = np.array([int(Action.DO)] * 2)
    assert noop_flags(actions, before, after).tolist() == [False, True]


def test_final_observation_is_not_a_noop():
    before, after = _pair(1)
    assert noop_flags(np.array([-1]), before, after).tolist() == [False]


def test_noop_flags_on_real_rollout(crafter_env):
    env = crafter_env
    step = env.reset(np.array([5, 6]))
    # env 0 idles; env 1 walks until it actually moves
    moved = False
    for action in [Action.MOVE_LEFT, Action.MOVE_RIGHT, Action.MOVE_UP, Action.MOVE_DOWN] * 2:
        after = env.step(np.array([Action.NOOP, action]))
        flags = noop_flags(np.array([Action.NOOP, action]), step.state, after.state)
        assert flags[0]
        if (after.state["player_pos"][1] != step.state["player_pos"][1]).any():
            assert not flags[1]
            moved = True
            break
        step = after
    assert moved


def test_filter_drops_sleeping_steps_unless_asked_to_keep_them():
    """Sleep is one long noop run; its labels mean nothing (the env ignores actions asleep)."""
    noop = np.array([False] * 2 + [True] * 30 + [False] * 3, bool)
    chunk = _chunk(noop)
    chunk["state"]["player_sleeping"][2:32] = True
    out = filter_noops(chunk)
    assert out["step_index"].tolist() == [0, 1, 32, 33, 34]
    assert out["cut"].tolist() == [False, False, True, False, False]
    kept = filter_noops(chunk, drop_sleeping=False)
    assert len(kept["step_index"]) == len(noop)
    counts = noop_counts(noop, noop_runs(noop), np.zeros(len(noop)), 20, chunk["state"]["player_sleeping"])
    assert counts["kept_steps"] == 5 and counts["kept_noop_steps"] == 0


def _numpy_noop_flags(actions, before, after):
    """The rule as numpy wrote it before ``noop_flags`` became one numba pass (reference)."""
    from zoo.data.noop import _OFFSETS
    from zoo.envs.schema import MAP_SIZE

    actions = np.asarray(actions, np.int64)
    idx = np.arange(len(actions))
    inv_same = (before["inventory"] == after["inventory"]).all(-1)
    ach_same = (before["achievements"] == after["achievements"]).all(-1)
    pos_same = (before["player_pos"] == after["player_pos"]).all(-1)
    dir_same = before["player_dir"] == after["player_dir"]
    fed = (after["player_vitals"][:, 1:3] > before["player_vitals"][:, 1:3]).any(-1)
    facing = before["player_pos"].astype(np.int64) + _OFFSETS[before["player_dir"].astype(np.int64)]
    row, col = np.clip(facing[:, 0], 0, MAP_SIZE - 1), np.clip(facing[:, 1], 0, MAP_SIZE - 1)
    facing_block = before["map"][idx, row, col]
    block_same = facing_block == after["map"][idx, row, col]
    mob_there = np.isin(before["mob_map"][idx, row, col], [Mob.COW, Mob.ZOMBIE, Mob.SKELETON])
    do_noop = (block_same & ~mob_there & (facing_block != Block.GRASS) & inv_same & ach_same
               & ~fed)
    moves = [Action.MOVE_LEFT, Action.MOVE_RIGHT, Action.MOVE_UP, Action.MOVE_DOWN]
    noop = actions == Action.NOOP
    noop |= np.isin(actions, moves) & pos_same & dir_same
    noop |= (actions == Action.DO) & do_noop
    noop |= (actions == Action.SLEEP) & ~after["player_sleeping"]
    noop |= (actions >= Action.PLACE_STONE) & inv_same
    noop |= before["player_sleeping"].astype(bool)
    return noop & (actions >= 0)


def test_noop_flags_equal_the_numpy_rule_on_random_transitions():
    rng = np.random.default_rng(0)
    n = 3000
    before = empty_state(n)
    before["player_pos"] = rng.integers(-1, 66, (n, 2)).astype(np.int16)  # edges clamp
    before["player_dir"] = rng.integers(0, 5, n).astype(np.uint8)
    before["map"] = rng.integers(0, 4, (n, 64, 64)).astype(np.uint8)  # grass 2 among them
    before["mob_map"] = rng.integers(0, 5, (n, 64, 64)).astype(np.uint8)
    before["inventory"] = rng.integers(0, 2, (n, 12)).astype(np.int16)
    before["achievements"] = rng.random((n, 22)) < 0.5
    before["player_vitals"] = rng.integers(0, 3, (n, 4)).astype(np.int8)
    before["player_sleeping"] = rng.random(n) < 0.2
    after = {k: v.copy() for k, v in before.items()}
    for name in ("player_pos", "inventory", "achievements", "player_vitals", "player_sleeping",
                 "map"):
        changed = rng.random(n) < 0.15  # each field changes alone in some steps
        if after[name].dtype == bool:
            after[name][changed] = ~after[name][changed]
        else:
            after[name][changed] += rng.integers(-1, 2, after[name][changed].shape).astype(
                after[name].dtype)
    after["player_dir"] = np.where(rng.random(n) < 0.15, rng.integers(0, 5, n),
                                   before["player_dir"]).astype(np.uint8)
    actions = rng.integers(-1, 18, n)
    flags = noop_flags(actions, before, after)
    np.testing.assert_array_equal(flags, _numpy_noop_flags(actions, before, after))
    assert 0.2 < flags.mean() < 0.95  # both outcomes, many times
