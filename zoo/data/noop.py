"""Which steps did nothing (the paper's "noop" actions), their runs, and the read-time filter.

The paper finds ~60% of expert steps are noops and trains C-VPT without noop runs shorter
than 20 steps, keeping longer ones (strategic waiting, e.g. sheltering). A step is a noop
when its action had no effect on the game:
- NOOP, or any action while the player sleeps (crafter turns those into NOOP);
- a move that neither moved nor turned the player;
- DO facing nothing it could change: the facing tile's block is unchanged, no cow, zombie
  or skeleton stands there (hitting one always costs it health), the inventory and
  achievements are unchanged and food/drink did not rise. DO facing grass is never a noop:
  it is a sapling try that pays with probability 0.1 in both games, so calling the 9 failed
  tries in 10 noops would filter out most of the expert's sapling collecting;
- SLEEP that did not put the player to sleep (energy already full);
- PLACE_* / MAKE_* that left the inventory unchanged (nothing placed or made).
Runs are computed per episode at generation time, so a run crossing a chunk boundary
keeps its full length in every chunk it touches.

Sleep is a long noop run (hundreds of steps), so "keep runs >= 20" alone keeps it. The env
overrides every action while the player sleeps, so those steps' action labels carry nothing to
imitate; the paper's 60% -> 4.6% (with sleep ~24% of all steps) is only reachable if they go.
The filter therefore drops sleeping steps too unless ``drop_sleeping=False``.
"""

from __future__ import annotations

import numpy as np

from zoo.envs.constants import DIRECTION_OFFSETS, Action, Block, Mob
from zoo.envs.schema import MAP_SIZE, State

_MOVES = np.array(sorted(DIRECTION_OFFSETS), np.int64)
# direction id (1..4) -> (d_row, d_col); row 0 pads the unused id 0
_OFFSETS = np.zeros((5, 2), np.int64)
for _dir, _off in DIRECTION_OFFSETS.items():
    _OFFSETS[_dir] = _off
_HITTABLE = np.array([Mob.COW, Mob.ZOMBIE, Mob.SKELETON], np.uint8)


def noop_flags(actions: np.ndarray, before: State, after: State) -> np.ndarray:
    """Noop flag per step from batched states before and after each action.

    Args:
        actions: (n,) action ids; negative ids (the episode's final observation) are not noops.
        before: state at which each action was taken, arrays with leading dim n.
        after: state that followed it.
    """
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
    mob_there = np.isin(before["mob_map"][idx, row, col], _HITTABLE)
    sapling_try = facing_block == Block.GRASS
    do_noop = block_same & ~mob_there & ~sapling_try & inv_same & ach_same & ~fed

    noop = actions == Action.NOOP
    noop |= np.isin(actions, _MOVES) & pos_same & dir_same
    noop |= (actions == Action.DO) & do_noop
    noop |= (actions == Action.SLEEP) & ~after["player_sleeping"]
    noop |= (actions >= Action.PLACE_STONE) & inv_same
    noop |= before["player_sleeping"].astype(bool)
    return noop & (actions >= 0)


def noop_runs(noop: np.ndarray) -> np.ndarray:
    """Length of the maximal run of consecutive noops each step belongs to (0 off runs)."""
    noop = np.asarray(noop, bool)
    runs = np.zeros(len(noop), np.int32)
    if not noop.any():
        return runs
    edges = np.diff(np.concatenate([[0], noop.astype(np.int8), [0]]))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    for start, end in zip(starts, ends):
        runs[start:end] = end - start
    return runs


def keep_mask(
    noop: np.ndarray,
    noop_run: np.ndarray,
    min_run: int = 20,
    sleeping: np.ndarray | None = None,
) -> np.ndarray:
    """Steps kept by the paper's filter: non-noops and noops in runs of at least ``min_run``,
    less the steps taken while asleep when ``sleeping`` is given."""
    keep = ~np.asarray(noop, bool) | (np.asarray(noop_run) >= min_run)
    return keep if sleeping is None else keep & ~np.asarray(sleeping, bool)


def filter_noops(chunk: dict, min_run: int = 20, drop_sleeping: bool = True) -> dict:
    """Drop noop steps in runs shorter than ``min_run`` (and sleeping steps) from a chunk.

    Adds ``cut`` (True where one or more steps were removed just before a kept step) and
    ``step_index`` (each kept step's index in the chunk). ``meta`` is passed through.
    """
    sleeping = chunk["state"]["player_sleeping"] if drop_sleeping else None
    keep = keep_mask(chunk["noop"], chunk["noop_run"], min_run, sleeping)
    index = np.flatnonzero(keep)
    gap_before = np.diff(np.concatenate([[-1], index])) > 1
    out = {k: v[keep] for k, v in chunk.items() if isinstance(v, np.ndarray)}
    out["state"] = {k: v[keep] for k, v in chunk["state"].items()}
    out["meta"] = chunk["meta"]
    out["cut"] = gap_before
    out["step_index"] = index.astype(np.int64)
    return out


def noop_counts(
    noop: np.ndarray,
    noop_run: np.ndarray,
    actions: np.ndarray,
    min_run: int = 20,
    sleeping: np.ndarray | None = None,
) -> dict:
    """Noop and step counts before/after filtering; the final observation (action -1) is no step."""
    acted = np.asarray(actions) >= 0
    noop = np.asarray(noop, bool) & acted
    keep = keep_mask(noop, noop_run, min_run, sleeping) & acted
    return {
        "steps": int(acted.sum()),
        "noop_steps": int(noop.sum()),
        "kept_steps": int(keep.sum()),
        "kept_noop_steps": int((noop & keep).sum()),
    }
