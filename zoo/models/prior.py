"""The C-Steve-1 prior: a conditional VAE from a C-CLIP text embedding to a goal embedding.

C-Steve-1's policy is trained on C-CLIP *video* embeddings z_v of future clips, but is told
what to do in words; the prior translates a text embedding z_t into a z_v the policy
understands (paper section 5.2, "Prior Model Training"; Steve-1's "prior", Sohn et al.'s CVAE).
One caption fits many clips, so the map is one-to-many: the latent c carries what the text
leaves open (where, which tree), and sampling c ~ N(0, I) draws one plausible goal.

    encoder q(c | z_v, z_t):  MLP([z_v, z_t]) -> (mu, logvar), two hidden layers
    decoder p(z_v | c, z_t):  MLP([c, z_t]) -> z_v_hat,        two hidden layers
    loss = sum_d (z_v_hat - z_v)_d^2 + kl_weight * KL(N(mu, exp(logvar)) || N(0, I))

The reconstruction term is -log p(z_v | c, z_t) of a Gaussian with variance 1/2 per dimension
(constants dropped), summed over dimensions like the KL, so ``kl_weight`` = 1 is the paper's
ELBO. Both terms are averaged over the batch. The decoder sees z_t directly, so even a collapsed
posterior (c ignored) leaves the prior at the conditional mean E[z_v | z_t]; ``sample(z_t,
mean=True)`` (c = 0) gives that mode, ``sample(z_t)`` a draw. Outputs are not normalised:
training targets are unit-norm, so they come out close to it.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

import torch
from torch import nn


@dataclass(frozen=True)
class PriorConfig:
    """Sizes of the CVAE prior; the defaults suit C-CLIP's 512-d embeddings (Steve-1's sizes)."""

    embed_dim: int = 512
    """Width of the C-CLIP embeddings (video and text share it)."""
    hidden: int = 512
    """Width of the two hidden layers of the encoder and of the decoder."""
    latent_dim: int = 256
    """Width of the latent c."""
    kl_weight: float = 1.0
    """Weight of the KL term (1: the paper's ELBO; < 1 lets c carry more of z_v)."""
    layer_norm: bool = False
    """A LayerNorm after each hidden layer, before its ReLU, as Steve-1's prior has (the paper
    config's choice; False: plain MLPs, as the shipped CPU prior was trained)."""

    def __post_init__(self) -> None:
        for name in ("embed_dim", "hidden", "latent_dim"):
            if getattr(self, name) < 1:
                raise ValueError(f"PriorConfig.{name} must be >= 1, got {getattr(self, name)}")
        if self.kl_weight < 0:
            raise ValueError(f"PriorConfig.kl_weight must be >= 0, got {self.kl_weight}")

    @classmethod
    def from_hparams(cls, hparams: dict[str, Any]) -> PriorConfig:
        """The config of a training run: its hyper-parameters that name config fields."""
        names = {f.name for f in fields(cls)}
        return cls(**{k: v for k, v in hparams.items() if k in names})


def mlp(width_in: int, hidden: int, width_out: int, layer_norm: bool = False) -> nn.Sequential:
    """Two hidden ReLU layers: the paper's "two-layer MLP" (``layer_norm``: Steve-1's, with a
    LayerNorm before each ReLU)."""
    layers: list[nn.Module] = []
    for width in (width_in, hidden):
        layers += [nn.Linear(width, hidden), *([nn.LayerNorm(hidden)] if layer_norm else []), nn.ReLU()]
    return nn.Sequential(*layers, nn.Linear(hidden, width_out))


def gaussian_kl(mu: torch.Tensor, logvar: torch.Tensor) -> torch.Tensor:
    """KL(N(mu, diag exp(logvar)) || N(0, I)) per row: (B, L) -> (B,)."""
    return 0.5 * (mu.pow(2) + logvar.exp() - 1.0 - logvar).sum(dim=-1)


class CVAEPrior(nn.Module):
    """z_t (B, D) -> goal z_v (B, D) through a latent c (B, latent_dim)."""

    def __init__(self, config: PriorConfig) -> None:
        super().__init__()
        self.config = config
        norm = config.layer_norm
        self.encoder = mlp(2 * config.embed_dim, config.hidden, 2 * config.latent_dim, norm)
        self.decoder = mlp(config.latent_dim + config.embed_dim, config.hidden, config.embed_dim, norm)

    def num_params(self) -> int:
        return sum(p.numel() for p in self.parameters())

    def _check(self, name: str, x: torch.Tensor) -> None:
        dim = self.config.embed_dim
        if x.ndim != 2 or x.shape[1] != dim:
            raise ValueError(
                f"{name} must have shape (batch, {dim}) (PriorConfig.embed_dim={dim}, the C-CLIP "
                f"embedding width), got {tuple(x.shape)}"
            )

    def encode(self, z_v: torch.Tensor, z_t: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """q(c | z_v, z_t): (mu, logvar), each (B, latent_dim)."""
        self._check("z_v", z_v)
        self._check("z_t", z_t)
        mu, logvar = self.encoder(torch.cat([z_v, z_t], dim=-1)).chunk(2, dim=-1)
        return mu, logvar

    def decode(self, c: torch.Tensor, z_t: torch.Tensor) -> torch.Tensor:
        """Mean of p(z_v | c, z_t): (B, embed_dim)."""
        self._check("z_t", z_t)
        return self.decoder(torch.cat([c, z_t], dim=-1))

    def forward(
        self, z_v: torch.Tensor, z_t: torch.Tensor, generator: torch.Generator | None = None
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Reparameterised pass: (reconstruction (B, D), mu (B, L), logvar (B, L))."""
        mu, logvar = self.encode(z_v, z_t)
        noise = torch.randn(mu.shape, generator=generator, device=mu.device, dtype=mu.dtype)
        recon = self.decode(mu + noise * (0.5 * logvar).exp(), z_t)
        return recon, mu, logvar

    def loss(
        self, z_v: torch.Tensor, recon: torch.Tensor, mu: torch.Tensor, logvar: torch.Tensor
    ) -> dict[str, torch.Tensor]:
        """Batch means of the reconstruction and KL terms and their weighted sum ("loss")."""
        reconstruction = (recon - z_v).pow(2).sum(dim=-1).mean()
        kl = gaussian_kl(mu, logvar).mean()
        total = reconstruction + self.config.kl_weight * kl
        return {"loss": total, "recon": reconstruction, "kl": kl}

    @torch.no_grad()
    def sample(
        self, z_t: torch.Tensor, generator: torch.Generator | None = None, mean: bool = False
    ) -> torch.Tensor:
        """Goal embeddings for text embeddings: c ~ N(0, I) (or c = 0 with ``mean``), decoded."""
        self._check("z_t", z_t)
        shape = (z_t.shape[0], self.config.latent_dim)
        if mean:
            c = torch.zeros(shape, device=z_t.device, dtype=z_t.dtype)
        else:
            c = torch.randn(shape, generator=generator, device=z_t.device, dtype=z_t.dtype)
        return self.decode(c, z_t)


__all__ = ["CVAEPrior", "PriorConfig", "gaussian_kl"]
