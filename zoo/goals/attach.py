"""CrafterPlay chunks with C-Steve-1 goals: relabelled goal steps -> stored C-CLIP embeddings.

A pipeline stage over shard sources (``zoo.data.sequences.ShardSources``): for each CrafterPlay
shard it loads the matching ``zoo goals embed`` shard (same index, same episodes), relabels each
episode once at its first chunk (``zoo.goals.relabel``) and attaches to every chunk, per step,
``goal`` (float16 (n, D), zeros on unconditional pieces), ``goal_mask`` (bool (n,)) and
``goal_step`` (int64 (n,), the episode step whose clip is the goal; -1 where the goal is a
caption's embedding). Attached before the noop filter, so the filter drops a step's goal with
the step. On goal-directed CrafterPlay the goals can also be the commanded instructions
(``zoo.goals.sources``; an episode's instruction segments are in its chunks' meta).

The relabelling stream of an episode is ``episode_rng(seed, epoch, episode)``: new goals every
training epoch, the same in whatever worker reads the episode; ``start_epoch`` is called by
``datamodules.seeded_shuffle.EpochSeededStream`` like the shuffles' (validation stays at epoch 0).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from pathlib import Path

import numpy as np

from zoo.data.sequences import read_shards
from zoo.goals.embed import load_embedding_manifest, read_embedding_shard
from zoo.goals.relabel import RelabelParams, drop_sequence_goals, episode_rng, relabel_episode
from zoo.goals.sources import GoalSourceParams, command_rng, episode_goals

GOAL_KEYS = ("goal", "goal_mask", "goal_step")


class GoalAttacher:
    """Reads shards and attaches relabelled goals to their chunks (see the module docstring).

    ``sources`` says where goals come from (None: hindsight); commanded caption goals need
    ``prototypes``, the caption embeddings of ``zoo.goals.sources.caption_goals``.
    """

    def __init__(
        self,
        embeddings: str | Path,
        params: RelabelParams,
        skip_corrupt: bool,
        sources: GoalSourceParams | None = None,
        prototypes: dict[int, np.ndarray] | None = None,
    ) -> None:
        manifest = load_embedding_manifest(embeddings)
        self.root = Path(embeddings)
        self.files = {int(entry["index"]): entry["file"] for entry in manifest["shards"]}
        self.embed_dim = int(manifest["embed_dim"])
        self.params = params
        self.sources = sources or GoalSourceParams()
        self.prototypes = prototypes or {}
        self.skip_corrupt = skip_corrupt
        self.seed = 0
        self.epoch = 0

    def start_epoch(self, seed: int, epoch: int) -> None:
        self.seed, self.epoch = seed, epoch

    def _shard_embeddings(self, source: dict) -> dict[int, dict[str, np.ndarray]]:
        index = int(source["index"])
        if index not in self.files:
            raise FileNotFoundError(
                f"{self.root}: no goal embeddings for CrafterPlay shard {index} ({source['url']});"
                f" run `zoo goals embed` over the whole dataset (or train on the shards it covers)"
            )
        return read_embedding_shard(self.root / self.files[index])

    def __call__(self, sources: Iterable[dict]) -> Iterator[dict]:
        for source in sources:
            episodes = self._shard_embeddings(source)
            current: tuple[int, dict[str, np.ndarray]] | None = None
            for chunk in read_shards([source], self.skip_corrupt):
                episode = int(chunk["meta"]["episode"])
                if current is None or current[0] != episode:
                    current = (episode, self._relabel(episodes, chunk["meta"], source["url"]))
                offset, n = int(chunk["meta"]["offset"]), len(chunk["actions"])
                yield {
                    **chunk,
                    **{key: value[offset : offset + n] for key, value in current[1].items()},
                }

    def _relabel(
        self, episodes: dict[int, dict[str, np.ndarray]], meta: dict, url: str
    ) -> dict[str, np.ndarray]:
        episode = int(meta["episode"])
        if episode not in episodes:
            raise ValueError(f"{url}: episode {episode} has no goal embeddings in {self.root}")
        record = episodes[episode]
        if len(record["caption"]) != int(meta["episode_length"]):
            raise ValueError(
                f"{self.root}: episode {episode} has {len(record['caption'])} embedded steps, "
                f"{url} holds {meta['episode_length']}: embeddings of another dataset?"
            )
        labels = relabel_episode(
            record["caption"], self.params, episode_rng(self.seed, self.epoch, episode)
        )
        return episode_goals(
            record["goal"], labels, meta.get("instructions"), self.sources, self.prototypes,
            command_rng(self.seed, self.epoch, episode),
        )


class SequenceGoalDrop:
    """The stage after sequence packing that makes whole sequences unconditional (``uncond_per:
    sequence``, STEVE-1's), seeded by (seed, epoch) like the relabelling."""

    def __init__(self, uncond_prob: float) -> None:
        self.uncond_prob = uncond_prob
        self.seed = 0
        self.epoch = 0

    def start_epoch(self, seed: int, epoch: int) -> None:
        self.seed, self.epoch = seed, epoch

    def __call__(self, sequences: Iterable[dict]) -> Iterator[dict]:
        for sequence in sequences:
            yield drop_sequence_goals(sequence, self.uncond_prob, self.seed, self.epoch)


__all__ = ["GOAL_KEYS", "GoalAttacher", "SequenceGoalDrop"]
