"""The original ``crafter`` game behind the same interface as Craftax: ids, frames, schema.

Crafter indexes its world as [x, y]; the schema is [row, col] = [y, x], so arrays are
transposed on export. Crafter has no cap on mobs: the nearest ones to the player fill the
schema's slots. Plants are objects in crafter and tiles in Craftax; they are written into
the map as PLANT / RIPE_PLANT so both envs' maps mean the same.
"""

from __future__ import annotations

import collections

import numpy as np

from zoo.envs.base import Step, check_actions, check_seeds
from zoo.envs.constants import ACHIEVEMENT_NAMES, ITEM_NAMES, Action, Block, Mob
from zoo.envs.schema import (
    FRAME_SHAPE,
    MAX_ARROWS,
    MAX_COWS,
    MAX_PLANTS,
    MAX_SKELETONS,
    MAX_ZOMBIES,
    State,
    empty_state,
)

_FACING_TO_DIR = {
    (-1, 0): int(Action.MOVE_LEFT),
    (1, 0): int(Action.MOVE_RIGHT),
    (0, -1): int(Action.MOVE_UP),
    (0, 1): int(Action.MOVE_DOWN),
}


def material_lookup(material_names: dict[int, str | None]) -> np.ndarray:
    """Crafter material id -> zoo Block id."""
    table = np.zeros(max(material_names) + 1, np.uint8)
    for idx, name in material_names.items():
        table[idx] = int(Block.INVALID) if name is None else int(Block[name.upper()])
    return table


class _InsertionOrderedSet(dict):
    """A set that iterates in insertion order (a dict of keys to None)."""

    def add(self, item) -> None:
        self[item] = None

    def remove(self, item) -> None:
        del self[item]


def _make_crafter_env(pixels: bool, max_steps: int):
    """A crafter.Env whose episodes depend on the seed alone.

    Two changes to crafter 1.8.3, neither of which changes the game's rules:
    - crafter keeps each chunk's objects in a ``set``, which iterates in memory-address order,
      and draws spawn/despawn randomness in that order, so the same seed and actions gave
      different episodes in different processes (danijar/crafter#31, #36). Chunks here keep
      insertion order.
    - crafter's night-time render noise draws from the world's generator, so rendering or not
      changed the game. The noise here has a generator of its own, seeded with the world.
    """
    import crafter

    class _Crafter(crafter.Env):
        def __init__(self) -> None:
            super().__init__(area=(64, 64), size=FRAME_SHAPE[:2], length=max_steps)
            world, view = self._world, self._local_view
            world_reset = world.reset

            def reset(seed=None):
                world_reset(seed)
                world._chunks = collections.defaultdict(_InsertionOrderedSet)
                view._noise_rng = np.random.RandomState(seed)

            def noise(canvas, amount, stddev):
                values = view._noise_rng.uniform(32, 127, canvas.shape[:2])[..., None]
                mask = amount * view._vignette(canvas.shape, stddev)[..., None]
                return (1 - mask) * canvas + mask * values

            world.reset, view._noise = reset, noise

        def _obs(self):
            return super()._obs() if pixels else None

    return _Crafter()


class CrafterEnv:
    """N original crafter envs stepped one after another (crafter is pure Python).

    Args:
        num_envs: envs held.
        pixels: render 144x144 frames (False skips crafter's renderer for state-only agents).
        max_steps: episode length limit (crafter's default: 10,000).
    """

    name = "crafter"

    def __init__(self, num_envs: int, pixels: bool = True, max_steps: int = 10_000) -> None:
        if num_envs < 1:
            raise ValueError(f"num_envs must be >= 1, got {num_envs}")
        self.num_envs = num_envs
        self.pixels = pixels
        self._envs = [_make_crafter_env(pixels, max_steps) for _ in range(num_envs)]
        self._lookup = material_lookup(self._envs[0]._world._mat_names)
        self._frames = np.zeros((num_envs, *FRAME_SHAPE), np.uint8) if pixels else None
        self._state = empty_state(num_envs)
        self._done = np.zeros(num_envs, bool)

    @property
    def raw_state(self) -> list:
        """The crafter.Env objects themselves."""
        return self._envs

    def reset(self, seeds: np.ndarray, mask: np.ndarray | None = None) -> Step:
        seeds = check_seeds(seeds, self.num_envs)
        mask = np.ones(self.num_envs, bool) if mask is None else np.asarray(mask, bool)
        for i in np.flatnonzero(mask):
            env = self._envs[i]
            # crafter seeds episode k of an env with hash((seed, k)); pinning k = 1 makes the
            # world depend on the episode seed alone.
            env._seed, env._episode = int(seeds[i]), 0
            obs = env.reset()
            self._record(i, obs)
            self._done[i] = False
        zeros = np.zeros(self.num_envs, np.float32)
        return Step(self._frames_copy(), self._state_copy(), zeros, self._done.copy(), self._envs)

    def step(self, actions: np.ndarray) -> Step:
        actions = check_actions(actions, self.num_envs)
        reward = np.zeros(self.num_envs, np.float32)
        for i, env in enumerate(self._envs):
            if self._done[i]:
                continue  # a finished env waits for reset, as in Craftax
            obs, r, done, _ = env.step(int(actions[i]))
            reward[i] = r
            self._done[i] = done
            self._record(i, obs)
        return Step(self._frames_copy(), self._state_copy(), reward, self._done.copy(), self._envs)

    def _frames_copy(self) -> np.ndarray | None:
        return None if self._frames is None else self._frames.copy()

    def _state_copy(self) -> State:
        return {k: v.copy() for k, v in self._state.items()}

    def _record(self, i: int, obs: np.ndarray | None) -> None:
        if obs is not None:
            self._frames[i] = obs
        export_crafter_state(self._envs[i], self._lookup, self._state, i)


