"""``stats.jsonl`` in crafter's own Recorder format, so crafter's analysis scripts read our runs.

crafter's ``Recorder`` appends one JSON object per finished episode::

    {"length": 153, "reward": 2.1, "achievement_collect_coal": 0, ..., "achievement_wake_up": 1}

``reward`` is the episode return rounded to one decimal; ``achievement_<name>`` is how many
times the achievement was unlocked, keys in crafter's (alphabetical) order. Our rollouts know
whether each achievement was unlocked, not how often (Craftax keeps flags only), so we write
1/0; crafter's analysis only tests ``>= 1``, so scores computed from the file are unchanged.

Also the two comparisons the reports state beside Wilson 95% intervals (``disjoint_above``, the
"separated" of the instruction matrix and the task tables, and ``two_proportion_p``): disjoint
95% intervals are a much stricter bar than a 95% test, so the reports give both.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from zoo.envs.constants import ACHIEVEMENT_NAMES, NUM_ACHIEVEMENTS

# crafter.constants.achievements is sorted by name; its Recorder writes keys in that order.
CRAFTER_ACHIEVEMENT_ORDER: tuple[str, ...] = tuple(sorted(ACHIEVEMENT_NAMES))
STATS_KEYS: tuple[str, ...] = ("length", "reward") + tuple(
    f"achievement_{name}" for name in CRAFTER_ACHIEVEMENT_ORDER
)


def disjoint_above(a: Sequence[float], b: Sequence[float]) -> bool:
    """Whether interval ``a`` (low, high) lies wholly above ``b``: every "separated" verdict.
    Intervals that touch share a point, so they are not disjoint."""
    return a[0] > b[1]


def two_proportion_p(k1: int, n1: int, k2: int, n2: int) -> float:
    """Two-sided p-value of the pooled two-proportion z-test of k1/n1 against k2/n2 (normal
    approximation); 1.0 when the pooled rate is 0 or 1 (both rates equal, no variance)."""
    for k, n in ((k1, n1), (k2, n2)):
        if n < 1 or not 0 <= k <= n:
            raise ValueError(f"need 0 <= k <= n and n >= 1, got k={k}, n={n}")
    pooled = (k1 + k2) / (n1 + n2)
    se = math.sqrt(pooled * (1 - pooled) * (1 / n1 + 1 / n2))
    if se == 0:
        return 1.0
    z = (k1 / n1 - k2 / n2) / se
    return math.erfc(abs(z) / math.sqrt(2))  # 2 (1 - Phi(|z|))


def p_text(p: float) -> str:
    """A p-value as the reports print it: three decimals, "< 0.001" below that."""
    return "< 0.001" if p < 0.001 else f"{p:.3f}"


def stats_lines(unlocks: np.ndarray, returns: np.ndarray, lengths: np.ndarray) -> list[str]:
    """One crafter stats line per episode; ``unlocks`` is bool (episodes, 22) in zoo order."""
    unlocks = np.asarray(unlocks, bool)
    returns, lengths = np.asarray(returns), np.asarray(lengths)
    n = len(unlocks)
    if unlocks.shape != (n, NUM_ACHIEVEMENTS) or returns.shape != (n,) or lengths.shape != (n,):
        raise ValueError(
            f"expected unlocks (E, {NUM_ACHIEVEMENTS}), returns (E,), lengths (E,); got "
            f"{unlocks.shape}, {returns.shape}, {lengths.shape}"
        )
    column = {name: i for i, name in enumerate(ACHIEVEMENT_NAMES)}
    lines = []
    for e in range(n):
        record = {"length": int(lengths[e]), "reward": round(float(returns[e]), 1)}
        for name in CRAFTER_ACHIEVEMENT_ORDER:
            record[f"achievement_{name}"] = int(unlocks[e, column[name]])
        lines.append(json.dumps(record))
    return lines


def write_stats(
    path: str | Path, unlocks: np.ndarray, returns: np.ndarray, lengths: np.ndarray
) -> Path:
    """Write (overwrite) ``path`` with one crafter stats line per episode."""
    path = Path(path)
    path.write_text("".join(line + "\n" for line in stats_lines(unlocks, returns, lengths)))
    return path


def _number(value, path: Path, lineno: int, key: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ValueError(f"{path}:{lineno}: {key!r} is {value!r}, expected a number")
    return value


def load_stats(path: str | Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Read a crafter ``stats.jsonl`` (ours or crafter's Recorder's).

    Returns:
        unlocks bool (episodes, 22) in zoo achievement order (``count >= 1``, as crafter's
        analysis counts success), returns float64 (episodes,), lengths int64 (episodes,).
    """
    path = Path(path)
    known = set(ACHIEVEMENT_NAMES)
    unlocks, returns, lengths = [], [], []
    with path.open() as file:
        for lineno, line in enumerate(file, start=1):
            if not line.strip():
                continue
            try:
                record = json.loads(line)
            except json.JSONDecodeError as err:
                raise ValueError(f"{path}:{lineno}: not valid JSON ({err.msg})") from None
            if not isinstance(record, dict):
                kind = type(record).__name__
                raise ValueError(f"{path}:{lineno}: expected a JSON object, got {kind}")
            unknown = [
                key for key in record
                if key.startswith("achievement_") and key.removeprefix("achievement_") not in known
            ]
            if unknown:
                raise ValueError(f"{path}:{lineno}: unknown achievements {unknown} (not crafter's)")
            missing = [key for key in STATS_KEYS if key not in record]
            if missing:
                raise ValueError(f"{path}:{lineno}: missing keys {missing}")
            lengths.append(_number(record["length"], path, lineno, "length"))
            returns.append(_number(record["reward"], path, lineno, "reward"))
            unlocks.append([
                _number(record[f"achievement_{name}"], path, lineno, f"achievement_{name}") >= 1
                for name in ACHIEVEMENT_NAMES
            ])
    if not unlocks:
        raise ValueError(f"{path}: no episodes (empty stats file)")
    return (
        np.array(unlocks, bool),
        np.array(returns, np.float64),
        np.array(lengths, np.int64),
    )
