"""Shared fixtures: compiled envs are expensive (JAX compile ~20 s), so build each once."""

from __future__ import annotations

import os

os.environ.setdefault("XLA_PYTHON_CLIENT_PREALLOCATE", "false")
os.environ.setdefault("WANDB_MODE", "offline")

import pytest  # noqa: E402


@pytest.fixture(scope="session")
def craftax_env():
    from zoo.envs import make_env

    return make_env("craftax", num_envs=2, pixels=True)


@pytest.fixture(scope="session")
def crafter_env():
    from zoo.envs import make_env

    return make_env("crafter", num_envs=2, pixels=True)
