"""Video -> text retrieval metrics for C-CLIP (paper section 5.3: R@1/5/10 and mean rank over 64).

The candidate set, precisely: held-out clips are cut, in data order, into groups of
`group_size` (64) consecutive clips; within a group every clip is a query and the group's 64
captions (each clip's own caption text, duplicates kept) are the candidates. CrafterCaption has
only 61 template captions, so a group usually holds several clips with the same caption id; any
candidate with the query's caption id counts as a correct answer.

A query's rank is 1 + the number of candidates with another caption id that score *at least* as
high as its best-scoring correct candidate: ties are broken against the model (pessimistically),
so a collapsed model whose embeddings are all equal ranks every query last, not first. R@k is the
fraction of queries whose rank is <= k and MeanR the mean rank; both come from the same ranks, so
they cannot disagree about a tie. (torchmetrics' hit rate breaks ties by sort order, arbitrarily:
on an all-equal matrix it gave R@1 ~ 3% while a strict ">" rank gave MeanR = 1.) A trailing group
shorter than `group_size` is dropped so every query competes against the same number of
candidates.
"""

from collections.abc import Sequence

import torch
from torch.nn import functional as F

DEFAULT_TOP_KS = (1, 5, 10)


def best_correct_rank(
    similarity: torch.Tensor, query_ids: torch.Tensor, candidate_ids: torch.Tensor
) -> torch.Tensor:
    """(Q,) 1-based rank of each query's best-scoring correct candidate, ties counted against it."""
    correct = query_ids[:, None] == candidate_ids[None, :]
    if not bool(correct.any(dim=1).all()):
        raise ValueError("every query needs at least one candidate with its own caption id")
    best_correct = similarity.masked_fill(~correct, float("-inf")).max(dim=1, keepdim=True).values
    return 1 + ((similarity >= best_correct) & ~correct).sum(dim=1)


def retrieval_metrics(
    similarity: torch.Tensor,
    query_ids: torch.Tensor,
    candidate_ids: torch.Tensor,
    top_ks: Sequence[int] = DEFAULT_TOP_KS,
) -> dict[str, float]:
    """R@k and MeanR for one similarity matrix (Q queries x C candidates)."""
    if similarity.ndim != 2 or similarity.shape != (len(query_ids), len(candidate_ids)):
        raise ValueError(
            f"similarity must be (queries, candidates) = ({len(query_ids)}, {len(candidate_ids)}), "
            f"got {tuple(similarity.shape)}"
        )
    return _metrics_from_blocks([similarity], [query_ids], [candidate_ids], top_ks)


def grouped_retrieval_metrics(
    video_embeddings: torch.Tensor,
    text_embeddings: torch.Tensor,
    caption_ids: torch.Tensor,
    group_size: int = 64,
    top_ks: Sequence[int] = DEFAULT_TOP_KS,
) -> dict[str, float]:
    """Video -> text retrieval over consecutive groups of `group_size` clips (see module doc).

    Args:
        video_embeddings: (N, D) unit-norm clip embeddings.
        text_embeddings: (N, D) unit-norm embeddings of each clip's own caption.
        caption_ids: (N,) template caption id of each clip.

    Returns:
        {"R@1": ..., "R@5": ..., "R@10": ..., "MeanR": ..., "queries": N used}, recalls in [0, 1].
    """
    count = len(caption_ids)
    if video_embeddings.shape[0] != count or text_embeddings.shape[0] != count:
        raise ValueError(
            f"need one video and one text embedding per caption id ({count}), got "
            f"{video_embeddings.shape[0]} and {text_embeddings.shape[0]}"
        )
    if count < group_size:
        raise ValueError(f"retrieval needs at least {group_size} clips, got {count}")
    num_groups = count // group_size
    similarities, query_ids = [], []
    for group in range(num_groups):
        rows = slice(group * group_size, (group + 1) * group_size)
        similarities.append(video_embeddings[rows].float() @ text_embeddings[rows].float().T)
        query_ids.append(caption_ids[rows])
    return _metrics_from_blocks(similarities, query_ids, query_ids, top_ks)


def _metrics_from_blocks(
    similarities: list[torch.Tensor],
    query_ids: list[torch.Tensor],
    candidate_ids: list[torch.Tensor],
    top_ks: Sequence[int],
) -> dict[str, float]:
    ranks = torch.cat([
        best_correct_rank(similarity.detach().float().cpu(), queries.cpu(), candidates.cpu())
        for similarity, queries, candidates in zip(
            similarities, query_ids, candidate_ids, strict=True
        )
    ]).float()
    metrics = {f"R@{k}": float((ranks <= k).float().mean()) for k in top_ks}
    metrics["MeanR"] = float(ranks.mean())
    metrics["queries"] = float(len(ranks))
    return metrics


def top_captions(video: torch.Tensor, text: torch.Tensor, texts: list[str], k: int = 3) -> list[list[str]]:
    """The ``k`` caption texts nearest each video embedding (cosine; rows of ``text`` are the
    captions' embeddings in the order of ``texts``), best first: what a person checks by eye."""
    if text.shape[0] != len(texts):
        raise ValueError(f"{text.shape[0]} text embeddings for {len(texts)} caption texts")
    sims = F.normalize(video.float(), dim=-1) @ F.normalize(text.float(), dim=-1).T
    order = sims.topk(min(k, len(texts)), dim=-1).indices.tolist()
    return [[texts[i] for i in row] for row in order]
