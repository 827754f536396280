"""C-VPT behaviour cloning (paper section 4.1): cross-entropy on expert actions.

Truncated BPTT: a batch holds long sequences (paper: 640 steps) that the module cuts into
windows of ``tbptt_len`` (64). The TrXL memory flows from one window into the next with
stop-gradient, and the optimizer steps once per batch on the mean loss over all steps, so
the usual Lightning loop (gradient clipping, AMP, DDP, accumulation) applies unchanged. With
``activation_checkpointing`` each window is recomputed during backward, so activation memory
is one window's, not the whole sequence's, for ~1/3 more compute.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import lightning as L
import torch
from torch import nn
from torch.nn import functional as F
from torch.utils.checkpoint import checkpoint
from torchmetrics import MetricCollection
from torchmetrics.classification import MulticlassAccuracy

from lit_models.schedules import WarmupCosine
from zoo.export import load_checkpoint_model, load_exported
from zoo.models.cvpt import CVPTConfig, CVPTModel

IGNORE_ACTION = -1  # the episode's final observation has no action


def _accuracy_metrics(num_actions: int, prefix: str) -> MetricCollection:
    return MetricCollection(
        {
            "acc": MulticlassAccuracy(num_actions, average="micro", ignore_index=IGNORE_ACTION),
            "acc_macro": MulticlassAccuracy(num_actions, average="macro", ignore_index=IGNORE_ACTION),
        },
        prefix=prefix,
    )


def _network_weights(path: str, config: CVPTConfig) -> dict[str, torch.Tensor]:
    """State dict of the C-VPT network at ``path``, refused unless its config is ``config``."""
    if not Path(path).exists():
        raise FileNotFoundError(
            f"model.init_weights={path}: no such checkpoint or export folder (resuming or testing"
            " a run that started from it? Its weights are in --ckpt_path: add"
            " --model.init_args.init_weights=null)"
        )
    source = load_exported(path) if Path(path).is_dir() else load_checkpoint_model(path)
    if source.config != config:
        theirs, ours = dataclasses.asdict(source.config), dataclasses.asdict(config)
        diff = {k: (theirs[k], ours[k]) for k in ours if theirs.get(k) != ours[k]}
        raise ValueError(
            f"model.init_weights={path} holds a different C-VPT: (its value, this model's) {diff}"
        )
    return source.state_dict()


class CVPT(L.LightningModule):
    """Behaviour-cloning C-VPT on CrafterPlay batches {frames, actions, first}."""

    def __init__(
        self,
        model: str = "tiny",
        d_model: int | None = None,
        d_ff: int | None = None,
        n_heads: int | None = None,
        n_layers: int | None = None,
        impala_width: int | None = None,
        impala_channels: list[int] | None = None,
        encoder_hidden: int | None = None,
        memory_len: int | None = None,
        dropout: float | None = None,
        input_downsample: int | None = None,
        tbptt_len: int = 64,
        lr: float = 5e-4,
        weight_decay: float = 1e-4,
        betas: tuple[float, float] = (0.9, 0.999),
        warmup_steps: int = 0,
        cosine_steps: int | None = None,
        min_lr_ratio: float = 0.0,
        label_smoothing: float = 0.0,
        activation_checkpointing: bool = True,
        init_weights: str | None = None,
    ) -> None:
        """Args:
            model: C-VPT preset (tiny, base, large); the size arguments below override it.
            d_model: Transformer-XL width (None: the preset's).
            d_ff: feed-forward width (None: the preset's).
            n_heads: attention heads (None: the preset's).
            n_layers: Transformer-XL layers (None: the preset's).
            impala_width: IMPALA channel multiplier (None: the preset's).
            impala_channels: IMPALA base channels per stage (None: [16, 32, 32]).
            encoder_hidden: dense layer after the IMPALA stack (None: 256).
            memory_len: TrXL memory and attention span in steps (None: 64).
            dropout: transformer dropout (None: 0).
            input_downsample: average-pool frames by this factor first (None: 1, the paper's).
            tbptt_len: window of truncated backprop; the sequence is cut into these.
            lr: peak AdamW learning rate (paper: 5e-4 tiny/base, 1e-4 large).
            weight_decay: AdamW decay for weight matrices (norms, biases, embeddings: none).
            betas: AdamW betas.
            warmup_steps: optimizer steps of linear warmup (paper: 10M frames).
            cosine_steps: steps of the cosine decay (None: trainer.max_steps).
            min_lr_ratio: final LR as a fraction of ``lr``.
            label_smoothing: cross-entropy label smoothing.
            activation_checkpointing: recompute each TBPTT window in backward (memory of one
                window instead of the whole sequence).
            init_weights: a C-VPT ``.ckpt`` or ``zoo export`` folder whose network starts this
                run with a fresh optimizer and schedule (fine-tuning, or training on past a
                finished cosine); same architecture required. Loaded in ``setup``, so
                ``load_from_checkpoint`` never needs the file.
        """
        super().__init__()
        self.save_hyperparameters()
        overrides = {
            "d_model": d_model,
            "d_ff": d_ff,
            "n_heads": n_heads,
            "n_layers": n_layers,
            "impala_width": impala_width,
            "impala_channels": tuple(impala_channels) if impala_channels is not None else None,
            "encoder_hidden": encoder_hidden,
            "memory_len": memory_len,
            "dropout": dropout,
            "input_downsample": input_downsample,
        }
        self.config = CVPTConfig.from_name(
            model, **{k: v for k, v in overrides.items() if v is not None}
        )
        self.model = CVPTModel(self.config)
        num_actions = self.config.num_actions
        self.train_metrics = _accuracy_metrics(num_actions, "train/")
        self.val_metrics = _accuracy_metrics(num_actions, "val/")
        self.test_metrics = _accuracy_metrics(num_actions, "test/")
        self._weights_ready = init_weights is None

    def setup(self, stage: str) -> None:
        # A --ckpt_path resume restores its own weights after this (on_load_checkpoint).
        if not self._weights_ready:
            self.model.load_state_dict(_network_weights(self.hparams.init_weights, self.config))
            self._weights_ready = True

    def on_load_checkpoint(self, checkpoint: dict) -> None:
        self._weights_ready = True

    def forward(self, frames: torch.Tensor, first: torch.Tensor) -> torch.Tensor:
        """Logits (B, T, num_actions) for whole sequences, window by window from empty memory."""
        recompute = self.hparams.activation_checkpointing and self.training and torch.is_grad_enabled()
        state = self.model.initial_state(frames.shape[0], frames.device)
        window_logits = []
        for start in range(0, frames.shape[1], self.hparams.tbptt_len):
            window = slice(start, start + self.hparams.tbptt_len)
            if recompute:
                logits, state = checkpoint(
                    self.model, frames[:, window], first[:, window], state, use_reentrant=False
                )
            else:
                logits, state = self.model(frames[:, window], first[:, window], state)
            window_logits.append(logits)
        return torch.cat(window_logits, dim=1)

    def _loss(self, logits: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        """Mean cross-entropy over the steps that have an action (0 if none has)."""
        loss_sum = F.cross_entropy(
            logits.flatten(0, 1).float(),
            actions.flatten(),
            ignore_index=IGNORE_ACTION,
            reduction="sum",
            label_smoothing=self.hparams.label_smoothing,
        )
        return loss_sum / (actions != IGNORE_ACTION).sum().clamp(min=1)

    def training_step(self, batch: dict[str, torch.Tensor], batch_idx: int) -> torch.Tensor:
        actions = batch["actions"]
        logits = self(batch["frames"], batch["first"])
        loss = self._loss(logits, actions)
        batch_size = actions.shape[0]
        self.log("train/loss", loss, prog_bar=True, batch_size=batch_size)
        self.log("train/lr", self.lr_schedulers().get_last_lr()[0], batch_size=batch_size)
        metrics = self.train_metrics(logits.detach().flatten(0, 1), actions.flatten())
        self.log_dict(metrics, batch_size=batch_size)
        return loss

    def _eval_step(self, batch: dict[str, torch.Tensor], stage: str, metrics: MetricCollection) -> None:
        actions = batch["actions"]
        logits = self(batch["frames"], batch["first"])
        loss = self._loss(logits, actions)
        self.log(f"{stage}/loss", loss, prog_bar=True, batch_size=actions.shape[0], sync_dist=True)
        metrics.update(logits.flatten(0, 1), actions.flatten())
        self.log_dict(metrics, batch_size=actions.shape[0])

    def validation_step(self, batch: dict[str, torch.Tensor], batch_idx: int) -> None:
        self._eval_step(batch, "val", self.val_metrics)

    def test_step(self, batch: dict[str, torch.Tensor], batch_idx: int) -> None:
        self._eval_step(batch, "test", self.test_metrics)

    def predict_step(self, batch: dict[str, torch.Tensor], batch_idx: int) -> dict[str, torch.Tensor]:
        """Per step: the expert's action, the policy's distribution and its most likely action,
        with the episode and step they belong to (``zoo predict`` writes these)."""
        probs = torch.softmax(self(batch["frames"], batch["first"]).float(), dim=-1)
        return {
            "episode": batch["episode"], "step": batch["step"], "action": batch["actions"],
            "predicted": probs.argmax(-1), "probs": probs,
        }

    def configure_optimizers(self):
        decay, no_decay = [], []
        for module in self.model.modules():
            for param in module.parameters(recurse=False):
                exempt = param.ndim < 2 or isinstance(module, (nn.Embedding, nn.LayerNorm))
                (no_decay if exempt else decay).append(param)
        optimizer = torch.optim.AdamW(
            [
                {"params": decay, "weight_decay": self.hparams.weight_decay},
                {"params": no_decay, "weight_decay": 0.0},
            ],
            lr=self.hparams.lr,
            betas=tuple(self.hparams.betas),
        )
        total = self.hparams.cosine_steps or self.trainer.max_steps
        if total is None or total <= 0:
            raise ValueError(
                "CVPT needs the cosine length: set model.init_args.cosine_steps or trainer.max_steps"
            )
        schedule = WarmupCosine(self.hparams.warmup_steps, total, self.hparams.min_lr_ratio)
        scheduler = torch.optim.lr_scheduler.LambdaLR(optimizer, schedule)
        return {"optimizer": optimizer, "lr_scheduler": {"scheduler": scheduler, "interval": "step"}}
