"""numba's on-disk cache for the kernel, keyed on every source file the kernel compiles in.

``numba.njit(cache=True)`` keys a cached function on its own bytecode, and drops its index when
the size or mtime of the one file that defines it changes. The kernel inlines functions and
freezes constants from other files (``shade``, ``noise``, ``llvm``, ``textures``,
``zoo.envs.constants``), so an edit there alone (say ``shade.SLEEP_BLUE``) would keep drawing
the old pixels from the cache. ``njit_cached`` folds a hash of all those files' bytes into
every cache entry's key: an edit to any of them recompiles, and undoing it finds the old entry.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable
from pathlib import Path

import numba
from numba.core.caching import FunctionCache

_PACKAGE = Path(__file__).resolve().parent
SOURCES = (*sorted(_PACKAGE.glob("*.py")), _PACKAGE.parent / "constants.py")
"""The files compiled code can hold: this package's and the view's size and block ids."""


def source_digest(paths: tuple[Path, ...] = SOURCES) -> str:
    """sha256 of the files' names and bytes, in order."""
    h = hashlib.sha256()
    for path in paths:
        data = path.read_bytes()
        h.update(f"{path.name}:{len(data)}:".encode())
        h.update(data)
    return h.hexdigest()


SOURCE_DIGEST = source_digest()


class _SourceKeyedCache(FunctionCache):
    """numba's function cache with ``SOURCE_DIGEST`` in every index key."""

    def _index_key(self, sig, codegen) -> tuple:
        return (*super()._index_key(sig, codegen), SOURCE_DIGEST)


def njit_cached(**options) -> Callable:
    """``numba.njit(cache=True, **options)``, its cache entries keyed on ``SOURCES`` too."""

    def decorate(fn: Callable) -> Callable:
        dispatcher = numba.njit(cache=True, **options)(fn)
        dispatcher._cache = _SourceKeyedCache(dispatcher.py_func)
        return dispatcher

    return decorate
