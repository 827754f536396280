"""Training of C-Steve-1's CVAE prior (paper section 5.2) on C-CLIP embedding pairs.

The loss is zoo.models.prior's negative ELBO. Validation also asks what the prior is for: is a
goal decoded from a text embedding close to the clip the text describes? It logs the cosine
between the true z_v and
  cos_mean:          ``sample(z_t, mean=True)`` (c = 0, the goal C-Steve-1 is given),
  cos_sample:        ``sample(z_t)`` with c ~ N(0, I) (seeded: the same draws each validation),
  cos_caption_mean:  the mean training z_v of the pair's caption (a lookup table from template
                     captions to goals: the reference a text-only prior can hardly beat),
  cos_text:          z_t itself (no prior at all: how far apart C-CLIP's two towers are).
"""

from __future__ import annotations

import lightning as L
import torch
from torch.nn import functional as F

from lit_models.schedules import WarmupCosine
from zoo.models.prior import CVAEPrior, PriorConfig

VALIDATION_SEED = 0


class CVAEPriorModule(L.LightningModule):
    """The CVAE prior on batches {video, text (B, D), caption_id (B,)} of C-CLIP embeddings."""

    def __init__(
        self,
        embed_dim: int = 512,
        hidden: int = 512,
        latent_dim: int = 256,
        kl_weight: float = 1.0,
        layer_norm: bool = False,
        lr: float = 1e-3,
        weight_decay: float = 0.0,
        warmup_steps: int = 0,
        cosine_steps: int | None = None,
        min_lr_ratio: float = 0.0,
    ) -> None:
        """Args:
            embed_dim: C-CLIP embedding width (512 for vit_b16, 64 for smoke); must match the
                pairs file.
            hidden: width of the two hidden layers of the encoder and decoder MLPs.
            latent_dim: width of the latent c.
            kl_weight: weight of KL(q(c | z_v, z_t) || N(0, I)) (1: the paper's objective).
            layer_norm: a LayerNorm after each hidden layer, as Steve-1's prior (the paper
                config sets it; the shipped CPU prior was trained without).
            lr: peak AdamW learning rate.
            weight_decay: AdamW weight decay.
            warmup_steps: optimizer steps of linear warmup.
            cosine_steps: steps of the cosine decay (None: trainer.max_steps).
            min_lr_ratio: final lr as a fraction of the peak.
        """
        super().__init__()
        self.save_hyperparameters()
        self.config = PriorConfig.from_hparams(dict(self.hparams))
        self.model = CVAEPrior(self.config)

    def setup(self, stage: str) -> None:
        datamodule = self.trainer.datamodule if self.trainer is not None else None
        width = getattr(datamodule, "embed_dim", None)
        if width is not None and width != self.config.embed_dim:
            raise ValueError(
                f"model.init_args.embed_dim={self.config.embed_dim}, but the pairs in "
                f"{datamodule.hparams.root} are {width}-d: set it to the C-CLIP embedding width"
            )

    def forward(self, text: torch.Tensor, mean: bool = True) -> torch.Tensor:
        """Goal embeddings (B, D) for text embeddings (B, D)."""
        return self.model.sample(text, mean=mean)

    def _losses(self, batch: dict, stage: str) -> torch.Tensor:
        recon, mu, logvar = self.model(batch["video"], batch["text"])
        losses = self.model.loss(batch["video"], recon, mu, logvar)
        self.log_dict(
            {f"{stage}/{name}": value for name, value in losses.items()},
            prog_bar=stage == "train", batch_size=len(recon),
        )
        return losses["loss"]

    def training_step(self, batch: dict, batch_idx: int) -> torch.Tensor:
        loss = self._losses(batch, "train")
        self.log("train/lr", self.lr_schedulers().get_last_lr()[0], batch_size=len(batch["video"]))
        return loss

    def on_validation_epoch_start(self) -> None:
        self._val_generator = torch.Generator(self.device).manual_seed(VALIDATION_SEED)

    def validation_step(self, batch: dict, batch_idx: int) -> None:
        self._losses(batch, "val")
        video, text = batch["video"], batch["text"]
        size = len(video)
        cosines = {
            "cos_mean": F.cosine_similarity(self.model.sample(text, mean=True), video),
            "cos_sample": F.cosine_similarity(
                self.model.sample(text, generator=self._val_generator), video
            ),
            "cos_text": F.cosine_similarity(text, video),
        }
        for name, value in cosines.items():
            self.log(f"val/{name}", value.mean(), batch_size=size, prog_bar=name == "cos_mean")
        present = batch["has_caption_mean"]
        if present.any():
            reference = F.cosine_similarity(batch["caption_mean"][present], video[present])
            self.log("val/cos_caption_mean", reference.mean(), batch_size=int(present.sum()))

    def configure_optimizers(self):
        hp = self.hparams
        optimizer = torch.optim.AdamW(self.parameters(), lr=hp.lr, weight_decay=hp.weight_decay)
        total = hp.cosine_steps or self.trainer.max_steps
        if total is None or total <= 0:
            raise ValueError(
                "CVAEPriorModule needs the cosine length: set model.init_args.cosine_steps or "
                "trainer.max_steps"
            )
        scheduler = torch.optim.lr_scheduler.LambdaLR(
            optimizer, WarmupCosine(hp.warmup_steps, total, hp.min_lr_ratio)
        )
        return {"optimizer": optimizer, "lr_scheduler": {"scheduler": scheduler, "interval": "step"}}
