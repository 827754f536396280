"""Tests keep their compiled caches to themselves (see tests/conftest.py)."""

import os
import tempfile


def test_caches_of_this_run_are_private() -> None:
    """numba and the JAX cache use the folder conftest.py made for this run."""
    import numba.core.config

    from zoo.envs.craftax_env import enable_compilation_cache

    assert numba.core.config.CACHE_DIR == os.environ["NUMBA_CACHE_DIR"]
    enable_compilation_cache()
    import jax

    assert jax.config.jax_compilation_cache_dir == os.environ["ZOO_JAX_CACHE"]
    assert os.environ["NUMBA_CACHE_DIR"].startswith(tempfile.gettempdir())