def export_crafter_state(env, lookup: np.ndarray, out: State, i: int) -> None:
    """Write crafter env ``env``'s state into row ``i`` of the batched schema arrays ``out``."""
    from crafter import objects

    world, player = env._world, env._player
    grid = lookup[world._mat_map].T  # [x, y] -> [row, col]
    mob_map = np.zeros_like(grid)
    plants, mobs = [], {objects.Cow: [], objects.Zombie: [], objects.Skeleton: [], objects.Arrow: []}
    for obj in world.objects:
        if isinstance(obj, objects.Plant):
            plants.append(obj)
        elif type(obj) in mobs:
            mobs[type(obj)].append(obj)
    for plant in plants:
        x, y = plant.pos
        grid[y, x] = int(Block.RIPE_PLANT if plant.ripe else Block.PLANT)

    px, py = player.pos
    dist = lambda o: abs(o.pos[0] - px) + abs(o.pos[1] - py)  # noqa: E731
    for key, cls, mob_id, cap in (
        ("cows", objects.Cow, Mob.COW, MAX_COWS),
        ("zombies", objects.Zombie, Mob.ZOMBIE, MAX_ZOMBIES),
        ("skeletons", objects.Skeleton, Mob.SKELETON, MAX_SKELETONS),
        ("arrows", objects.Arrow, Mob.ARROW, MAX_ARROWS),
    ):
        for obj in mobs[cls]:
            mob_map[obj.pos[1], obj.pos[0]] = int(mob_id)
        pos, status = out[f"{key}_pos"][i], out[f"{key}_status"][i]
        pos[:], status[:] = 0, 0
        if key == "arrows":
            out["arrows_dir"][i] = 0
        for slot, obj in enumerate(sorted(mobs[cls], key=dist)[:cap]):
            pos[slot] = (obj.pos[1], obj.pos[0])
            cooldown = getattr(obj, "cooldown", getattr(obj, "reload", 0))
            status[slot] = (1, obj.health, cooldown)
            if key == "arrows":
                out["arrows_dir"][i, slot] = (obj.facing[1], obj.facing[0])

    out["map"][i], out["mob_map"][i] = grid, mob_map
    out["light_level"][i] = world.daylight
    out["plants_pos"][i], out["plants_status"][i] = 0, 0
    for slot, plant in enumerate(sorted(plants, key=dist)[:MAX_PLANTS]):
        out["plants_pos"][i, slot] = (plant.pos[1], plant.pos[0])
        out["plants_status"][i, slot] = (1, plant.grown, plant.ripe)
    out["player_pos"][i] = (py, px)
    out["player_dir"][i] = _FACING_TO_DIR[tuple(int(v) for v in player.facing)]
    inv = player.inventory
    out["player_vitals"][i] = [inv["health"], inv["food"], inv["drink"], inv["energy"]]
    out["player_counters"][i] = [player._recover, player._hunger, player._thirst, player._fatigue]
    out["player_sleeping"][i] = player.sleeping
    out["inventory"][i] = [inv[name] for name in ITEM_NAMES]
    out["achievements"][i] = [player.achievements[name] > 0 for name in ACHIEVEMENT_NAMES]
    out["timestep"][i] = env._step
