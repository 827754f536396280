"""Crafter evaluation: play agents reproducibly, score them (Crafter Score, Return), report."""

from zoo.eval.report import format_table, summarize, write_report
from zoo.eval.rollout import EpisodeResult, episode_seed, evaluate
from zoo.metrics import ChunkedValue, chunked, crafter_score, normalized_return, success_rates
from zoo.eval.stats import load_stats, write_stats

__all__ = [
    "ChunkedValue", "EpisodeResult", "chunked", "crafter_score", "episode_seed", "evaluate",
    "format_table", "load_stats", "normalized_return", "success_rates", "summarize",
    "write_report", "write_stats",
]
