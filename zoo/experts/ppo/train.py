"""The jitted PPO-RNN update: rollout, GAE, clipped-surrogate epochs over env-split minibatches.

``build_update_block(config)`` returns one jitted function that runs ``updates_per_block``
updates with ``lax.scan`` (each update itself a scan over ``num_steps`` env steps), so the
host only sees one call per block. Episode statistics are accumulated inside the scan.
"""

from __future__ import annotations

import functools
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import optax

from zoo.envs.constants import NUM_ACHIEVEMENTS
from zoo.experts.ppo.config import PPOConfig
from zoo.experts.ppo.network import (
    ActorCriticRNN,
    action_log_prob,
    entropy,
    sample_actions,
)
from zoo.experts.ppo.vec_env import CraftaxTrainEnv, EnvBatch


class TrainState(NamedTuple):
    params: Any
    opt_state: Any


class EpisodeTally(NamedTuple):
    """Running per-env episode counters, and sums over the episodes that ended."""

    running_return: jax.Array  # (N,) crafter reward so far in each env's episode
    running_length: jax.Array  # (N,)
    episodes: jax.Array  # () episodes ended
    return_sum: jax.Array  # () crafter return summed over ended episodes
    length_sum: jax.Array
    deaths: jax.Array
    unlocked: jax.Array  # (22,) episodes that unlocked each achievement

    @classmethod
    def zeros(cls, num_envs: int) -> EpisodeTally:
        z = jnp.zeros((), jnp.float32)
        return cls(
            jnp.zeros(num_envs, jnp.float32), jnp.zeros(num_envs, jnp.float32),
            z, z, z, z, jnp.zeros(NUM_ACHIEVEMENTS, jnp.float32),
        )

    def cleared(self) -> EpisodeTally:
        """Keep the running counters, zero the sums (start of a logging block)."""
        zeros = EpisodeTally.zeros(self.running_return.shape[0])
        return zeros._replace(
            running_return=self.running_return, running_length=self.running_length
        )


class Runner(NamedTuple):
    train: TrainState
    env: EnvBatch
    obs: jax.Array  # (N, D) observation the next action is taken at
    first: jax.Array  # (N,) bool: obs is the first of an episode (resets the GRU)
    hidden: jax.Array  # (N, H)
    tally: EpisodeTally
    key: jax.Array


class Transition(NamedTuple):
    obs: jax.Array
    first: jax.Array
    action: jax.Array
    log_prob: jax.Array
    value: jax.Array
    reward: jax.Array
    done: jax.Array


def gae(rewards, values, dones, last_value, gamma: float, lam: float):
    """Generalised advantage estimates and value targets over the time axis (axis 0).

    ``dones[t]`` means the episode ended with step t's reward, so nothing is bootstrapped past
    it (the time limit counts as an end, as in Craftax's PPO).
    """

    def backward(carry, step):
        advantage, next_value = carry
        reward, value, done = step
        keep = 1.0 - done.astype(jnp.float32)
        delta = reward + gamma * next_value * keep - value
        advantage = delta + gamma * lam * keep * advantage
        return (advantage, value), advantage

    init = (jnp.zeros_like(last_value), last_value)
    _, advantages = jax.lax.scan(backward, init, (rewards, values, dones), reverse=True)
    return advantages, advantages + values


def ppo_loss(params, network: ActorCriticRNN, config: PPOConfig, hidden0, batch: Transition,
             advantages, targets):
    """Craftax's PPO loss: clipped surrogate, clipped value loss, entropy bonus."""
    _, logits, value = network.apply(params, hidden0, batch.obs, batch.first)
    log_prob = action_log_prob(logits, batch.action)
    log_ratio = log_prob - batch.log_prob
    ratio = jnp.exp(log_ratio)
    adv = (advantages - advantages.mean()) / (advantages.std() + 1e-8)
    clipped_ratio = jnp.clip(ratio, 1.0 - config.clip_eps, 1.0 + config.clip_eps)
    policy_loss = -jnp.minimum(ratio * adv, clipped_ratio * adv).mean()

    value_clipped = batch.value + jnp.clip(value - batch.value, -config.clip_eps, config.clip_eps)
    value_loss = 0.5 * jnp.maximum((value - targets) ** 2, (value_clipped - targets) ** 2).mean()
    ent = entropy(logits).mean()
    total = policy_loss + config.vf_coef * value_loss - config.ent_coef * ent
    stats = {
        "loss": total,
        "policy_loss": policy_loss,
        "value_loss": value_loss,
        "entropy": ent,
        "approx_kl": ((ratio - 1.0) - log_ratio).mean(),
        "clip_frac": (jnp.abs(ratio - 1.0) > config.clip_eps).mean(),
    }
    return total, stats


def learning_rate(config: PPOConfig, update: jax.Array | int) -> jax.Array:
    """Craftax's schedule: constant per update, linear from lr to 0 over the run."""
    if not config.anneal_lr:
        return jnp.asarray(config.lr, jnp.float32)
    return config.lr * (1.0 - jnp.asarray(update, jnp.float32) / config.num_updates)


