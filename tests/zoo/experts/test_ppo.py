"""PPO-RNN expert: config files, GAE, the death penalty, a smoke run, checkpoints, resume, agent.

Compiles dominate (~30 s for the smoke run's update block), so one module-scoped smoke run
is shared by the checkpoint, resume and agent tests.
"""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from zoo.envs.base import Step
from zoo.envs.constants import NUM_ACTIONS
from zoo.experts.ppo import PPOConfig, PPOExpert, train_ppo
from zoo.experts.ppo.checkpoint import (
    checkpoint_dir,
    list_checkpoints,
    load_opt_state,
    load_params,
    load_rollout,
    read_meta,
    save_checkpoint,
)
from zoo.experts.ppo.network import ActorCriticRNN
from zoo.experts.ppo.train import build_trainer, gae, make_optimizer
from zoo.experts.ppo.vec_env import CraftaxTrainEnv, EnvBatch

REPO = Path(__file__).resolve().parents[3]
SMOKE_YAML = REPO / "configs" / "expert_ppo_smoke.yaml"
PAPER_YAML = REPO / "configs" / "expert_ppo.yaml"


@pytest.fixture(scope="module")
def smoke_config() -> PPOConfig:
    return PPOConfig.from_yaml(SMOKE_YAML)


@pytest.fixture(scope="module")
def smoke_run(smoke_config, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("ppo") / "run"
    train_ppo(smoke_config, out, log=lambda line: None)
    return out


def _records(run: Path) -> list[dict]:
    return [json.loads(line) for line in (run / "metrics.jsonl").read_text().splitlines()]


# --- config -----------------------------------------------------------------------------


def test_paper_config_has_the_papers_values():
    config = PPOConfig.from_yaml(PAPER_YAML)
    assert (config.lr, config.gamma, config.num_steps) == (2e-4, 0.99, 64)
    assert config.num_minibatches == 8
    assert (config.update_epochs, config.max_grad_norm, config.num_envs) == (4, 1.0, 4096)
    assert config.total_timesteps == 1_000_000_000
    assert config.death_penalty == -10.0
    assert config.num_updates == 1_000_000_000 // (4096 * 64)


def _write_yaml(tmp_path: Path, change: dict, drop: str | None = None) -> Path:
    values = PPOConfig.from_yaml(SMOKE_YAML).to_dict() | change
    if drop:
        del values[drop]
    path = tmp_path / "bad.yaml"
    path.write_text("\n".join(f"{k}: {json.dumps(v)}" for k, v in values.items()))
    return path


def test_config_unknown_key_names_key_and_file(tmp_path):
    path = _write_yaml(tmp_path, {"learning_rate": 1e-3})
    with pytest.raises(ValueError, match=r"learning_rate") as err:
        PPOConfig.from_yaml(path)
    assert str(path) in str(err.value)


def test_config_missing_key_names_key_and_file(tmp_path):
    path = _write_yaml(tmp_path, {}, drop="gae_lambda")
    with pytest.raises(ValueError, match=r"missing key\(s\) \['gae_lambda'\]") as err:
        PPOConfig.from_yaml(path)
    assert str(path) in str(err.value)


def test_config_type_and_consistency_errors(tmp_path):
    with pytest.raises(ValueError, match=r"num_steps must be int, got 'many'"):
        PPOConfig.from_yaml(_write_yaml(tmp_path, {"num_steps": "many"}))
    with pytest.raises(ValueError, match=r"num_envs \(8\) must be divisible by num_minibatches"):
        PPOConfig.from_yaml(_write_yaml(tmp_path, {"num_minibatches": 3}))
    with pytest.raises(FileNotFoundError, match="nowhere.yaml"):
        PPOConfig.from_yaml(tmp_path / "nowhere.yaml")
    # YAML 1.1 reads "1e9" as a string; an exact number in that form is accepted.
    config = PPOConfig.from_yaml(_write_yaml(tmp_path, {"total_timesteps": "1e4"}))
    assert config.total_timesteps == 10_000


# --- GAE and reward -----------------------------------------------------------------------


def test_gae_matches_hand_computed_values():
    # gamma 0.9, lambda 0.5; the episode ends after step 1, so step 1 does not bootstrap.
    rewards = jnp.array([[1.0], [0.0], [2.0]])
    values = jnp.array([[0.5], [0.2], [0.1]])
    dones = jnp.array([[False], [True], [False]])
    advantages, targets = gae(rewards, values, dones, jnp.array([0.4]), gamma=0.9, lam=0.5)
    # t=2: 2 + 0.9*0.4 - 0.1 = 2.26
    # t=1: 0 - 0.2 = -0.2 (done: no bootstrap, no carry)
    # t=0: delta 1 + 0.9*0.2 - 0.5 = 0.68; + 0.9*0.5*(-0.2) = 0.59
    np.testing.assert_allclose(advantages[:, 0], [0.59, -0.2, 2.26], rtol=1e-6)
    np.testing.assert_allclose(targets[:, 0], [1.09, 0.0, 2.36], rtol=1e-6)


def test_death_penalty_on_death_not_on_time_limit(craftax_env):
    env = CraftaxTrainEnv(num_envs=3, max_episode_steps=50, death_penalty=-10.0)
    # The shared fixture may hold any state other tests left; start from fresh worlds.
    craftax_env.reset(np.array([11, 12]))
    # Three live Craftax states (the fixture's two and a copy of the first): env 0 dies
    # (health 0), env 1 reaches the time limit, env 2 plays on.
    states = jax.tree_util.tree_map(lambda x: jnp.concatenate([x, x[:1]]), craftax_env.raw_state)
    states = states.replace(
        player_health=states.player_health.at[0].set(0),
        timestep=jnp.array([3, 49, 7], jnp.int32),
    )
    pool = states.replace(timestep=jnp.array([100, 200, 300], jnp.int32))  # marks pool worlds
    batch = EnvBatch(states, pool, jnp.zeros((), jnp.int32))
    batch, out = jax.jit(env.step)(batch, jnp.zeros(3, jnp.int32), jax.random.PRNGKey(2))
    np.testing.assert_array_equal(out.done, [True, True, False])
    np.testing.assert_array_equal(out.died, [True, False, False])
    np.testing.assert_allclose(out.reward - out.crafter_reward, [-10.0, 0.0, 0.0])
    # The ended envs take the pool's next unused worlds in order; env 2 keeps going.
    np.testing.assert_array_equal(batch.states.timestep, [100, 200, 8])
    assert int(batch.pool_used) == 2
    np.testing.assert_array_equal(out.obs, jax.vmap(env.env.get_obs)(batch.states))


# --- smoke training, checkpoints, resume --------------------------------------------------


def test_smoke_run_writes_metrics_and_checkpoints(smoke_run, smoke_config):
    records = _records(smoke_run)
    assert [r["update"] for r in records] == [1, 2]
    assert [r["env_steps"] for r in records] == [128, 256]
    for record in records:
        # the 12-step time limit ends every episode inside a 16-step rollout
        assert record["episodes"] == smoke_config.num_envs
        for key, value in record.items():
            assert value is not None and math.isfinite(value), (key, value)
        assert 0.0 < record["entropy"] <= math.log(NUM_ACTIONS) + 1e-5
    assert [p.name for p in list_checkpoints(smoke_run)] == ["update_0000001", "update_0000002"]
    meta, saved = read_meta(smoke_run)
    assert (meta["update"], meta["env_steps"], saved) == (2, 256, smoke_config)
    assert PPOConfig.from_yaml(smoke_run / "config.yaml") == smoke_config


def test_checkpoint_round_trip_gives_identical_outputs(tmp_path, smoke_config):
    network = ActorCriticRNN(NUM_ACTIONS, smoke_config.layer_size)
    params = network.init_params(jax.random.PRNGKey(3), obs_dim=20)
    optimizer = make_optimizer(smoke_config)
    opt_state = optimizer.init(params)
    _, opt_state = jax.jit(optimizer.update)(params, opt_state, params)  # non-trivial moments
    save_checkpoint(tmp_path, smoke_config, 7, params, opt_state, keep=1)

    target = network.init_params(jax.random.PRNGKey(4), obs_dim=20)
    loaded = load_params(tmp_path, target)
    obs = jax.random.normal(jax.random.PRNGKey(5), (3, 2, 20))
    resets = jnp.array([[True, True], [False, True], [False, False]])
    hidden = network.initial_hidden(2)
    apply = jax.jit(network.apply)
    for a, b in zip(apply(params, hidden, obs, resets), apply(loaded, hidden, obs, resets)):
        np.testing.assert_array_equal(a, b)
    restored = load_opt_state(tmp_path, optimizer.init(target))
    jax.tree_util.tree_map(np.testing.assert_array_equal, restored, opt_state)


def test_resume_continues_to_the_configured_step_count(smoke_run, smoke_config, tmp_path):
    run = tmp_path / "run"
    shutil.copytree(smoke_run, run)
    shutil.rmtree(run / "checkpoints" / "update_0000002")
    with pytest.raises(FileExistsError, match="--resume"):
        train_ppo(smoke_config, run, log=lambda line: None)
    with pytest.raises(ValueError, match="seed: checkpoint 0 vs given 1"):
        train_ppo(smoke_config.replace(seed=1), run, resume=True, log=lambda line: None)

    lines: list[str] = []
    train_ppo(smoke_config, run, resume=True, log=lines.append)
    assert "update 1" in lines[0]
    records = _records(run)
    assert [r["update"] for r in records] == [1, 2, 2]
    assert records[-1]["env_steps"] == 256
    meta, _ = read_meta(run)
    assert meta["update"] == 2


def test_resumed_run_ends_bit_identical_to_the_straight_run(smoke_run, smoke_config, tmp_path):
    """Interrupted after update 1 and resumed, against the straight 2-update smoke run: the
    same parameters, optimizer state and rollout state (envs, GRU, counters, PRNG key), bit for
    bit. (1+1 vs 2 reuses the shared smoke run; a 3-update run would compile another block.)"""
    run = tmp_path / "run"
    shutil.copytree(smoke_run, run)
    shutil.rmtree(checkpoint_dir(run, 2))
    train_ppo(smoke_config, run, resume=True, log=lambda line: None)

    template = build_trainer(smoke_config).init(jax.random.PRNGKey(0))
    straight, resumed = checkpoint_dir(smoke_run, 2), checkpoint_dir(run, 2)
    for load, like in (
        (load_params, template.train.params),
        (load_opt_state, template.train.opt_state),
        (load_rollout, tuple(template[1:])),
    ):
        jax.tree_util.tree_map(
            np.testing.assert_array_equal, load(resumed, like), load(straight, like)
        )


# --- the agent ------------------------------------------------------------------------------


def _play(agent: PPOExpert, env, seeds: np.ndarray, steps: int) -> np.ndarray:
    agent.reset(seeds)
    step = env.reset(seeds)
    actions = []
    for _ in range(steps):
        action = agent.act(step)
        actions.append(action)
        step = env.step(action)
    return np.stack(actions)


def test_expert_acts_in_craftax_deterministically(smoke_run, craftax_env):
    agent = PPOExpert.load(smoke_run, num_envs=craftax_env.num_envs)
    seeds = np.array([11, 12])
    first = _play(agent, craftax_env, seeds, steps=6)
    assert first.dtype == np.int32 and first.shape == (6, 2)
    assert first.min() >= 0 and first.max() < NUM_ACTIONS
    np.testing.assert_array_equal(_play(agent, craftax_env, seeds, steps=6), first)
    assert not np.array_equal(_play(agent, craftax_env, np.array([13, 14]), steps=6), first)


def test_expert_rejects_non_craftax_steps(smoke_run):
    agent = PPOExpert.load(smoke_run, num_envs=2)
    zeros = np.zeros(2, np.float32)
    step = Step(frames=None, state={}, reward=zeros, done=zeros.astype(bool), raw=None)
    with pytest.raises(TypeError, match="--env craftax"):
        agent.act(step)


def test_cli_parses_train_arguments():
    from zoo.cli import build_parser

    args = build_parser().parse_args(
        ["expert", "train", "--config", str(SMOKE_YAML), "--total-timesteps", "1e3", "--seed", "4"]
        + ["--resume"]
    )
    assert (args.total_timesteps, args.seed, args.resume, args.wandb) == (1000, 4, True, False)
    assert args.handler.__name__ == "run_train"
