"""PPO written once for every RL agent of the zoo: GAE, the clipped objective, entropy, KL.

Shapes follow the rollout: (N envs, T steps). ``dones[:, t]`` is True when the action at t
ended the episode (death, the step limit, or the task's last sub-task), so no value is
bootstrapped across it. A time-limit end is treated as terminal too: the agents see no clock,
and the tasks' sparse rewards make the bias small (cleanrl's and Craftax's PPO do the same).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch.nn import functional as F


def gae(
    rewards: torch.Tensor,
    values: torch.Tensor,
    dones: torch.Tensor,
    last_value: torch.Tensor,
    gamma: float,
    lam: float,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Generalised advantage estimates and returns (both (N, T)).

    rewards, values, dones: (N, T); last_value: (N,) the value of the state after the last step.
    """
    n, t = rewards.shape
    advantages = torch.zeros_like(rewards)
    running = torch.zeros(n, dtype=rewards.dtype, device=rewards.device)
    next_value = last_value
    for k in reversed(range(t)):
        alive = 1.0 - dones[:, k].to(rewards.dtype)
        delta = rewards[:, k] + gamma * next_value * alive - values[:, k]
        running = delta + gamma * lam * alive * running
        advantages[:, k] = running
        next_value = values[:, k]
    return advantages, advantages + values


def categorical_kl(logits_p: torch.Tensor, logits_q: torch.Tensor) -> torch.Tensor:
    """KL(p || q) per row of two logit tensors (..., A)."""
    logp, logq = F.log_softmax(logits_p, -1), F.log_softmax(logits_q, -1)
    return (logp.exp() * (logp - logq)).sum(-1)


@dataclass
class PPOLoss:
    """The terms of one minibatch's loss (``total`` is what is minimised)."""

    total: torch.Tensor
    policy: torch.Tensor
    value: torch.Tensor
    entropy: torch.Tensor
    kl_ref: torch.Tensor
    approx_kl: torch.Tensor
    clip_fraction: torch.Tensor


def ppo_loss(
    logits: torch.Tensor,
    values: torch.Tensor,
    actions: torch.Tensor,
    old_logp: torch.Tensor,
    old_values: torch.Tensor,
    advantages: torch.Tensor,
    returns: torch.Tensor,
    clip_eps: float,
    vf_coef: float,
    ent_coef: float,
    ref_logits: torch.Tensor | None = None,
    kl_coef: float = 0.0,
    normalize_advantages: bool = True,
) -> PPOLoss:
    """Clipped policy loss + clipped value loss - entropy bonus + KL to a reference policy.

    logits: (..., A) of the policy being trained; every other tensor has the leading shape
    (...). ``ref_logits`` (..., A) are a frozen reference policy's (C-VPT-RL's pretrained
    C-VPT, as VPT's fine-tuning): the term is KL(pi_theta || pi_ref), weighted by ``kl_coef``.
    """
    logp_all = F.log_softmax(logits.float(), -1)
    logp = logp_all.gather(-1, actions.long().unsqueeze(-1)).squeeze(-1)
    if normalize_advantages and advantages.numel() > 1:
        advantages = (advantages - advantages.mean()) / (advantages.std() + 1e-8)
    log_ratio = logp - old_logp
    ratio = log_ratio.exp()
    policy = torch.max(
        -advantages * ratio, -advantages * ratio.clamp(1 - clip_eps, 1 + clip_eps)
    ).mean()
    clipped = old_values + (values - old_values).clamp(-clip_eps, clip_eps)
    value = 0.5 * torch.max((values - returns) ** 2, (clipped - returns) ** 2).mean()
    entropy = -(logp_all.exp() * logp_all).sum(-1).mean()
    kl_ref = (
        categorical_kl(logits.float(), ref_logits.float()).mean()
        if ref_logits is not None
        else torch.zeros((), device=logits.device)
    )
    total = policy + vf_coef * value - ent_coef * entropy + kl_coef * kl_ref
    with torch.no_grad():
        approx_kl = ((ratio - 1) - log_ratio).mean()
        clip_fraction = ((ratio - 1).abs() > clip_eps).float().mean()
    return PPOLoss(total, policy, value, entropy, kl_ref, approx_kl, clip_fraction)


def explained_variance(values: torch.Tensor, returns: torch.Tensor) -> float:
    """1 - Var(returns - values) / Var(returns): how much of the return the critic predicts."""
    var = returns.var()
    return float("nan") if var == 0 else float(1 - (returns - values).var() / var)
