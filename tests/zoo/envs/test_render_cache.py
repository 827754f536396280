"""numba's cache of the render kernel follows edits to every file the kernel compiles in.

numba alone keys a cached function on the file defining it, so an edit to a constant in
``shade.py`` would be drawn with the kernel.py entry compiled before it. ``zoo.envs.render.cache``
folds a hash of all the sources into each entry's key; these tests check that key and draw a
frame from an edited copy of the package.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np

SLEEP_BLUE = "SLEEP_BLUE = np.float32(8.0)"
DRAW = """
import json, sys
import numpy as np
import zoo
from zoo.envs.render import render_frames
from zoo.envs.render.kernel import render_batch
from zoo.envs.schema import empty_state

state = empty_state(1)
state["player_sleeping"][:] = True  # sleep's grey carries shade.SLEEP_BLUE into every pixel
np.save(sys.argv[1], render_frames(state, np.zeros((1, 2), np.uint32)))
stats = render_batch.stats
print(json.dumps({"zoo": zoo.__file__, "hits": sum(stats.cache_hits.values()),
                  "misses": sum(stats.cache_misses.values())}))
"""


def _draw(root: Path, name: str) -> tuple[dict, np.ndarray]:
    """Draw a sleeping frame in a fresh interpreter that imports zoo from ``root``, with the
    numba cache in ``root``: (what it reports, the frame)."""
    env = {**os.environ, "PYTHONPATH": str(root), "NUMBA_CACHE_DIR": str(root / "numba")}
    frame = root / f"{name}.npy"
    done = subprocess.run([sys.executable, "-c", DRAW, str(frame)], cwd=root, env=env,
                          capture_output=True, text=True, timeout=240)
    assert done.returncode == 0, done.stderr
    report = json.loads(done.stdout.strip().splitlines()[-1])
    assert Path(report["zoo"]).is_relative_to(root)
    return report, np.load(frame)[0]


def test_an_edit_to_shade_recompiles_the_kernel(tmp_path: Path) -> None:
    """Copy the zoo package, draw, draw again (a cache hit, the same bytes), then brighten
    the sleep tint's blue in shade.py alone: the next draw recompiles and shows it."""
    import zoo

    shutil.copytree(Path(zoo.__file__).parent, tmp_path / "zoo",
                    ignore=shutil.ignore_patterns("__pycache__"))
    cold, before = _draw(tmp_path, "cold")
    warm, again = _draw(tmp_path, "warm")
    assert (cold["misses"], warm["hits"], warm["misses"]) == (1, 1, 0)
    np.testing.assert_array_equal(before, again)
    shade = tmp_path / "zoo" / "envs" / "render" / "shade.py"
    source = shade.read_text()
    assert source.count(SLEEP_BLUE) == 1
    shade.write_text(source.replace(SLEEP_BLUE, "SLEEP_BLUE = np.float32(12.0)"))
    edited, after = _draw(tmp_path, "edited")
    assert edited["misses"] == 1
    expected = before.copy()
    expected[:112, :, 2] += 4  # the map's blue only, 12 - 8 more; the panel as it was
    np.testing.assert_array_equal(after, expected)


def test_every_cached_function_keys_on_the_sources_digest(tmp_path: Path) -> None:
    """Every cached function of the kernel keys its entries on the digest of all the files
    it compiles in, and a byte more in any of those files changes the digest."""
    import numba
    from numba.core.caching import NullCache
    from numba.core.registry import cpu_target

    from zoo.envs import constants
    from zoo.envs.render import cache, kernel, llvm, noise, shade, textures

    files = {Path(m.__file__).resolve() for m in (kernel, shade, noise, llvm, textures, constants)}
    assert files <= set(cache.SOURCES)
    cached = [f for m in (kernel, shade, noise) for f in vars(m).values()
              if isinstance(f, numba.core.dispatcher.Dispatcher)
              and not isinstance(f._cache, NullCache) and f.py_func.__module__ == m.__name__]
    assert {f.__name__ for f in cached} >= {"render_batch", "blend_sprite", "uniform"}
    codegen = cpu_target.target_context.codegen()
    for f in cached:
        assert f._cache._index_key(numba.types.void(), codegen)[-1] == cache.SOURCE_DIGEST
    copies = []
    for path in cache.SOURCES:
        copies.append(tmp_path / path.name)
        shutil.copyfile(path, copies[-1])
    assert cache.source_digest(tuple(copies)) == cache.SOURCE_DIGEST
    for copy in copies:
        original = copy.read_bytes()
        copy.write_bytes(original + b"\n")
        assert cache.source_digest(tuple(copies)) != cache.SOURCE_DIGEST, copy.name
        copy.write_bytes(original)
