"""Symmetric InfoNCE where clips sharing a template caption are positives of each other."""

import torch
import torch.nn.functional as F


def positive_mask(caption_ids: torch.Tensor) -> torch.Tensor:
    """(B,) caption ids -> (B, B) bool, True where two samples have the same template caption."""
    if caption_ids.ndim != 1:
        raise ValueError(f"caption_ids must be 1-D (batch,), got shape {tuple(caption_ids.shape)}")
    return caption_ids[:, None] == caption_ids[None, :]


def multi_positive_infonce(
    video_embeddings: torch.Tensor,
    text_embeddings: torch.Tensor,
    caption_ids: torch.Tensor,
    logit_scale: torch.Tensor | float,
) -> torch.Tensor:
    """Mean of the video->text and text->video cross-entropies with soft multi-positive targets.

    Two clips in a batch labelled with the same template caption (their texts may be different
    paraphrases) are not negatives of each other: the target of video i is uniform over all
    texts j with caption_ids[j] == caption_ids[i], and likewise for text -> video. With all ids
    distinct this is CLIP's loss. Embeddings are expected unit-norm; logits are
    logit_scale * cosine similarity.
    """
    if video_embeddings.shape != text_embeddings.shape or video_embeddings.ndim != 2:
        raise ValueError(
            "video and text embeddings must both be (batch, dim), got "
            f"{tuple(video_embeddings.shape)} and {tuple(text_embeddings.shape)}"
        )
    if caption_ids.shape != video_embeddings.shape[:1]:
        raise ValueError(
            f"caption_ids must be ({video_embeddings.shape[0]},), got {tuple(caption_ids.shape)}"
        )
    logits = logit_scale * video_embeddings @ text_embeddings.T
    positives = positive_mask(caption_ids).to(logits.dtype)
    targets = positives / positives.sum(dim=1, keepdim=True)
    # The mask is symmetric, so the same targets serve both directions.
    video_to_text = -(targets * F.log_softmax(logits, dim=1)).sum(dim=1).mean()
    text_to_video = -(targets * F.log_softmax(logits.T, dim=1)).sum(dim=1).mean()
    return (video_to_text + text_to_video) / 2
