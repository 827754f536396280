"""Craftax-Classic (JAX) as N batched envs with 144x144 pixels and the zoo's state schema.

One jitted call steps every env and exports the schema arrays, so a batch costs one device
round trip. Frames (16-pixel blocks, the paper's setting) are drawn from the exported state by
the renderer ``zoo.envs.render.choose_renderer`` picks: the numba kernel on the CPU (the same
pixels, tens of times faster), or Craftax's JAX renderer inside the jitted step.
Each env carries its own PRNG key seeded from its episode seed: an episode's course depends
on its seed and its actions only, never on which slot or batch size it ran in.
"""

from __future__ import annotations

import os

os.environ.setdefault("XLA_PYTHON_CLIENT_PREALLOCATE", "false")

from functools import partial  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from zoo.envs.base import Step, check_actions, check_seeds  # noqa: E402
from zoo.envs.constants import Block, Mob  # noqa: E402
from zoo.envs.render import choose_renderer, render_frames  # noqa: E402
from zoo.envs.schema import (  # noqa: E402
    MAX_ARROWS,
    MAX_COWS,
    MAX_SKELETONS,
    MAX_ZOMBIES,
    STATE_FIELDS,
)

BLOCK_PIXELS = 16


def enable_compilation_cache(path: str | None = None) -> None:
    """Reuse compiled XLA programs across processes (compiling step+render is slow on a CPU)."""
    import jax

    cache = path or os.environ.get(
        "ZOO_JAX_CACHE", str(Path.home() / ".cache" / "crafter-zoo" / "jax")
    )
    Path(cache).mkdir(parents=True, exist_ok=True)
    jax.config.update("jax_compilation_cache_dir", cache)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)


def env_renderer(renderer: str | None = None) -> str:
    """The renderer a Craftax env draws its frames with: ``choose_renderer``'s, where JAX's
    own renderer is the default on a GPU (the frame comes out of the jitted step there)."""
    import jax

    return choose_renderer(renderer, on_gpu=jax.default_backend() != "cpu")


def frame_renderer():
    """Craftax's JAX pixel renderer at the zoo's block size, as the uint8 frame the envs
    return (the ``jax`` renderer; ``zoo.envs.render`` draws the same pixels with numba).

    One definition for the env and for frames re-rendered from stored states
    (``zoo.data.rerender``), so both round and clip alike.
    """
    import jax.numpy as jnp
    from craftax.craftax_classic.renderer import make_craftax_pixel_renderer

    render = make_craftax_pixel_renderer(BLOCK_PIXELS)

    def frame(state):
        return jnp.clip(jnp.round(render(state)), 0, 255).astype(jnp.uint8)

    return frame


def _pad(x, n: int):
    """Pad the entity axis to the schema's maximum (Craftax keeps fewer of some mobs)."""
    import jax.numpy as jnp

    extra = n - x.shape[0]
    if extra <= 0:
        return x[:n]
    return jnp.concatenate([x, jnp.zeros((extra, *x.shape[1:]), x.dtype)], axis=0)


def _mobs(mobs, n: int):
    import jax.numpy as jnp

    status = jnp.stack([mobs.mask, mobs.health, mobs.attack_cooldown], axis=-1)
    return _pad(mobs.position, n), _pad(status.astype(jnp.int32), n)


def export_state(state) -> dict:
    """Map one Craftax EnvState onto the zoo's schema (jax arrays, cast to schema dtypes)."""
    import jax.numpy as jnp

    mob_map = jnp.zeros(state.map.shape, jnp.uint8)
    for mobs, mob_id in (
        (state.cows, Mob.COW),
        (state.zombies, Mob.ZOMBIE),
        (state.skeletons, Mob.SKELETON),
        (state.arrows, Mob.ARROW),
    ):
        rows = jnp.where(mobs.mask, mobs.position[:, 0], state.map.shape[0])
        mob_map = mob_map.at[rows, mobs.position[:, 1]].set(int(mob_id), mode="drop")

    plants_pos = state.growing_plants_positions
    ripe = state.map[plants_pos[:, 0], plants_pos[:, 1]] == int(Block.RIPE_PLANT)
    inv = state.inventory
    out = {
        "map": state.map,
        "mob_map": mob_map,
        "light_level": state.light_level,
        "plants_pos": plants_pos,
        "plants_status": jnp.stack(
            [state.growing_plants_mask, state.growing_plants_age, ripe & state.growing_plants_mask],
            axis=-1,
        ).astype(jnp.int32),
        "player_pos": state.player_position,
        "player_dir": state.player_direction,
        "player_vitals": jnp.stack(
            [state.player_health, state.player_food, state.player_drink, state.player_energy]
        ),
        "player_counters": jnp.stack(
            [state.player_recover, state.player_hunger, state.player_thirst, state.player_fatigue]
        ),
        "player_sleeping": state.is_sleeping,
        "inventory": jnp.stack(
            [
                inv.wood, inv.stone, inv.coal, inv.iron, inv.diamond, inv.sapling,
                inv.wood_pickaxe, inv.stone_pickaxe, inv.iron_pickaxe,
                inv.wood_sword, inv.stone_sword, inv.iron_sword,
            ]
        ),
        "achievements": state.achievements,
        "arrows_dir": _pad(state.arrow_directions, MAX_ARROWS),
        "timestep": state.timestep,
    }
    for key, mobs, n in (
        ("cows", state.cows, MAX_COWS),
        ("zombies", state.zombies, MAX_ZOMBIES),
        ("skeletons", state.skeletons, MAX_SKELETONS),
        ("arrows", state.arrows, MAX_ARROWS),
    ):
        out[f"{key}_pos"], out[f"{key}_status"] = _mobs(mobs, n)
    return {k: jnp.asarray(v).astype(STATE_FIELDS[k].dtype) for k, v in out.items()}


