"""Craftax-Classic-Symbolic as a pure-JAX batch of envs for training, with explicit resets.

Generating a world costs about 50 env steps on CPU, so resetting every env on every step
(what auto-reset does under vmap) dominates the run. Instead a pool of ``num_envs`` fresh
worlds is generated only when the envs that finished have used it up, and each finished env
takes the next unused world (``jnp.where`` over the state tree). The cost of world generation
then follows the number of episodes actually finished, and no world is handed out twice.

The training reward is crafter's (+1 per new achievement, +-0.1 per health point) plus
``death_penalty`` on the step an episode ends by death; the time limit is not a death.
"""

from __future__ import annotations

import os

os.environ.setdefault("XLA_PYTHON_CLIENT_PREALLOCATE", "false")

from typing import Any, NamedTuple  # noqa: E402

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
from craftax.craftax_classic.envs.craftax_symbolic_env import (  # noqa: E402
    CraftaxClassicSymbolicEnvNoAutoReset,
)
from craftax.craftax_classic.game_logic import is_game_over  # noqa: E402

from zoo.envs.constants import NUM_ACHIEVEMENTS  # noqa: E402

NEVER = jnp.iinfo(jnp.int32).max


class EnvBatch(NamedTuple):
    """Everything the batched env carries between steps."""

    states: Any  # Craftax EnvState, leaves (N, ...)
    pool: Any  # Craftax EnvState of N fresh worlds
    pool_used: jax.Array  # int32 scalar: worlds of the pool already handed out


class StepOut(NamedTuple):
    obs: jax.Array  # (N, obs_dim) float32, of the new episode where done
    reward: jax.Array  # (N,) training reward: crafter's + death penalty
    crafter_reward: jax.Array  # (N,) crafter's own reward
    done: jax.Array  # (N,) bool: the episode ended on this step
    died: jax.Array  # (N,) bool: it ended by death, not by the time limit
    achievements: jax.Array  # (N, 22) bool: the ended episode's achievements (at done)


def _strong(tree):
    """Drop weak types (set by world generation) so scan carries keep one dtype."""
    return jax.tree_util.tree_map(lambda x: jnp.asarray(x, dtype=jnp.asarray(x).dtype), tree)


def _where(mask: jax.Array, new, old):
    def pick(a, b):
        return jnp.where(mask.reshape((-1,) + (1,) * (a.ndim - 1)), a, b)

    return jax.tree_util.tree_map(pick, new, old)


class CraftaxTrainEnv:
    """Pure functions over ``EnvBatch``; call them inside jit/scan."""

    def __init__(self, num_envs: int, max_episode_steps: int, death_penalty: float) -> None:
        self.env = CraftaxClassicSymbolicEnvNoAutoReset()
        self.params = self.env.default_params.replace(max_timesteps=max_episode_steps)
        self.num_envs = num_envs
        self.death_penalty = death_penalty
        self.num_actions = self.env.num_actions
        self.obs_dim = self.env.observation_space(self.params).shape[0]

    def new_worlds(self, key: jax.Array):
        keys = jax.random.split(key, self.num_envs)
        _, states = jax.vmap(self.env.reset_env, in_axes=(0, None))(keys, self.params)
        return _strong(states)

    def observe(self, states) -> jax.Array:
        return jax.vmap(self.env.get_obs)(states)

    def died(self, states) -> jax.Array:
        """Game over for a reason other than the time limit (health 0 or standing in lava)."""
        no_limit = self.params.replace(max_timesteps=NEVER)
        return jax.vmap(is_game_over, in_axes=(0, None))(states, no_limit)

    def reset(self, key: jax.Array) -> tuple[EnvBatch, jax.Array]:
        start_key, pool_key = jax.random.split(key)
        states = self.new_worlds(start_key)
        batch = EnvBatch(states, self.new_worlds(pool_key), jnp.zeros((), jnp.int32))
        return batch, self.observe(states)

    def step(self, batch: EnvBatch, actions: jax.Array, key: jax.Array) -> tuple[EnvBatch, StepOut]:
        step_key, pool_key = jax.random.split(key)
        keys = jax.random.split(step_key, self.num_envs)
        _, stepped, reward, done, _ = jax.vmap(self.env.step_env, in_axes=(0, 0, 0, None))(
            keys, batch.states, actions, self.params
        )
        stepped = _strong(stepped)
        reward = reward.astype(jnp.float32)
        died = done & self.died(stepped)

        batch = self._take_fresh_worlds(batch._replace(states=stepped), done, pool_key)
        out = StepOut(
            obs=self.observe(batch.states),
            reward=reward + self.death_penalty * died.astype(jnp.float32),
            crafter_reward=reward,
            done=done,
            died=died,
            achievements=stepped.achievements[:, :NUM_ACHIEVEMENTS] & done[:, None],
        )
        return batch, out

    def _take_fresh_worlds(self, batch: EnvBatch, done: jax.Array, key: jax.Array) -> EnvBatch:
        needed = done.sum(dtype=jnp.int32)
        refill = batch.pool_used + needed > self.num_envs
        pool, used = jax.lax.cond(
            refill,
            lambda: (self.new_worlds(key), jnp.zeros((), jnp.int32)),
            lambda: (batch.pool, batch.pool_used),
        )
        slot = used + jnp.cumsum(done, dtype=jnp.int32) - 1
        fresh = jax.tree_util.tree_map(lambda leaf: leaf[jnp.clip(slot, 0)], pool)
        return EnvBatch(_where(done, fresh, batch.states), pool, used + needed)
