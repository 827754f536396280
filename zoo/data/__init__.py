"""CrafterPlay: expert episodes as WebDataset shards (generation, reading, noop filtering)."""

from zoo.data.noop import filter_noops, noop_flags, noop_runs
from zoo.data.reader import (
    CorruptShardError,
    ReadStats,
    decode_sample,
    iter_chunks,
    iter_episodes,
    list_shards,
)

__all__ = [
    "CorruptShardError", "ReadStats", "decode_sample", "filter_noops", "iter_chunks",
    "iter_episodes", "list_shards", "noop_flags", "noop_runs",
]
