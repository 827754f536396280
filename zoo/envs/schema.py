"""The per-step game state every env exports, as plain numpy arrays (the paper's Table B.2).

Both envs fill exactly these arrays, so the scripted expert, the caption rules and the
datasets read one format. Positions are (row, col) on the 64x64 map; row grows downwards.
Entity lists are padded to the paper's maxima; column 0 of every ``*_status`` is the mask.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

MAP_SIZE = 64
MAX_PLANTS = 10
MAX_COWS = 4
MAX_ZOMBIES = 4
MAX_SKELETONS = 2
MAX_ARROWS = 4
FRAME_SHAPE = (144, 144, 3)


@dataclass(frozen=True)
class Field:
    """One state array: its per-env shape, dtype and meaning."""

    shape: tuple[int, ...]
    dtype: str
    doc: str


STATE_FIELDS: dict[str, Field] = {
    "map": Field((MAP_SIZE, MAP_SIZE), "uint8", "block id per tile (zoo.envs.Block)"),
    "mob_map": Field((MAP_SIZE, MAP_SIZE), "uint8", "mob id per tile (zoo.envs.Mob)"),
    "light_level": Field((), "float32", "daylight in [0, 1]"),
    "plants_pos": Field((MAX_PLANTS, 2), "int16", "growing plants (row, col)"),
    "plants_status": Field((MAX_PLANTS, 3), "int16", "[mask, age, ripe]"),
    "player_pos": Field((2,), "int16", "player (row, col)"),
    "player_dir": Field((), "uint8", "facing: 1 left, 2 right, 3 up, 4 down (move action ids)"),
    "player_vitals": Field((4,), "int8", "[health, food, drink, energy], each 0..9"),
    "player_counters": Field((4,), "float32", "[recover, hunger, thirst, fatigue] counters"),
    "player_sleeping": Field((), "bool", "whether the player sleeps"),
    "inventory": Field((12,), "int16", "item counts (zoo.envs.Item)"),
    "achievements": Field((22,), "bool", "unlocked so far this episode (zoo.envs.Achievement)"),
    "cows_pos": Field((MAX_COWS, 2), "int16", "cows (row, col)"),
    "cows_status": Field((MAX_COWS, 3), "int16", "[mask, health, cooldown]"),
    "zombies_pos": Field((MAX_ZOMBIES, 2), "int16", "zombies (row, col)"),
    "zombies_status": Field((MAX_ZOMBIES, 3), "int16", "[mask, health, cooldown]"),
    "skeletons_pos": Field((MAX_SKELETONS, 2), "int16", "skeletons (row, col)"),
    "skeletons_status": Field((MAX_SKELETONS, 3), "int16", "[mask, health, cooldown]"),
    "arrows_pos": Field((MAX_ARROWS, 2), "int16", "arrows (row, col)"),
    "arrows_status": Field((MAX_ARROWS, 3), "int16", "[mask, health, cooldown]"),
    "arrows_dir": Field((MAX_ARROWS, 2), "int8", "arrow heading (d_row, d_col)"),
    "timestep": Field((), "int32", "steps since the episode began"),
}

State = dict[str, np.ndarray]


def empty_state(num_envs: int) -> State:
    """Zero-filled batched state, the shape every env exports."""
    return {
        name: np.zeros((num_envs, *f.shape), dtype=f.dtype) for name, f in STATE_FIELDS.items()
    }


def validate_state(state: State, num_envs: int | None = None) -> None:
    """Raise a ValueError naming the field when a batched state breaks the schema."""
    missing = sorted(set(STATE_FIELDS) - set(state))
    if missing:
        raise ValueError(f"state is missing fields {missing}; expected {sorted(STATE_FIELDS)}")
    for name, f in STATE_FIELDS.items():
        arr = np.asarray(state[name])
        n = arr.shape[0] if arr.ndim else None
        if arr.shape[1:] != f.shape or (num_envs is not None and n != num_envs):
            want = ("N" if num_envs is None else str(num_envs), *map(str, f.shape))
            raise ValueError(
                f"state field {name!r} has shape {arr.shape}, expected ({', '.join(want)})"
            )
        if arr.dtype != np.dtype(f.dtype):
            raise ValueError(f"state field {name!r} has dtype {arr.dtype}, expected {f.dtype}")


def index_state(state: State, i: int | slice | np.ndarray) -> State:
    """Select env(s) ``i`` from a batched state."""
    return {k: v[i] for k, v in state.items()}


def stack_states(states: list[State]) -> State:
    """Stack per-step states (each unbatched) into one array per field, time first."""
    return {k: np.stack([s[k] for s in states]) for k in STATE_FIELDS}
