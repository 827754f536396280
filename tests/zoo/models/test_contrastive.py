"""Multi-positive InfoNCE against an explicit per-sample loop and against CLIP's loss."""

import math

import pytest
import torch
import torch.nn.functional as F

from zoo.models.contrastive import multi_positive_infonce, positive_mask


def unit(batch: int, dim: int, seed: int) -> torch.Tensor:
    generator = torch.Generator().manual_seed(seed)
    return F.normalize(torch.randn(batch, dim, generator=generator), dim=-1)


def reference_loss(video, text, ids, scale) -> float:
    """Written out one sample at a time: -mean over positives of log p(positive)."""
    batch = len(ids)
    total = 0.0
    for direction in ("video_to_text", "text_to_video"):
        for i in range(batch):
            queries, keys = (video, text) if direction == "video_to_text" else (text, video)
            scores = [scale * float(queries[i] @ keys[j]) for j in range(batch)]
            log_norm = math.log(sum(math.exp(s) for s in scores))
            positives = [j for j in range(batch) if ids[j] == ids[i]]
            total += -sum(scores[j] - log_norm for j in positives) / len(positives)
    return total / (2 * batch)


def test_matches_explicit_loop_with_repeated_caption_ids():
    ids = torch.tensor([3, 7, 3, 1, 7, 3])
    video, text = unit(6, 16, 0), unit(6, 16, 1)
    loss = multi_positive_infonce(video, text, ids, logit_scale=10.0)
    assert loss.item() == pytest.approx(reference_loss(video, text, ids.tolist(), 10.0), rel=1e-5)


def test_distinct_ids_reduce_to_clip_loss():
    video, text = unit(5, 8, 2), unit(5, 8, 3)
    logits = 14.3 * video @ text.T
    labels = torch.arange(5)
    clip_loss = (F.cross_entropy(logits, labels) + F.cross_entropy(logits.T, labels)) / 2
    loss = multi_positive_infonce(video, text, torch.tensor([4, 0, 9, 2, 1]), logit_scale=14.3)
    torch.testing.assert_close(loss, clip_loss)


def test_paraphrases_of_one_caption_are_not_pushed_apart():
    """Two clips with the same caption id: swapping their texts leaves the loss unchanged."""
    ids = torch.tensor([0, 0, 1])
    video, text = unit(3, 8, 4), unit(3, 8, 5)
    swapped = text[[1, 0, 2]]
    torch.testing.assert_close(
        multi_positive_infonce(video, text, ids, 5.0),
        multi_positive_infonce(video, swapped, ids, 5.0),
    )


def test_gradient_flows_to_both_towers_and_the_scale():
    video, text = unit(4, 8, 6).requires_grad_(), unit(4, 8, 7).requires_grad_()
    scale = torch.tensor(5.0, requires_grad=True)
    multi_positive_infonce(video, text, torch.tensor([0, 1, 1, 2]), scale).backward()
    assert video.grad.abs().sum() > 0 and text.grad.abs().sum() > 0 and scale.grad != 0


def test_positive_mask_and_bad_shapes():
    torch.testing.assert_close(
        positive_mask(torch.tensor([1, 2, 1])),
        torch.tensor([[True, False, True], [False, True, False], [True, False, True]]),
    )
    with pytest.raises(ValueError, match="caption_ids must be"):
        multi_positive_infonce(unit(3, 4, 0), unit(3, 4, 1), torch.tensor([0, 1]), 1.0)
    with pytest.raises(ValueError, match=r"\(batch, dim\)"):
        multi_positive_infonce(unit(3, 4, 0), unit(2, 4, 1), torch.tensor([0, 1, 2]), 1.0)
