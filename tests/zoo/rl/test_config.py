"""Every shipped RL config loads, names existing weights, and bad configs say what is wrong."""

from __future__ import annotations

from pathlib import Path

import pytest

from zoo.rl.config import AGENTS, RLConfig

ROOT = Path(__file__).resolve().parents[3]
CONFIGS = sorted((ROOT / "configs" / "rl").glob("*.yaml"))


def test_there_is_a_config_per_agent_and_long_horizon_task():
    names = {p.stem for p in CONFIGS}
    assert names == {f"{a}_t{k}" for a in AGENTS for k in range(1, 5)}


@pytest.mark.parametrize("path", CONFIGS, ids=lambda p: p.stem)
def test_shipped_configs_load_and_point_at_shipped_weights(path):
    config = RLConfig.from_yaml(path)
    assert path.stem == f"{config.agent}_{config.task.lower()}"
    for key in ("checkpoint", "cclip", "prior"):
        if getattr(config, key):
            assert (ROOT / getattr(config, key)).exists(), f"{path.name}: {key} is missing"
    if config.agent == "cvpt_rl":
        assert (config.lora_rank, config.lora_alpha, config.kl_coef) == (16, 16.0, 0.1)  # paper
    if config.agent == "ppo_steve":
        assert (config.option_steps, config.cfg_scale) == (10, 1.5)  # paper


def test_bad_values_name_the_field():
    base = RLConfig.from_yaml(CONFIGS[0]).to_dict()
    with pytest.raises(ValueError, match="agent='dqn'"):
        RLConfig.from_dict(base | {"agent": "dqn"})
    with pytest.raises(ValueError, match="divisible by num_minibatches"):
        RLConfig.from_dict(base | {"num_envs": 6, "num_minibatches": 4})
    with pytest.raises(ValueError, match=r"needs \['checkpoint'\]"):
        RLConfig.from_dict(base | {"agent": "ppo_steve", "checkpoint": None, "cclip": None,
                                   "prior": None})
    with pytest.raises(ValueError, match="cpu only"):
        RLConfig.from_dict(base | {"device": "cuda"})
    with pytest.raises(ValueError, match="lr must be float"):
        RLConfig.from_dict(base | {"lr": "fast"})


def test_the_pretrained_agent_is_checked_as_zoo_eval_checks_it():
    """PPO-Steve's C-Steve-1 is an ``AgentSpec``: its goal models come as a pair or from the
    export, with ``zoo eval``'s messages."""
    steve = str(ROOT / "weights" / "csteve1_cpu")
    base = RLConfig.from_yaml(CONFIGS[0]).to_dict() | {"agent": "ppo_steve", "checkpoint": steve}
    spec = RLConfig.from_dict(base).pretrained()
    assert (spec.kind, spec.checkpoint) == ("csteve1", steve)
    with pytest.raises(ValueError, match="give --cclip and --prior together"):
        RLConfig.from_dict(base | {"cclip": str(ROOT / "weights" / "cclip_cpu")}).pretrained()
    with pytest.raises(ValueError, match="starts from no pretrained agent"):
        RLConfig.from_dict(base | {"agent": "ppo_rnn"}).pretrained()
