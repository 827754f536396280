"""Does a goal land on its caption? Per-caption mean video embeddings and a goal's rank among them.

C-Steve-1 is trained on C-CLIP video embeddings of relabelled goals and told what to do at
test time through the text tower and the CVAE prior. When an instruction fails, these say
whether the goal pipeline is to blame: the prior's goal for "craft wood pickaxe" should lie
nearer the mean embedding of the clips captioned "craft wood pickaxe" than any other caption's.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
import torch
from torch.nn import functional as F


def caption_centroids(
    episodes: Iterable[dict[str, np.ndarray]], num_captions: int
) -> tuple[torch.Tensor, np.ndarray]:
    """Unit-norm mean goal per caption (num_captions, D) and its step count, over episodes of
    ``zoo goals embed`` ({"goal": (T, D), "caption": (T,)}; caption -1 = none, skipped)."""
    sums, counts = None, np.zeros(num_captions, np.int64)
    for episode in episodes:
        ids = episode["caption"].astype(np.int64)
        goal = episode["goal"].astype(np.float64)
        if sums is None:
            sums = np.zeros((num_captions, goal.shape[1]))
        keep = ids >= 0
        if (ids[keep] >= num_captions).any():
            raise ValueError(f"caption id {ids.max()} out of range for {num_captions} captions")
        np.add.at(sums, ids[keep], goal[keep])
        np.add.at(counts, ids[keep], 1)
    if sums is None:
        raise ValueError("no episodes to average")
    means = sums / np.maximum(counts, 1)[:, None]
    return F.normalize(torch.tensor(means, dtype=torch.float32), dim=-1), counts


def rank_of_caption(
    centroids: torch.Tensor, goal: torch.Tensor, caption: int, present: torch.Tensor
) -> int:
    """How many present captions' centroids lie nearer (cosine) to ``goal`` than ``caption``'s
    (0 = nearest). ``present`` (num_captions,) bool masks captions with too few steps."""
    if not present[caption]:
        raise ValueError(f"caption {caption} has no centroid (too few steps)")
    sims = (centroids @ F.normalize(goal.float(), dim=-1)).masked_fill(~present, -2.0)
    return int((sims > sims[caption]).sum())


def nearest_captions(
    centroids: torch.Tensor, goals: torch.Tensor, present: torch.Tensor
) -> torch.Tensor:
    """(N,) index of the nearest present centroid for each of N goals (N, D)."""
    sims = F.normalize(goals.float(), dim=-1) @ centroids.T
    return sims.masked_fill(~present, -2.0).argmax(1)
