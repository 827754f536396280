"""PPO's pieces against hand-computed values on fixed rollouts."""

from __future__ import annotations

import math

import pytest
import torch

from zoo.rl.ppo import categorical_kl, explained_variance, gae, ppo_loss


def test_gae_matches_a_hand_computed_rollout_with_an_episode_end():
    rewards = torch.tensor([[1.0, 0.0, 2.0]])
    values = torch.tensor([[0.5, 1.0, 0.2]])
    dones = torch.tensor([[False, True, False]])  # the action at t=1 ended the episode
    last = torch.tensor([3.0])
    gamma, lam = 0.9, 0.5
    # t=2: delta = 2 + 0.9*3 - 0.2 = 4.5; A2 = 4.5
    # t=1: terminal: delta = 0 - 1.0 = -1.0; A1 = -1.0 (nothing flows back across the end)
    # t=0: delta = 1 + 0.9*1.0 - 0.5 = 1.4; A0 = 1.4 + 0.9*0.5*(-1.0) = 0.95
    adv, ret = gae(rewards, values, dones, last, gamma, lam)
    torch.testing.assert_close(adv, torch.tensor([[0.95, -1.0, 4.5]]))
    torch.testing.assert_close(ret, adv + values)


def test_gae_with_lambda_one_is_the_discounted_return_minus_the_value():
    rewards = torch.tensor([[1.0, 2.0, 3.0]])
    values = torch.zeros(1, 3)
    _, ret = gae(rewards, values, torch.zeros(1, 3, dtype=torch.bool), torch.tensor([4.0]),
                 0.5, 1.0)
    # G0 = 1 + .5*2 + .25*3 + .125*4 = 3.25; G1 = 2 + .5*3 + .25*4 = 4.5; G2 = 3 + .5*4 = 5
    torch.testing.assert_close(ret, torch.tensor([[3.25, 4.5, 5.0]]))


def _fixed_batch():
    logits = torch.log(torch.tensor([[0.5, 0.5], [0.8, 0.2]]))
    actions = torch.tensor([0, 1])
    # old probabilities of the taken actions: 0.25 and 0.4 -> ratios 2.0 and 0.5
    old_logp = torch.log(torch.tensor([0.25, 0.4]))
    return logits, actions, old_logp


def test_clipped_policy_and_value_losses_match_hand_computed_values():
    logits, actions, old_logp = _fixed_batch()
    advantages = torch.tensor([1.0, -2.0])
    values, old_values = torch.tensor([1.0, 0.0]), torch.tensor([0.5, 0.1])
    returns = torch.tensor([2.0, -1.0])
    loss = ppo_loss(logits, values, actions, old_logp, old_values, advantages, returns,
                    clip_eps=0.2, vf_coef=0.5, ent_coef=0.01, normalize_advantages=False)
    # ratio 2.0, A=+1: max(-2.0, -1.2) = -1.2 ; ratio 0.5, A=-2: max(1.0, 1.6) = 1.6
    assert loss.policy.item() == pytest.approx((-1.2 + 1.6) / 2)
    # value: row 0 clipped to 0.7: max((1-2)^2, (0.7-2)^2) = 1.69; row 1 unclipped 0.0 vs
    # clipped -0.1: max(1, 0.81) = 1 -> 0.5 * mean = 0.6725
    assert loss.value.item() == pytest.approx(0.5 * (1.69 + 1.0) / 2)
    entropy = (math.log(2) + -(0.8 * math.log(0.8) + 0.2 * math.log(0.2))) / 2
    assert loss.entropy.item() == pytest.approx(entropy, rel=1e-5)
    assert loss.clip_fraction.item() == 1.0  # both ratios leave [0.8, 1.2]
    total = loss.policy + 0.5 * loss.value - 0.01 * loss.entropy
    assert loss.total.item() == pytest.approx(total.item())


def test_the_kl_term_is_zero_against_itself_and_positive_otherwise():
    logits = torch.randn(5, 17, generator=torch.Generator().manual_seed(0))
    assert categorical_kl(logits, logits).abs().max() < 1e-6
    other = logits.flip(-1)
    assert (categorical_kl(logits, other) > 0).all()
    args = (torch.zeros(5, dtype=torch.long), torch.zeros(5), torch.zeros(5), torch.zeros(5),
            torch.ones(5), torch.zeros(5))
    same = ppo_loss(logits, *args, 0.2, 0.5, 0.0, ref_logits=logits, kl_coef=0.1)
    assert same.kl_ref.item() == pytest.approx(0.0, abs=1e-6)
    moved = ppo_loss(logits, *args, 0.2, 0.5, 0.0, ref_logits=other, kl_coef=0.1)
    assert moved.total.item() == pytest.approx(same.total.item() + 0.1 * moved.kl_ref.item(),
                                               rel=1e-5)


def test_the_kl_term_is_kl_of_the_policy_from_the_reference_not_the_reverse():
    """docs/rl.md: KL(pi || pi_ref), the expectation under the policy being trained."""
    pi = torch.tensor([[0.5, 0.5], [0.2, 0.8]])
    ref = torch.tensor([[0.9, 0.1], [0.5, 0.5]])
    # KL(pi || ref) = sum pi log(pi / ref): 0.5 ln(5/9) + 0.5 ln 5 = 0.5108; 0.2 ln 0.4 +
    # 0.8 ln 1.6 = 0.1927. The reverse would be 0.3681 and 0.2231.
    forward = [0.5 * math.log(5 / 9) + 0.5 * math.log(5), 0.2 * math.log(0.4) + 0.8 * math.log(1.6)]
    torch.testing.assert_close(categorical_kl(pi.log(), ref.log()), torch.tensor(forward))
    args = (torch.zeros(2, dtype=torch.long), torch.zeros(2), torch.zeros(2), torch.zeros(2),
            torch.zeros(2), torch.zeros(2))
    loss = ppo_loss(pi.log(), *args, 0.2, 0.5, 0.0, ref_logits=ref.log(), kl_coef=0.1)
    assert loss.kl_ref.item() == pytest.approx(sum(forward) / 2, rel=1e-5)


def test_explained_variance():
    returns = torch.tensor([1.0, 2.0, 3.0])
    assert explained_variance(returns, returns) == pytest.approx(1.0)
    assert explained_variance(torch.zeros(3), returns) == pytest.approx(0.0)
    assert math.isnan(explained_variance(returns, torch.ones(3)))
