"""Drawing actions from a policy head's scores: the one sampler of the agents and of RL."""

from __future__ import annotations

import numpy as np
import torch


def sample_actions(
    scores: torch.Tensor,
    temperature: float = 1.0,
    greedy: bool = False,
    uniforms: np.ndarray | None = None,
    generator: torch.Generator | None = None,
    log_probs: bool = False,
) -> np.ndarray:
    """One action per row of (N, A) ``scores``: argmax if ``greedy``, else a draw from
    softmax(scores / temperature).

    ``uniforms`` (N,) in [0, 1) drive inverse-CDF sampling, so an agent can give each env its
    own seeded stream; without them ``torch.multinomial`` draws from ``generator`` (one stream
    for the batch, as PPO keeps in its checkpoints). ``log_probs``: ``scores`` are already
    log-probabilities and are sampled as exp(scores / temperature), not renormalised by a
    softmax, so a draw comes from exactly the distribution whose log-probs the caller keeps.
    """
    if uniforms is not None and generator is not None:
        raise ValueError("give uniforms or a generator, not both")
    if greedy:
        return scores.argmax(-1).cpu().numpy()
    scaled = scores.float() / temperature
    weights = scaled.exp() if log_probs else torch.softmax(scaled, dim=-1)  # both draws normalise
    if uniforms is None:
        return torch.multinomial(weights.cpu(), 1, generator=generator)[:, 0].numpy()
    cdf = np.cumsum(weights.double().cpu().numpy(), axis=-1)
    actions = (np.asarray(uniforms)[:, None] * cdf[:, -1:] >= cdf).sum(-1)
    return np.minimum(actions, cdf.shape[-1] - 1)
