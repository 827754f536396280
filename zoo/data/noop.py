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

import numba
import numpy as np

from zoo.envs.constants import DIRECTION_OFFSETS, Action, Block, Mob
from zoo.envs.schema import MAP_SIZE, STATE_FIELDS, State

_MOVES = np.array(sorted(DIRECTION_OFFSETS), np.int64)
# direction id (1..4) -> (d_row, d_col); row 0 pads the unused id 0
_OFFSETS = np.zeros((5, 2), np.int64)
for _dir, _off in DIRECTION_OFFSETS.items():
    _OFFSETS[_dir] = _off
_HITTABLE = np.array([Mob.COW, Mob.ZOMBIE, Mob.SKELETON], np.uint8)
_IS_HITTABLE = np.isin(np.arange(256), _HITTABLE)  # uint8 mob id -> hittable
_FIRST_MOVE, _LAST_MOVE = int(_MOVES[0]), int(_MOVES[-1])
assert np.array_equal(_MOVES, np.arange(_FIRST_MOVE, _LAST_MOVE + 1)), "moves: one id range"
_NOOP, _DO, _SLEEP, _PLACE_STONE = (int(a) for a in (Action.NOOP, Action.DO, Action.SLEEP,
                                                     Action.PLACE_STONE))
_GRASS = int(Block.GRASS)
_FLAG_FIELDS = ("inventory", "achievements", "player_pos", "player_dir", "player_vitals", "map",
                "mob_map", "player_sleeping")


@numba.njit(cache=True)
def _all_equal(a, b, i):
    for j in range(a.shape[1]):
        if a[i, j] != b[i, j]:
            return False
    return True


@numba.njit(cache=True)
def _flags(actions, inventory, achievements, pos, direction, vitals, map_, mob_map, sleeping,
           inventory2, achievements2, pos2, direction2, vitals2, map2, sleeping2, offsets,
           hittable, out):
    """The rule of ``noop_flags``, env by env: the action kinds are disjoint, so of the rule's
    terms only the action's own can hold (a sleeping player's steps are all noops)."""
    for i in range(actions.shape[0]):
        if direction[i] >= offsets.shape[0]:
            raise IndexError("player_dir out of range")
        a = actions[i]
        if a < 0:
            out[i] = False
        elif sleeping[i] or a == _NOOP:
            out[i] = True
        elif _FIRST_MOVE <= a <= _LAST_MOVE:
            out[i] = _all_equal(pos, pos2, i) and direction[i] == direction2[i]
        elif a == _DO:
            row = min(max(np.int64(pos[i, 0]) + offsets[direction[i], 0], 0), MAP_SIZE - 1)
            col = min(max(np.int64(pos[i, 1]) + offsets[direction[i], 1], 0), MAP_SIZE - 1)
            block = map_[i, row, col]
            fed = vitals2[i, 1] > vitals[i, 1] or vitals2[i, 2] > vitals[i, 2]
            out[i] = (block == map2[i, row, col] and not hittable[mob_map[i, row, col]]
                      and block != _GRASS and _all_equal(inventory, inventory2, i)
                      and _all_equal(achievements, achievements2, i) and not fed)
        elif a == _SLEEP:
            out[i] = not sleeping2[i]
        else:
            out[i] = a >= _PLACE_STONE and _all_equal(inventory, inventory2, i)


def noop_flags(actions: np.ndarray, before: State, after: State) -> np.ndarray:
    """Noop flag per step from batched states before and after each action.

    Args:
        actions: (n,) action ids; negative ids (the episode's final observation) are not noops.
        before: state at which each action was taken, arrays with leading dim n.
        after: state that followed it.
    """
    actions = np.asarray(actions, np.int64)
    # one numba pass instead of a chain of numpy ops, a visible share of a generation step
    states = [np.asarray(state[k], STATE_FIELDS[k].dtype) for state in (before, after)
              for k in _FLAG_FIELDS]
    del states[-2]  # the mob map after the step is not read
    out = np.empty(len(actions), bool)
    _flags(actions, *states, _OFFSETS, _IS_HITTABLE, out)
    return out


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
