"""Caption centroids and goal ranks against hand-computed values."""

import numpy as np
import pytest
import torch

from zoo.eval.goal_check import caption_centroids, nearest_captions, rank_of_caption


def _episodes():
    return [
        {"goal": np.array([[1, 0], [3, 0], [0, 2]], np.float16), "caption": np.array([0, 0, 1])},
        {"goal": np.array([[0, 5], [9, 9]], np.float16), "caption": np.array([1, -1])},
    ]


def test_centroids_are_unit_means_and_skip_uncaptioned_steps():
    centroids, counts = caption_centroids(_episodes(), num_captions=3)
    assert counts.tolist() == [2, 2, 0]
    torch.testing.assert_close(centroids[0], torch.tensor([1.0, 0.0]))  # mean (2, 0)
    torch.testing.assert_close(centroids[1], torch.tensor([0.0, 1.0]))  # mean (0, 3.5)
    assert torch.all(centroids[2] == 0)  # no steps: the -1 step is not caption 2's


def test_rank_and_nearest_ignore_absent_captions():
    centroids = torch.tensor([[1.0, 0.0], [0.0, 1.0], [0.6, 0.8]])
    present = torch.tensor([True, True, False])
    goal = torch.tensor([0.5, 0.9])  # nearest is caption 2, but it is absent
    assert rank_of_caption(centroids, goal, 1, present) == 0
    assert rank_of_caption(centroids, goal, 0, present) == 1
    assert nearest_captions(centroids, torch.stack([goal, -goal + 1.5]), present).tolist() == [1, 0]
    with pytest.raises(ValueError, match="caption 2 has no centroid"):
        rank_of_caption(centroids, goal, 2, present)


def test_out_of_range_caption_is_named():
    bad = [{"goal": np.ones((1, 2), np.float16), "caption": np.array([5])}]
    with pytest.raises(ValueError, match="caption id 5 out of range for 3"):
        caption_centroids(bad, num_captions=3)
