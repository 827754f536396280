"""Actor-critic with a GRU core, shaped like Craftax's PPO-RNN agent.

obs -> Dense(layer) -> ReLU -> GRU(layer) -> {actor: 2 x (Dense(layer) -> ReLU) -> logits,
critic: 2 x (Dense(layer) -> ReLU) -> value}. Orthogonal inits with the usual PPO gains
(sqrt(2) for the embedding, 2 for the head layers, 0.01 for the logits, 1 for the value).
The GRU state is zeroed wherever ``resets`` marks the first step of an episode, so one
sequence may span several episodes.
"""

from __future__ import annotations

import math

import flax.linen as nn
import jax
import jax.numpy as jnp


class ResettingGRU(nn.Module):
    """One GRU step that first forgets the state of envs starting a new episode."""

    features: int

    @nn.compact
    def __call__(self, carry: jax.Array, inputs: tuple[jax.Array, jax.Array]):
        x, resets = inputs
        carry = jnp.where(resets[:, None], jnp.zeros_like(carry), carry)
        return nn.GRUCell(self.features)(carry, x)


# The GRU unrolled over the leading (time) axis with shared parameters.
ScannedGRU = nn.scan(
    ResettingGRU,
    variable_broadcast="params",
    split_rngs={"params": False},
    in_axes=0,
    out_axes=0,
)


def _dense(features: int, gain: float, name: str) -> nn.Dense:
    return nn.Dense(
        features,
        kernel_init=nn.initializers.orthogonal(gain),
        bias_init=nn.initializers.constant(0.0),
        name=name,
    )


class ActorCriticRNN(nn.Module):
    """Maps (hidden (N,H), obs (T,N,D), resets (T,N)) to (hidden, logits (T,N,A), value (T,N))."""

    num_actions: int
    layer_size: int

    @nn.compact
    def __call__(self, hidden: jax.Array, obs: jax.Array, resets: jax.Array):
        embedding = nn.relu(_dense(self.layer_size, math.sqrt(2), "embed")(obs))
        hidden, core = ScannedGRU(self.layer_size, name="gru")(hidden, (embedding, resets))
        logits = _dense(self.num_actions, 0.01, "logits")(self._trunk(core, "actor"))
        value = _dense(1, 1.0, "value")(self._trunk(core, "critic"))
        return hidden, logits, value[..., 0]

    def _trunk(self, x: jax.Array, name: str) -> jax.Array:
        for i in range(2):
            x = nn.relu(_dense(self.layer_size, 2.0, f"{name}_{i}")(x))
        return x

    def initial_hidden(self, num_envs: int) -> jax.Array:
        return jnp.zeros((num_envs, self.layer_size), jnp.float32)

    def init_params(self, key: jax.Array, obs_dim: int):
        """Parameters for observations of size ``obs_dim`` (shapes do not depend on N or T)."""
        return self.init(
            key,
            self.initial_hidden(1),
            jnp.zeros((1, 1, obs_dim), jnp.float32),
            jnp.zeros((1, 1), bool),
        )


def log_probs(logits: jax.Array) -> jax.Array:
    """Categorical log-probabilities over the last axis."""
    return jax.nn.log_softmax(logits, axis=-1)


def action_log_prob(logits: jax.Array, actions: jax.Array) -> jax.Array:
    return jnp.take_along_axis(log_probs(logits), actions[..., None], axis=-1)[..., 0]


def entropy(logits: jax.Array) -> jax.Array:
    logp = log_probs(logits)
    return -jnp.sum(jnp.exp(logp) * logp, axis=-1)


def sample_actions(key: jax.Array, logits: jax.Array) -> jax.Array:
    """One categorical sample per row of ``logits`` (Gumbel-max via jax.random.categorical)."""
    return jax.random.categorical(key, logits, axis=-1).astype(jnp.int32)
