"""The one action sampler: its generator draws are torch.multinomial's (RL's random stream, kept
in checkpoints, must not change), its uniform draws inverse-CDF."""

import numpy as np
import pytest
import torch

from zoo.models.sampling import sample_actions


def _logits(seed: int = 0) -> torch.Tensor:
    return torch.randn(256, 17, generator=torch.Generator().manual_seed(seed)) * 3


def test_generator_draws_are_the_multinomial_stream_of_softmax_or_exp():
    logits = _logits()
    logp = torch.log_softmax(logits, -1)
    ours, theirs = torch.Generator().manual_seed(5), torch.Generator().manual_seed(5)
    for _ in range(20):
        np.testing.assert_array_equal(
            sample_actions(logits, generator=ours),
            torch.multinomial(torch.softmax(logits, -1), 1, generator=theirs)[:, 0].numpy(),
        )
        np.testing.assert_array_equal(
            sample_actions(logp, generator=ours, log_probs=True),
            torch.multinomial(logp.exp(), 1, generator=theirs)[:, 0].numpy(),
        )
    assert torch.equal(ours.get_state(), theirs.get_state())


def test_uniforms_pick_by_inverse_cdf_at_the_temperature():
    logits = torch.tensor([[0.0, 0.0, 0.0, 0.0]]).repeat(4, 1)
    u = np.array([0.0, 0.3, 0.6, 0.999])
    np.testing.assert_array_equal(sample_actions(logits, uniforms=u), [0, 1, 2, 3])
    peaked = torch.tensor([[0.0, 1.0, 0.0]]).repeat(3, 1)
    cold = sample_actions(peaked, temperature=0.01, uniforms=np.array([0.001, 0.5, 0.999]))
    np.testing.assert_array_equal(cold, [1, 1, 1])


def test_log_probs_and_logits_give_the_same_uniform_draws():
    logits, u = _logits(1), np.random.default_rng(0).random(256)
    for temperature in (0.5, 1.0, 2.0):
        np.testing.assert_array_equal(
            sample_actions(torch.log_softmax(logits, -1), temperature, uniforms=u, log_probs=True),
            sample_actions(logits, temperature, uniforms=u),
        )


def test_greedy_is_argmax_and_one_source_of_randomness_at_a_time():
    logits = _logits(2)
    np.testing.assert_array_equal(sample_actions(logits, greedy=True), logits.argmax(-1).numpy())
    with pytest.raises(ValueError, match="not both"):
        sample_actions(logits, uniforms=np.zeros(256), generator=torch.Generator())
