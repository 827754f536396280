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

from pathlib import Path

import pytest  # noqa: E402


@pytest.fixture(scope="session")
def craftax_env():
    from zoo.envs import make_env

    return make_env("craftax", num_envs=2, pixels=True)


@pytest.fixture(scope="session")
def crafter_env():
    from zoo.envs import make_env

    return make_env("crafter", num_envs=2, pixels=True)


@pytest.fixture(scope="session")
def steve_play(tmp_path_factory) -> Path:
    """4 scripted crafter episodes of 120 steps in 2 shards (C-Steve-1 data tests)."""
    from zoo.cli import main

    out = tmp_path_factory.mktemp("play")
    argv = ["data", "generate", "--expert", "scripted", "--env", "crafter", "--episodes", "4",
            "--episodes-per-shard", "2", "--max-steps", "120", "--seed", "0", "--out", str(out),
            "--no-progress"]
    assert main(argv) == 0
    return out


@pytest.fixture(scope="session")
def steve_cclip(tmp_path_factory) -> Path:
    """A tiny random C-CLIP saved as Lightning saves lit_models.cclip.CCLIP."""
    import torch

    from zoo.models.cclip import build_cclip

    torch.manual_seed(0)
    model = build_cclip("smoke", vision_layers=1, text_layers=1)
    checkpoint = tmp_path_factory.mktemp("cclip") / "cclip.ckpt"
    torch.save({
        "hyper_parameters": {"model": "smoke", "vision_layers": 1, "text_layers": 1},
        "state_dict": {f"model.{k}": v for k, v in model.state_dict().items()},
    }, checkpoint)
    return checkpoint


@pytest.fixture(scope="session")
def steve_embeddings(steve_play: Path, steve_cclip: Path, tmp_path_factory) -> Path:
    """`zoo goals embed` of steve_play with steve_cclip."""
    from zoo.cli import main

    out = tmp_path_factory.mktemp("embed")
    argv = ["goals", "embed", "--checkpoint", str(steve_cclip), "--src", str(steve_play), "--out",
            str(out), "--no-progress"]
    assert main(argv) == 0
    return out