class CraftaxEnv:
    """N Craftax-Classic envs under jit(vmap); see the module docstring.

    Args:
        num_envs: envs stepped together.
        pixels: render 144x144 frames (set False for state-only experts).
        max_steps: episode length limit (crafter's and the paper's: 10,000).
        renderer: "numba" or "jax"; None: ``choose_renderer``'s choice ($ZOO_RENDERER, else
            numba, or jax when JAX runs on a GPU).
    """

    name = "craftax"

    def __init__(
        self, num_envs: int, pixels: bool = True, max_steps: int = 10_000,
        renderer: str | None = None,
    ) -> None:
        import jax
        import jax.numpy as jnp
        from craftax.craftax_classic.envs.craftax_state import EnvParams, StaticEnvParams
        from craftax.craftax_classic.game_logic import craftax_step, is_game_over
        from craftax.craftax_classic.world_gen import generate_world

        if num_envs < 1:
            raise ValueError(f"num_envs must be >= 1, got {num_envs}")
        enable_compilation_cache()
        self.num_envs = num_envs
        self.pixels = pixels
        self.renderer = env_renderer(renderer) if pixels else None
        self.params = EnvParams(max_timesteps=max_steps)
        self.static_params = StaticEnvParams()
        render = frame_renderer() if self.renderer == "jax" else None
        params, static = self.params, self.static_params

        def observe(state):
            return None if render is None else render(state), export_state(state)

        def strong(state):
            # Weak-typed leaves (player_direction after reset) would make every jitted
            # function compile twice: once for reset's output, once for step's.
            return jax.tree_util.tree_map(lambda x: jnp.asarray(x, dtype=jnp.asarray(x).dtype), state)

        # World generation runs env by env (lax.map), not under vmap: on XLA:CPU the vmapped
        # generator gave envs 9+ worlds that depended on the batch size (CHANGELOG).
        def reset_one(seed):
            key = jax.random.PRNGKey(seed)
            key, world_key = jax.random.split(key)
            return strong(generate_world(world_key, params, static)), key

        def step_one(state, key, action):
            key, step_key = jax.random.split(key)
            state, reward = craftax_step(step_key, state, action, params, static)
            done = is_game_over(state, params)
            return strong(state), key, reward.astype(jnp.float32), done

        @partial(jax.jit, donate_argnums=(0, 1))
        def reset_batch(states, keys, seeds, mask):
            new_states, new_keys = jax.lax.map(reset_one, seeds)
            pick = lambda new, old: jnp.where(  # noqa: E731
                mask.reshape((-1,) + (1,) * (new.ndim - 1)), new, old
            )
            states = jax.tree_util.tree_map(pick, new_states, states)
            keys = pick(new_keys, keys)
            frames, exported = jax.vmap(observe)(states)
            return states, keys, frames, exported

        @partial(jax.jit, donate_argnums=(0, 1))
        def step_batch(states, keys, actions):
            states, keys, reward, done = jax.vmap(step_one)(states, keys, actions)
            frames, exported = jax.vmap(observe)(states)
            return states, keys, frames, exported, reward, done

        @jax.jit
        def fresh(seeds):
            return jax.lax.map(reset_one, seeds)

        self._jax = jax
        self._reset_batch = reset_batch
        self._step_batch = step_batch
        self._states, self._keys = fresh(jnp.zeros(num_envs, jnp.uint32))

    @property
    def raw_state(self):
        """Craftax's own batched EnvState (for agents that read it, e.g. the PPO expert)."""
        return self._states

    def reset(self, seeds: np.ndarray, mask: np.ndarray | None = None) -> Step:
        seeds = check_seeds(seeds, self.num_envs)
        mask = np.ones(self.num_envs, bool) if mask is None else np.asarray(mask, bool)
        # Seeds are folded to uint32 (PRNGKey's range); distinct seeds below 2**32 stay distinct.
        seeds32 = (seeds % (1 << 32)).astype(np.uint32)
        self._states, self._keys, frames, exported = self._reset_batch(
            self._states, self._keys, seeds32, mask
        )
        frames, exported = self._fetch(frames, exported)
        zeros = np.zeros(self.num_envs, np.float32)
        return Step(frames, exported, zeros, np.zeros(self.num_envs, bool), self._states)

    def step(self, actions: np.ndarray) -> Step:
        actions = check_actions(actions, self.num_envs)
        self._states, self._keys, frames, exported, reward, done = self._step_batch(
            self._states, self._keys, actions
        )
        frames, exported = self._fetch(frames, exported)
        reward, done = self._jax.device_get((reward, done))
        return Step(frames, exported, reward, done, self._states)

    def _fetch(self, frames, exported) -> tuple[np.ndarray | None, dict]:
        """The step's frames and exported state as numpy; the numba renderer draws the frames
        here, from the exported state and ``state_rng`` (fetched in the same transfer)."""
        if self.renderer != "numba":
            return self._jax.device_get((frames, exported))
        exported, state_rng = self._jax.device_get((exported, self._states.state_rng))
        return render_frames(exported, state_rng), exported
