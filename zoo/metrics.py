"""Crafter's two headline metrics, computed exactly as crafter's own analysis code does.

Crafter Score (Hafner 2022): success rate s_i in percent of each of the 22 achievements over
a set of episodes, then ``exp(mean_i ln(1 + s_i)) - 1``: a geometric mean offset by 1 so that
an achievement never unlocked does not zero the score, and rare achievements weigh more than
in an arithmetic mean. Return is normalized by the 22 achievements (the paper, Appendix A).
The paper reports both as mean ± std over 5 chunks of 20 episodes (``chunked``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass

import numpy as np

from zoo.envs.constants import NUM_ACHIEVEMENTS


def success_rates(unlocks: np.ndarray) -> np.ndarray:
    """Percent of episodes in which each achievement was unlocked at least once.

    Args:
        unlocks: bool (episodes, 22), True where episode e unlocked achievement i.

    Returns:
        float64 (22,) in [0, 100].
    """
    unlocks = np.asarray(unlocks)
    if unlocks.ndim != 2 or unlocks.shape[1] != NUM_ACHIEVEMENTS or unlocks.shape[0] == 0:
        raise ValueError(
            f"unlocks has shape {unlocks.shape}, expected (episodes >= 1, {NUM_ACHIEVEMENTS})"
        )
    return 100.0 * unlocks.astype(bool).mean(axis=0)


def crafter_score(rates_percent: np.ndarray) -> float:
    """``exp(mean_i ln(1 + s_i)) - 1`` over success rates in percent (0 -> 0, all 100 -> 100)."""
    rates = np.asarray(rates_percent, dtype=np.float64)
    if rates.ndim != 1 or rates.size == 0:
        raise ValueError(f"rates_percent has shape {rates.shape}, expected (achievements,)")
    if not ((rates >= 0) & (rates <= 100)).all():
        raise ValueError(f"success rates must be percentages in [0, 100], got {rates.tolist()}")
    return float(np.exp(np.mean(np.log1p(rates))) - 1.0)


def normalized_return(returns: np.ndarray) -> np.ndarray:
    """Episode return in percent of the maximum 22 (+1 per achievement; the paper's unit)."""
    return np.asarray(returns, dtype=np.float64) / NUM_ACHIEVEMENTS * 100.0


@dataclass(frozen=True)
class ChunkedValue:
    """A metric over consecutive episode chunks: mean ± std across chunks, and over all episodes."""

    mean: float
    std: float  # population std (numpy's default, ddof=0) of the per-chunk values
    per_chunk: list[float]
    pooled: float  # the metric over all episodes at once
    chunk_sizes: list[int]

    def to_dict(self) -> dict:
        return asdict(self)


def chunked(
    values_fn: Callable[[np.ndarray], float], episodes: np.ndarray, chunks: int = 5
) -> ChunkedValue:
    """Apply ``values_fn`` to each of ``chunks`` consecutive slices of ``episodes`` (first axis).

    The paper's protocol is 100 episodes in 5 chunks of 20. When the count does not divide,
    chunk sizes differ by at most one (``np.array_split``); fewer episodes than chunks is an
    error because a chunk would be empty.
    """
    episodes = np.asarray(episodes)
    if chunks < 1:
        raise ValueError(f"chunks must be >= 1, got {chunks}")
    if len(episodes) < chunks:
        raise ValueError(f"{len(episodes)} episodes cannot fill {chunks} chunks: need one each")
    parts = np.array_split(episodes, chunks)
    values = np.array([float(values_fn(part)) for part in parts])
    return ChunkedValue(
        mean=float(values.mean()),
        std=float(values.std()),
        per_chunk=values.tolist(),
        pooled=float(values_fn(episodes)),
        chunk_sizes=[len(part) for part in parts],
    )
