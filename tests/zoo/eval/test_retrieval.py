"""Retrieval metrics against values worked out by hand on tiny similarity matrices."""

import pytest
import torch
import torch.nn.functional as F

from zoo.eval.retrieval import best_correct_rank, grouped_retrieval_metrics, retrieval_metrics


def test_hand_computed_ranks_recalls_and_mean_rank():
    # 4 queries x 4 candidates, caption ids all distinct; correct candidate = the diagonal.
    similarity = torch.tensor(
        [
            [0.9, 0.1, 0.2, 0.3],  # correct scores highest: rank 1
            [0.5, 0.4, 0.6, 0.1],  # 0.5 and 0.6 beat 0.4: rank 3
            [0.2, 0.3, 0.25, 0.1],  # 0.3 beats 0.25: rank 2
            [0.8, 0.7, 0.6, 0.1],  # everything beats 0.1: rank 4
        ]
    )
    ids = torch.tensor([10, 11, 12, 13])
    assert best_correct_rank(similarity, ids, ids).tolist() == [1, 3, 2, 4]
    metrics = retrieval_metrics(similarity, ids, ids, top_ks=(1, 2, 3))
    assert metrics["R@1"] == pytest.approx(1 / 4)
    assert metrics["R@2"] == pytest.approx(2 / 4)
    assert metrics["R@3"] == pytest.approx(3 / 4)
    assert metrics["MeanR"] == pytest.approx((1 + 3 + 2 + 4) / 4)
    assert metrics["queries"] == 4


def test_any_candidate_with_the_same_caption_id_is_correct():
    # Candidates 0 and 2 share caption id 5 (e.g. two clips labelled "kill cow").
    similarity = torch.tensor(
        [
            [0.1, 0.9, 0.8],  # id 5: best correct 0.8, one wrong (0.9) above it -> rank 2
            [0.3, 0.2, 0.25],  # id 6: both id-5 candidates beat it -> rank 3
            [0.7, 0.1, 0.2],  # id 5: best correct 0.7 is top -> rank 1
        ]
    )
    ids = torch.tensor([5, 6, 5])
    assert best_correct_rank(similarity, ids, ids).tolist() == [2, 3, 1]
    metrics = retrieval_metrics(similarity, ids, ids, top_ks=(1, 2))
    assert metrics["R@1"] == pytest.approx(1 / 3)
    assert metrics["R@2"] == pytest.approx(2 / 3)
    assert metrics["MeanR"] == pytest.approx(2.0)


def test_groups_of_consecutive_clips_and_dropped_remainder():
    # 10 clips in groups of 4: two groups; the last 2 clips are dropped.
    ids = torch.tensor([0, 1, 2, 3, 0, 1, 2, 3, 9, 9])
    video = F.one_hot(ids % 4, 4).float()
    text = video.clone()
    text[5] = torch.tensor([0.0, 0.5, 0.0, 1.2])  # clip 5's caption (id 1) also looks like id 3
    metrics = grouped_retrieval_metrics(video, text, ids, group_size=4, top_ks=(1, 2))
    assert metrics["queries"] == 8
    # Every clip ranks its caption first except clip 7 (id 3): text 5 scores 1.2 > its own 1.0.
    assert metrics["MeanR"] == pytest.approx((7 * 1 + 2) / 8)
    assert metrics["R@1"] == pytest.approx(7 / 8)
    assert metrics["R@2"] == pytest.approx(1.0)


def test_groups_rank_only_within_their_own_group():
    ids = torch.tensor([0, 1, 0, 1])
    video = torch.tensor([[1.0, 0.0], [0.0, 1.0], [0.0, 1.0], [1.0, 0.0]])
    assert grouped_retrieval_metrics(video, video, ids, group_size=2)["MeanR"] == 1.0
    # Swap the texts of clips 2 and 3: in the second group both clips now rank their caption 2nd.
    swapped = video[[0, 1, 3, 2]]
    metrics = grouped_retrieval_metrics(video, swapped, ids, group_size=2, top_ks=(1,))
    assert metrics["MeanR"] == pytest.approx(1.5) and metrics["R@1"] == pytest.approx(0.5)


