"""CrafterPlay with hindsight-relabelled goals for C-Steve-1 (paper §4.3, "Dataset Generation").

The CrafterPlay pipeline (shard order, episode splits, noop filter, packing, seeded shuffles)
unchanged, with one more per-step input: each chunk is read together with its ``zoo goals
embed`` shard and relabelled (``zoo.goals.attach.GoalAttacher``, ``zoo.goals.relabel``). Batches
are {frames, actions, first, episode, step} as for C-VPT plus goal float16 (B, S, D),
goal_mask bool (B, S) (False on unconditional pieces or sequences, whose goal is zeros) and goal_step int64
(B, S) (the episode step whose clip is the goal, -1 for a caption's embedding).

On goal-directed CrafterPlay (``zoo data generate --instructions``) the goals can instead be the
instructions the expert was commanded, or a mix of both (``goal_source``; ``zoo.goals.sources``).

Training goals are redrawn every epoch from (seed, epoch, episode); validation and test goals
are those of epoch 0, so their losses are comparable across a run.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Iterable, Iterator

import numpy as np

from datamodules.crafterplay import CrafterPlayDataModule
from zoo.data.manifest import require_manifest
from zoo.data.sequences import ShardSources
from zoo.goals.attach import GOAL_KEYS, GoalAttacher, SequenceGoalDrop
from zoo.goals.embed import GOAL_DTYPE, check_embeddings_match, load_embedding_manifest
from zoo.goals.relabel import RelabelMode, RelabelParams, UncondPer
from zoo.goals.sources import (
    CommandedGoal,
    CommandedSegments,
    GoalSource,
    GoalSourceParams,
    caption_goals,
)


class CSteve1DataModule(CrafterPlayDataModule):
    """CrafterPlay sequences with relabelled C-CLIP goals (see the module docstring)."""

    extra_keys = GOAL_KEYS

    def __init__(
        self,
        root: str,
        embeddings: str,
        relabel: RelabelMode = "event",
        min_gap: int = 1,
        max_gap: int = 10,
        uncond_prob: float = 0.1,
        uncond_per: UncondPer = "piece",
        goal_source: GoalSource = "hindsight",
        commanded_weight: float = 0.5,
        commanded_goal: CommandedGoal = "caption",
        commanded_segments: CommandedSegments = "all",
        cclip: str | None = None,
        prior: str | None = None,
        prior_samples: int = 32,
        partial_embeddings: bool = False,
        seq_len: int = 640,
        batch_size: int = 128,
        num_workers: int = 4,
        noop_filter: bool = True,
        min_noop_run: int = 20,
        val_fraction: float = 0.05,
        test_fraction: float = 0.05,
        split_salt: int = 0,
        shuffle_buffer: int = 64,
        train_batches_per_epoch: int | None = None,
        pin_memory: bool = True,
        seed: int | None = None,
        skip_corrupt: bool = False,
    ) -> None:
        """Args:
        root: CrafterPlay folder (manifest.json + shards) or its URL (docs/data.md).
        embeddings: its ``zoo goals embed`` folder (C-CLIP goal embeddings + step captions); a
            local folder.
        relabel: ``event`` (the paper's event-based packing: the window's first caption
            segment), ``event_any`` (any segment of the window, so an event also labels its
            run-up) or ``plain`` (STEVE-1's), for the relabelling ablation.
        min_gap: fewest steps a goal lies ahead (paper: 1).
        max_gap: most steps a goal lies ahead (paper: 10).
        uncond_prob: share of pieces (or sequences) without a goal, for classifier-free
            guidance (paper: 0.1).
        uncond_per: ``sequence``: ``uncond_prob`` zeroes a whole training sequence's goals
            (STEVE-1's, which the paper's C-Steve-1 follows; configs/csteve1.yaml); ``piece``:
            each relabelled piece of 1-10 steps (how the shipped CPU C-Steve-1 was trained).
        goal_source: ``hindsight`` (the paper's relabelling), ``commanded`` (the instruction the
            expert was pursuing at each step; goal-directed data only) or ``mix`` (per
            instruction segment, commanded with probability ``commanded_weight``).
        commanded_weight: ``mix``: the share of instruction segments with commanded goals.
        commanded_goal: a commanded goal is the ``caption``'s embedding (the mean C-CLIP
            embedding of its clips in ``embeddings``) or the ``completion`` clip's (the step that
            completed the instruction; segments that did not complete keep hindsight goals), or
            ``prior``: one of ``prior_samples`` goals the ``prior`` gives the caption's text
            (through ``cclip``'s text tower), drawn per segment: what a typed instruction gives.
        commanded_segments: ``all`` instruction segments get commanded goals, or only those
            whose instruction was ``completed`` (the others keep hindsight goals).
        cclip: C-CLIP checkpoint or export of ``commanded_goal: prior`` (its text tower; the
            one that embedded ``embeddings``).
        prior: CVAE prior checkpoint or export of ``commanded_goal: prior``.
        prior_samples: prior goals drawn per caption, once (seeded by the caption id).
        partial_embeddings: train on the CrafterPlay shards that ``embeddings`` covers (a
            ``zoo goals embed --shards A:B`` run) instead of refusing an incomplete folder.
        seq_len: steps per sequence (paper: 640).
        batch_size: sequences per batch (paper: 128).
        num_workers: DataLoader workers; each reads different shards.
        noop_filter: drop noop runs shorter than ``min_noop_run``.
        min_noop_run: noop runs at least this long are kept.
        val_fraction: share of episodes in the validation split.
        test_fraction: share of episodes in the test split.
        split_salt: changes which episodes land in which split.
        shuffle_buffer: training sequences held for shuffling.
        train_batches_per_epoch: epoch length in batches; None: one pass.
        pin_memory: page-locked batches for faster host-to-GPU copies.
        seed: seed of the training order and the goals; None: ``seed_everything``'s.
        skip_corrupt: skip unreadable shards with a warning instead of stopping.
        """
        super().__init__(
            root=root,
            seq_len=seq_len,
            batch_size=batch_size,
            num_workers=num_workers,
            noop_filter=noop_filter,
            min_noop_run=min_noop_run,
            val_fraction=val_fraction,
            test_fraction=test_fraction,
            split_salt=split_salt,
            shuffle_buffer=shuffle_buffer,
            train_batches_per_epoch=train_batches_per_epoch,
            pin_memory=pin_memory,
            seed=seed,
            skip_corrupt=skip_corrupt,
        )
        self.save_hyperparameters()  # after the parent's: this subclass's arguments win
        self.relabel_params = RelabelParams(relabel, min_gap, max_gap, uncond_prob, uncond_per)
        self.goal_sources = GoalSourceParams(
            goal_source, commanded_weight, commanded_goal, commanded_segments
        )
        self._embeddings_checked = False
        self._caption_goals: dict | None = None

    @property
    def shards(self) -> ShardSources:
        """The CrafterPlay shards, restricted to the embedded ones with ``partial_embeddings``."""
        if self._shards is None:
            shards = super().shards
            if self.hparams.partial_embeddings:
                manifest = load_embedding_manifest(self.hparams.embeddings)
                embedded = {int(entry["index"]) for entry in manifest["shards"]}
                total = len(shards.sources)
                shards.sources = [s for s in shards.sources if int(s["index"]) in embedded]
                warnings.warn(
                    f"training on the {len(shards.sources)} of {total} CrafterPlay shards that "
                    f"{self.hparams.embeddings} covers (partial_embeddings=true)",
                    stacklevel=2,
                )
        return self._shards

    @property
    def goal_dim(self) -> int:
        """Width of the goal embeddings (the C-CLIP embedding size)."""
        return GoalAttacher(self.hparams.embeddings, self.relabel_params, False).embed_dim

    def chunk_reader(self) -> Callable[[Iterable[dict]], Iterator[dict]]:
        if not self._embeddings_checked:  # here, not in __init__: a config check reads no data
            check_embeddings_match(
                self.hparams.embeddings, self.hparams.root, self.hparams.partial_embeddings
            )
            self._embeddings_checked = True
        return GoalAttacher(
            self.hparams.embeddings, self.relabel_params, self.hparams.skip_corrupt,
            self.goal_sources, self._commanded_caption_goals(),
        )

    def _commanded_caption_goals(self) -> dict | None:
        """The caption embeddings commanded goals need (None: they need none); refuses data
        that was not generated goal-directed."""
        sources = self.goal_sources
        if sources.source == "hindsight":
            return None
        schedule = require_manifest(self.hparams.root)["config"].get("instructions")
        if schedule is None:
            raise ValueError(
                f"goal_source={sources.source!r} needs goal-directed CrafterPlay, but "
                f"{self.hparams.root} was generated without instructions (zoo data generate "
                "--instructions); use goal_source: hindsight"
            )
        if self._caption_goals is None and sources.commanded_goal == "caption":
            self._caption_goals = caption_goals(self.hparams.embeddings)
        if self._caption_goals is None and sources.commanded_goal == "prior":
            self._caption_goals = self._prior_goals(schedule["caption_ids"])
        return self._caption_goals

    def _prior_goals(self, caption_ids: list[int]) -> dict[int, np.ndarray]:
        """caption id -> (prior_samples, D) goals of its text, as CSteve1Agent draws them."""
        from zoo.agents.csteve1_agent import GoalEncoder

        missing = [k for k in ("cclip", "prior") if not self.hparams.get(k)]
        if missing:
            raise ValueError(
                f"commanded_goal='prior' needs data.init_args.{' and '.join(missing)} "
                "(the C-CLIP and CVAE prior checkpoints that turn a caption's text into goals)"
            )
        if self.hparams.prior_samples < 1:
            raise ValueError(f"prior_samples={self.hparams.prior_samples} must be >= 1")
        encoder = GoalEncoder.load(self.hparams.cclip, self.hparams.prior)
        if encoder.goal_dim != self.goal_dim:
            raise ValueError(
                f"cclip {self.hparams.cclip} embeds {encoder.goal_dim}-d goals, the embeddings "
                f"{self.hparams.embeddings} are {self.goal_dim}-d"
            )
        goals = {}
        for caption_id in caption_ids:
            ids = [int(caption_id)] * self.hparams.prior_samples
            goals[int(caption_id)] = (
                encoder.from_caption_ids(ids, seed=int(caption_id)).numpy().astype(GOAL_DTYPE)
            )
        return goals

    def sequence_stages(self) -> list[Callable[[Iterable[dict]], Iterator[dict]]]:
        if self.relabel_params.uncond_per == "sequence":
            return [SequenceGoalDrop(self.relabel_params.uncond_prob)]
        return []


__all__ = ["CSteve1DataModule"]