def make_optimizer(config: PPOConfig) -> optax.GradientTransformation:
    steps_per_update = config.update_epochs * config.num_minibatches
    return optax.chain(
        optax.clip_by_global_norm(config.max_grad_norm),
        optax.adam(
            lambda count: learning_rate(config, count // steps_per_update), eps=config.adam_eps
        ),
    )


class Trainer(NamedTuple):
    """The pieces a run needs, built once per config (compiles are cached with them)."""

    config: PPOConfig
    env: CraftaxTrainEnv
    network: ActorCriticRNN
    optimizer: optax.GradientTransformation
    init: Any  # jitted (key) -> Runner with fresh params, episodes and GRU state
    update_block: Any  # jitted (runner) -> (runner, per-update metrics)


@functools.cache
def build_trainer(config: PPOConfig) -> Trainer:
    env = CraftaxTrainEnv(config.num_envs, config.max_episode_steps, config.death_penalty)
    network = ActorCriticRNN(env.num_actions, config.layer_size)
    optimizer = make_optimizer(config)
    n = config.num_envs

    def init(key: jax.Array) -> Runner:
        net_key, env_key, run_key = jax.random.split(key, 3)
        params = network.init_params(net_key, env.obs_dim)
        batch, obs = env.reset(env_key)
        return Runner(
            TrainState(params, optimizer.init(params)), batch, obs, jnp.ones(n, bool),
            network.initial_hidden(n), EpisodeTally.zeros(n), run_key,
        )

    def env_step(runner: Runner, _):
        key, act_key, step_key = jax.random.split(runner.key, 3)
        hidden, logits, value = network.apply(
            runner.train.params, runner.hidden, runner.obs[None], runner.first[None]
        )
        logits, value = logits[0], value[0]
        action = sample_actions(act_key, logits)
        batch, out = env.step(runner.env, action, step_key)

        t = runner.tally
        ended = out.done.astype(jnp.float32)
        episode_return = t.running_return + out.crafter_reward
        episode_length = t.running_length + 1.0
        tally = EpisodeTally(
            running_return=episode_return * (1.0 - ended),
            running_length=episode_length * (1.0 - ended),
            episodes=t.episodes + ended.sum(),
            return_sum=t.return_sum + (episode_return * ended).sum(),
            length_sum=t.length_sum + (episode_length * ended).sum(),
            deaths=t.deaths + out.died.sum(dtype=jnp.float32),
            unlocked=t.unlocked + out.achievements.sum(axis=0, dtype=jnp.float32),
        )
        transition = Transition(
            runner.obs, runner.first, action, action_log_prob(logits, action), value,
            out.reward, out.done,
        )
        runner = Runner(runner.train, batch, out.obs, out.done, hidden, tally, key)
        return runner, transition

    def minibatch_step(train: TrainState, minibatch):
        hidden0, batch, advantages, targets = minibatch
        grads, stats = jax.grad(ppo_loss, has_aux=True)(
            train.params, network, config, hidden0, batch, advantages, targets
        )
        updates, opt_state = optimizer.update(grads, train.opt_state, train.params)
        return TrainState(optax.apply_updates(train.params, updates), opt_state), stats

    def epoch(carry, _):
        train, key, data = carry
        key, perm_key = jax.random.split(key)
        order = jax.random.permutation(perm_key, n)
        per_mb = n // config.num_minibatches

        def split(x, env_axis):
            x = jnp.take(x, order, axis=env_axis)
            groups = (config.num_minibatches, per_mb)
            x = x.reshape(x.shape[:env_axis] + groups + x.shape[env_axis + 1 :])
            return jnp.moveaxis(x, env_axis, 0)

        hidden0, traj, advantages, targets = data
        minibatches = (
            split(hidden0, 0),
            jax.tree_util.tree_map(lambda x: split(x, 1), traj),
            split(advantages, 1),
            split(targets, 1),
        )
        train, stats = jax.lax.scan(minibatch_step, train, minibatches)
        return (train, key, data), stats

    def update(runner: Runner, _):
        hidden0 = runner.hidden
        runner, traj = jax.lax.scan(env_step, runner, None, length=config.num_steps)
        _, _, last_value = network.apply(
            runner.train.params, runner.hidden, runner.obs[None], runner.first[None]
        )
        advantages, targets = gae(
            traj.reward, traj.value, traj.done, last_value[0], config.gamma, config.gae_lambda
        )
        key, epoch_key = jax.random.split(runner.key)
        (train, _, _), stats = jax.lax.scan(
            epoch, (runner.train, epoch_key, (hidden0, traj, advantages, targets)), None,
            length=config.update_epochs,
        )
        stats = jax.tree_util.tree_map(jnp.mean, stats)
        return runner._replace(train=train, key=key), stats

    def update_block(runner: Runner, num_updates: int):
        runner = runner._replace(tally=runner.tally.cleared())
        return jax.lax.scan(update, runner, None, length=num_updates)

    return Trainer(
        config, env, network, optimizer,
        init=jax.jit(init),
        update_block=jax.jit(update_block, static_argnums=1, donate_argnums=0),
    )
