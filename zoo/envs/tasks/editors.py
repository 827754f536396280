"""Game edits for tasks, made in each game itself: the starting inventory and T1's peace."""

from __future__ import annotations

from functools import cache

import numpy as np

from zoo.envs.base import GameEnv, Step
from zoo.envs.constants import ITEM_NAMES
from zoo.envs.render import render_frames
from zoo.envs.tasks.specs import VITAL_MAX, TaskSpec


class Editor:
    def edit(self, step: Step, mask: np.ndarray, inventory: bool) -> None:
        """Apply the task to envs where ``mask`` and rewrite their rows of ``step`` in place."""
        raise NotImplementedError


class CrafterEditor(Editor):
    """Edits crafter's objects: the player's inventory dict and the world's mob objects."""

    def __init__(self, env, task: TaskSpec) -> None:
        from zoo.envs.crafter_env import material_lookup

        self.env, self.task = env, task
        self.lookup = material_lookup(env.raw_state[0]._world._mat_names)
        self.inventory = dict(zip(ITEM_NAMES, task.inventory_vector().tolist()))

    def edit(self, step: Step, mask: np.ndarray, inventory: bool) -> None:
        from crafter import objects

        from zoo.envs.crafter_env import export_crafter_state

        mobs = (objects.Zombie, objects.Skeleton, objects.Cow, objects.Arrow)
        for i in np.flatnonzero(mask):
            game = self.env.raw_state[i]
            player = game._player
            if inventory:
                player.inventory.update(self.inventory)
            if self.task.peaceful:
                for obj in [o for o in game._world.objects if isinstance(o, mobs)]:
                    game._world.remove(obj)
                for need in ("food", "drink", "energy"):
                    player.inventory[need] = VITAL_MAX
            export_crafter_state(game, self.lookup, step.state, i)
            if step.frames is not None:
                step.frames[i] = game.render()


@cache
def _craftax_edit_fn(pixels: bool):
    """The jitted batched edit (+ JAX render if ``pixels``, and export). What to edit is all
    arguments (item counts, which envs to pacify), so every task and TaskEnv shares one program."""
    import jax
    import jax.numpy as jnp

    from zoo.envs.craftax_env import BLOCK_PIXELS, export_state

    render = None
    if pixels:
        from craftax.craftax_classic.renderer import make_craftax_pixel_renderer

        render = make_craftax_pixel_renderer(BLOCK_PIXELS)

    def edit_one(state, set_inventory, make_peace, counts):
        inv = state.inventory
        new_inv = {}
        for k, name in enumerate(ITEM_NAMES):
            old = getattr(inv, name)
            new_inv[name] = jnp.where(set_inventory, counts[k].astype(old.dtype), old)
        changes = {"inventory": inv.replace(**new_inv)}
        for key in ("zombies", "skeletons", "cows", "arrows"):
            mobs = getattr(state, key)
            # Zero health too: a DO recomputes every mob's mask as health > 0.
            changes[key] = mobs.replace(
                mask=mobs.mask & ~make_peace,
                health=jnp.where(make_peace, jnp.zeros_like(mobs.health), mobs.health),
            )
        changes["mob_map"] = state.mob_map & ~make_peace
        for key in ("player_food", "player_drink", "player_energy"):
            old = getattr(state, key)
            changes[key] = jnp.where(make_peace, jnp.asarray(VITAL_MAX, old.dtype), old)
        state = state.replace(**changes)
        frame = None
        if render is not None:
            frame = jnp.clip(jnp.round(render(state)), 0, 255).astype(jnp.uint8)
        return state, frame, export_state(state)

    return jax.jit(jax.vmap(edit_one, in_axes=(0, 0, 0, None)))


class CraftaxEditor(Editor):
    """Edits the batched EnvState under one jitted call that also re-renders and re-exports."""

    def __init__(self, env, task: TaskSpec) -> None:
        import jax

        self.env = env
        self._jax = jax
        self._counts = task.inventory_vector().astype(np.int32)
        self._peaceful = task.peaceful
        # The frames come from the env's renderer: inside the jitted edit for "jax", from the
        # exported state afterwards for "numba" (zoo.envs.render), as the env's own steps.
        self._edit = _craftax_edit_fn(env.renderer == "jax")

    def edit(self, step: Step, mask: np.ndarray, inventory: bool) -> None:
        mask = np.asarray(mask, bool)
        states, frames, exported = self._edit(
            self.env.raw_state, mask & inventory, mask & self._peaceful, self._counts
        )
        # CraftaxEnv has no setter for its states; the edited pytree replaces them.
        self.env._states = states
        frames, exported, state_rng = self._jax.device_get((frames, exported, states.state_rng))
        for k, v in exported.items():
            step.state[k][mask] = v[mask]
        if step.frames is not None and self.env.renderer == "numba":
            edited = {k: v[mask] for k, v in exported.items()}
            step.frames[mask] = render_frames(edited, state_rng[mask])
        elif step.frames is not None:
            step.frames[mask] = frames[mask]
        step.raw = states


def make_editor(env: GameEnv, task: TaskSpec) -> Editor:
    """The editor of ``env``'s game for ``task``."""
    if env.name == "craftax":
        return CraftaxEditor(env, task)
    if env.name == "crafter":
        return CrafterEditor(env, task)
    raise ValueError(f"no task support for env {env.name!r}; expected craftax or crafter")
