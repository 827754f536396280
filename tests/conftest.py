"""Shared fixtures: compiled envs are expensive (JAX compile ~20 s), so build each once.

The JAX compilation cache and numba's cache go to a temp folder of this run (spawned workers
inherit it through the environment), so tests never read a user's cache (a stale program could
hide a bug) nor write beside the sources.
"""

from __future__ import annotations

import atexit
import os
import shutil
import tempfile

os.environ.setdefault("XLA_PYTHON_CLIENT_PREALLOCATE", "false")
os.environ.setdefault("WANDB_MODE", "offline")
_CACHES = tempfile.mkdtemp(prefix="crafter-zoo-test-caches-")
atexit.register(shutil.rmtree, _CACHES, ignore_errors=True)
os.environ["ZOO_JAX_CACHE"] = os.path.join(_CACHES, "jax")
os.environ["NUMBA_CACHE_DIR"] = os.path.join(_CACHES, "numba")

import pytest  # noqa: E402


@pytest.fixture(scope="session")
def craftax_env():
    from zoo.envs import make_env

    return make_env("craftax", num_envs=2, pixels=True)


@pytest.fixture(scope="session")
def crafter_env():
    from zoo.envs import make_env

    return make_env("crafter", num_envs=2, pixels=True)