def test_grouped_metrics_average_the_per_group_metrics():
    generator = torch.Generator().manual_seed(0)
    video = F.normalize(torch.randn(128, 16, generator=generator), dim=-1)
    text = F.normalize(torch.randn(128, 16, generator=generator), dim=-1)
    ids = torch.randint(0, 61, (128,), generator=generator)
    grouped = grouped_retrieval_metrics(video, text, ids)
    halves = [
        retrieval_metrics(video[rows] @ text[rows].T, ids[rows], ids[rows])
        for rows in (slice(0, 64), slice(64, 128))
    ]
    for key in ("R@1", "R@5", "R@10", "MeanR"):
        assert grouped[key] == pytest.approx((halves[0][key] + halves[1][key]) / 2)


def test_bad_inputs_are_named():
    ids = torch.arange(3)
    with pytest.raises(ValueError, match="at least 64 clips"):
        grouped_retrieval_metrics(torch.zeros(3, 2), torch.zeros(3, 2), ids)
    with pytest.raises(ValueError, match="one video and one text embedding"):
        grouped_retrieval_metrics(torch.zeros(3, 2), torch.zeros(2, 2), ids, group_size=2)
    with pytest.raises(ValueError, match="similarity must be"):
        retrieval_metrics(torch.zeros(2, 3), ids, ids)
    with pytest.raises(ValueError, match="own caption id"):
        best_correct_rank(torch.zeros(2, 2), torch.tensor([0, 1]), torch.tensor([0, 0]))


def test_ties_count_against_the_model():
    # A collapsed model: every clip and caption embeds to the same vector, so all scores tie.
    # 4 queries, 4 candidates with distinct ids: each query's correct candidate ties with 3 wrong
    # ones and ranks last (4), so R@1 = R@3 = 0 and R@4 = 1 (not MeanR = 1 with R@1 ~ 1/4).
    ids = torch.tensor([0, 1, 2, 3])
    similarity = torch.ones(4, 4)
    assert best_correct_rank(similarity, ids, ids).tolist() == [4, 4, 4, 4]
    metrics = retrieval_metrics(similarity, ids, ids, top_ks=(1, 3, 4))
    assert metrics == {"R@1": 0.0, "R@3": 0.0, "R@4": 1.0, "MeanR": 4.0, "queries": 4.0}
    # A partial tie: query 0's correct score 0.5 ties with one wrong candidate -> rank 2.
    similarity = torch.tensor([[0.5, 0.5, 0.1], [0.2, 0.9, 0.2], [0.3, 0.3, 0.3]])
    ids = torch.tensor([0, 1, 2])
    assert best_correct_rank(similarity, ids, ids).tolist() == [2, 1, 3]


def test_collapsed_embeddings_in_groups_score_as_chance_or_worse():
    ids = torch.arange(64) % 61
    same = F.normalize(torch.ones(64, 8), dim=-1)
    metrics = grouped_retrieval_metrics(same, same, ids)
    # ids 0..2 appear twice: those 6 queries tie with 62 wrong candidates (rank 63); the other
    # 58 tie with 63 (rank 64).
    assert metrics["MeanR"] == pytest.approx((6 * 63 + 58 * 64) / 64)
    assert metrics["R@1"] == metrics["R@5"] == metrics["R@10"] == 0.0


def test_top_captions_are_the_nearest_texts_best_first():
    from zoo.eval.retrieval import top_captions

    text = torch.tensor([[1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])
    video = torch.tensor([[2.0, 0.1], [0.0, -1.0]])
    assert top_captions(video, text, ["a", "b", "ab"], k=2) == [["a", "ab"], ["a", "ab"]]
    assert top_captions(video[:1], text, ["a", "b", "ab"], k=5) == [["a", "ab", "b"]]
    with pytest.raises(ValueError, match="3 text embeddings for 2"):
        top_captions(video, text, ["a", "b"])
