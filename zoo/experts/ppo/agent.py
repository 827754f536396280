"""``PPOExpert``: a trained PPO-RNN checkpoint playing in ``CraftaxEnv``.

It reads Craftax's own state (``step.raw``), renders the symbolic observation it was trained
on, and keeps one GRU state and one PRNG key per env. A key is re-made from the episode seed
on ``reset``, so an episode's actions depend only on its seed (and the env's course).
"""

from __future__ import annotations

import os

os.environ.setdefault("XLA_PYTHON_CLIENT_PREALLOCATE", "false")

from pathlib import Path  # noqa: E402

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from craftax.craftax_classic.envs.craftax_state import EnvState  # noqa: E402
from craftax.craftax_classic.renderer import render_craftax_symbolic  # noqa: E402

from zoo.envs.base import Step, check_seeds  # noqa: E402
from zoo.envs.constants import NUM_ACTIONS  # noqa: E402
from zoo.envs.craftax_env import enable_compilation_cache  # noqa: E402
from zoo.experts.ppo.checkpoint import load_params, read_meta, resolve_checkpoint  # noqa: E402
from zoo.experts.ppo.network import ActorCriticRNN, sample_actions  # noqa: E402


class PPOExpert:
    """Acts for N Craftax envs from a PPO checkpoint; ``greedy`` takes the most likely action."""

    name = "ppo"
    needs_pixels = False  # reads the Craftax state (symbolic observation)

    def __init__(
        self, network: ActorCriticRNN, params, num_envs: int, greedy: bool = False
    ) -> None:
        if num_envs < 1:
            raise ValueError(f"num_envs must be >= 1, got {num_envs}")
        enable_compilation_cache()
        self.network = network
        self.params = params
        self.num_envs = num_envs
        self.greedy = greedy
        self._hidden = network.initial_hidden(num_envs)
        self._keys = jax.vmap(jax.random.PRNGKey)(jnp.zeros(num_envs, jnp.uint32))
        self._policy = jax.jit(self._policy_step, static_argnums=4)

    @classmethod
    def load(cls, path: str | Path, num_envs: int, greedy: bool = False) -> PPOExpert:
        """From a checkpoint folder or a run directory (its newest checkpoint)."""
        path = resolve_checkpoint(path)
        _, config = read_meta(path)
        from craftax.craftax_classic.envs.craftax_symbolic_env import (
            CraftaxClassicSymbolicEnvNoAutoReset,
        )

        env = CraftaxClassicSymbolicEnvNoAutoReset()
        obs_dim = env.observation_space(env.default_params).shape[0]
        network = ActorCriticRNN(NUM_ACTIONS, config.layer_size)
        params = load_params(path, network.init_params(jax.random.PRNGKey(0), obs_dim))
        return cls(network, params, num_envs, greedy)

    def reset(self, seeds: np.ndarray, mask: np.ndarray | None = None) -> None:
        seeds = check_seeds(seeds, self.num_envs)
        mask = np.ones(self.num_envs, bool) if mask is None else np.asarray(mask, bool)
        if mask.shape != (self.num_envs,):
            raise ValueError(f"mask has shape {mask.shape}, expected ({self.num_envs},)")
        seeds32 = jnp.asarray((seeds % (1 << 32)).astype(np.uint32))
        fresh_keys = jax.vmap(jax.random.PRNGKey)(seeds32)
        mask_j = jnp.asarray(mask)
        self._keys = jnp.where(mask_j[:, None], fresh_keys, self._keys)
        self._hidden = jnp.where(mask_j[:, None], 0.0, self._hidden)

    def act(self, step: Step) -> np.ndarray:
        if not isinstance(step.raw, EnvState):
            raise TypeError(
                f"the PPO expert reads Craftax's state (step.raw), got {type(step.raw).__name__}: "
                f"it needs --env craftax"
            )
        if step.raw.player_position.shape[0] != self.num_envs:
            raise ValueError(
                f"step holds {step.raw.player_position.shape[0]} envs, the agent was built for "
                f"{self.num_envs}"
            )
        actions, self._hidden, self._keys = self._policy(
            self.params, self._hidden, self._keys, step.raw, self.greedy
        )
        return np.asarray(actions, np.int32)

    def _policy_step(self, params, hidden, keys, states, greedy: bool):
        obs = jax.vmap(render_craftax_symbolic)(states)
        no_reset = jnp.zeros((1, self.num_envs), bool)
        hidden, logits, _ = self.network.apply(params, hidden, obs[None], no_reset)
        logits = logits[0]
        split = jax.vmap(jax.random.split)(keys)
        keys, sample_keys = split[:, 0], split[:, 1]
        if greedy:
            actions = jnp.argmax(logits, axis=-1).astype(jnp.int32)
        else:
            actions = jax.vmap(sample_actions)(sample_keys, logits)
        return actions, hidden, keys
