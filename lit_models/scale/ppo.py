"""The PPO expert's policy network (JAX/flax, zoo/experts/ppo) measured as the torch stages are.

FLOPs come from the jaxpr of the real functions (the rollout's forward, and ``jax.grad`` of
``ppo_loss``): 2 x M x N x K per ``dot_general``, a scan body times its length (XLA's own cost
analysis counts a loop body once, so it is not used). One env step costs a forward during the
rollout plus ``update_epochs`` forward+backward passes. Activation bytes are XLA's temporary
buffers of the compiled minibatch gradient at two minibatch sizes; the rollout buffer and the
env states are counted from shapes. The Craftax env itself, which the paper's 10 GPU-hours
mostly are, is not counted: the projection is of the network alone.
"""

from __future__ import annotations

import math
import os
from typing import Any

from lit_models.scale.measure import Measurement, best_time, cpu_peak_flops
from lit_models.scale.stages import Stage

os.environ.setdefault("XLA_PYTHON_CLIENT_PREALLOCATE", "false")

ENV_STATE_BYTES = 48 * 1024  # per env, measured (zoo/experts/ppo/checkpoint.py's docstring)


def _sub_jaxprs(value: Any) -> list:
    """The jaxprs inside an equation parameter (a closed or open jaxpr, or a tuple of them)."""
    if isinstance(value, (tuple, list)):
        return [j for v in value for j in _sub_jaxprs(v)]
    inner = getattr(value, "jaxpr", value)
    return [inner] if hasattr(inner, "eqns") else []


def jaxpr_flops(jaxpr) -> float:
    """Matmul FLOPs of a jaxpr, scans unrolled by their length and a cond's dearest branch."""
    total = 0.0
    for eqn in jaxpr.eqns:
        if eqn.primitive.name == "dot_general":
            (contract, _), _ = eqn.params["dimension_numbers"]
            lhs, out = eqn.invars[0].aval.shape, eqn.outvars[0].aval.shape
            total += 2.0 * math.prod(out) * math.prod(lhs[d] for d in contract)
        inner = [jaxpr_flops(j) for v in eqn.params.values() for j in _sub_jaxprs(v)]
        if eqn.primitive.name == "cond":
            total += max(inner, default=0.0)
        else:
            total += sum(inner) * eqn.params.get("length", 1)
    return total


def measure_ppo(stage: Stage, envs: tuple[int, int] = (2, 4), steps: int = 1) -> Measurement:
    """Count, measure and time the PPO network's minibatch update on the CPU."""
    import jax
    import jax.numpy as jnp
    import optax
    from craftax.craftax_classic.envs.craftax_symbolic_env import (
        CraftaxClassicSymbolicEnvNoAutoReset,
    )

    from zoo.envs.constants import NUM_ACTIONS
    from zoo.experts.ppo.config import PPOConfig
    from zoo.experts.ppo.network import ActorCriticRNN
    from zoo.experts.ppo.train import Transition, make_optimizer, ppo_loss

    config = PPOConfig.from_yaml(stage.path)
    env = CraftaxClassicSymbolicEnvNoAutoReset()
    obs_dim = env.observation_space(env.default_params).shape[0]
    network = ActorCriticRNN(NUM_ACTIONS, config.layer_size)
    params = network.init_params(jax.random.PRNGKey(0), obs_dim)
    optimizer = make_optimizer(config)
    t = config.num_steps

    def inputs(n: int) -> tuple:
        zeros = jnp.zeros((t, n), jnp.float32)
        flags = jnp.zeros((t, n), bool)
        batch = Transition(jnp.zeros((t, n, obs_dim)), flags, jnp.zeros((t, n), jnp.int32),
                           zeros, zeros, zeros, flags)  # fmt: skip
        return network.initial_hidden(n), batch, zeros, zeros

    def grad(p, hidden, batch, advantages, targets):
        return jax.grad(ppo_loss, has_aux=True)(p, network, config, hidden, batch, advantages,
                                                targets)[0]  # fmt: skip

    def step(p, opt_state, *minibatch):
        updates, opt_state = optimizer.update(grad(p, *minibatch), opt_state, p)
        return optax.apply_updates(p, updates), opt_state

    n = envs[0]
    hidden, batch, _, _ = inputs(n)
    act = jax.make_jaxpr(network.apply)(params, hidden, batch.obs[:1], batch.first[:1])
    forward = jaxpr_flops(act.jaxpr) / n
    train = jaxpr_flops(jax.make_jaxpr(grad)(params, *inputs(n)).jaxpr) / (n * t)
    temp = {}
    for size in envs:
        compiled = jax.jit(grad).lower(params, *inputs(size)).compile()
        temp[size] = float(compiled.memory_analysis().temp_size_in_bytes)
    run = jax.jit(step)
    state, minibatch = (params, optimizer.init(params)), inputs(n)
    seconds = best_time(lambda: jax.block_until_ready(run(*state, *minibatch)), steps, warmup=1)
    count = sum(x.size for x in jax.tree_util.tree_leaves(params))
    per_step_buffer = 4 * obs_dim + 4 * 6 + 2  # obs, action, log_prob, value, reward, adv, target
    return Measurement(
        params_trainable=count,
        params_frozen=0,
        flops_per_unit=forward + config.update_epochs * train,
        flops_batch=n,
        activation_bytes=temp,
        memory_batch=config.num_envs // config.num_minibatches,
        extra_bytes_per_sample=0.0,
        extra_bytes_fixed=float(config.num_envs * (t * per_step_buffer + ENV_STATE_BYTES)),
        cpu_step_s=seconds,
        cpu_step_batch=n,
        cpu_step_flops=train * n * t,
        cpu_peak_flops=cpu_peak_flops(),
        notes=[
            f"FLOPs per env step: rollout forward {forward:.3g} + {config.update_epochs} epochs x "
            f"forward+backward {train:.3g}, counted from the jaxpr (JAX network, not torch)",
            "samples are envs of a minibatch (x num_steps env steps); activations are XLA's "
            "temporary buffers of the compiled minibatch gradient",
            "rollout buffer and env states (48 KB/env) counted from shapes, not measured",
            "the Craftax env (JAX, on the GPU) is not counted: PPO's hours are mostly the env",
        ],
    )


__all__ = ["jaxpr_flops", "measure_ppo"]
