"""C-CLIP's video -> text retrieval (R@k, MeanR over groups of held-out clips) as a torchmetrics
Metric, so that the embeddings of every DDP rank are gathered by the library, not by hand.

The math and the pessimistic tie rule live in zoo.eval.retrieval alone (zoo never imports
torchmetrics); this module only accumulates the embeddings and hands them over.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from lightning.pytorch.utilities import rank_zero_warn
from torchmetrics import Metric
from torchmetrics.utilities import dim_zero_cat

from zoo.eval.retrieval import DEFAULT_TOP_KS, grouped_retrieval_metrics


class GroupedRetrieval(Metric):
    """Video -> text R@k and MeanR of zoo.eval.retrieval.grouped_retrieval_metrics.

    Groups are consecutive clips in update order (rank after rank under DDP), so the states are
    lists concatenated on sync, never reduced per batch. They are not saved in checkpoints.
    """

    is_differentiable = False
    higher_is_better = None  # R@k: higher; MeanR: lower
    full_state_update = False

    video: list[torch.Tensor]
    text: list[torch.Tensor]
    caption_id: list[torch.Tensor]

    def __init__(
        self, group_size: int = 64, top_ks: Sequence[int] = DEFAULT_TOP_KS, prefix: str = "",
        **kwargs,
    ) -> None:  # fmt: skip
        """Args:
            group_size: candidate captions per query (paper: 64).
            top_ks: the k of each R@k.
            prefix: put before every key that compute() returns (e.g. "val/").
            **kwargs: torchmetrics.Metric options (process_group, compute_on_cpu, ...).
        """
        super().__init__(**kwargs)
        if group_size < 1:
            raise ValueError(f"group_size must be >= 1, got {group_size}")
        self.group_size = group_size
        self.top_ks = tuple(top_ks)
        self.prefix = prefix
        for name in ("video", "text", "caption_id"):
            self.add_state(name, default=[], dist_reduce_fx="cat", persistent=False)

    def update(self, video: torch.Tensor, text: torch.Tensor, caption_ids: torch.Tensor) -> None:
        """Add a batch: (B, D) unit-norm clip and caption embeddings, (B,) caption ids."""
        self.video.append(video.detach().float())
        self.text.append(text.detach().float())
        self.caption_id.append(caption_ids.detach())

    def compute(self) -> dict[str, float]:
        """{prefix + "R@k", ..., "MeanR", "queries"}; {} with a warning below one full group."""
        # Lists of batches before a DDP sync, one tensor after it.
        caption_ids = dim_zero_cat(self.caption_id) if len(self.caption_id) else torch.empty(0)
        if len(caption_ids) < self.group_size:
            rank_zero_warn(
                f"{self.prefix}retrieval: {len(caption_ids)} held-out clips are fewer than the "
                f"group size {self.group_size}; R@k and MeanR skipped"
            )
            return {}
        metrics = grouped_retrieval_metrics(
            dim_zero_cat(self.video), dim_zero_cat(self.text), caption_ids,
            self.group_size, self.top_ks,
        )  # fmt: skip
        return {f"{self.prefix}{key}": value for key, value in metrics.items()}
