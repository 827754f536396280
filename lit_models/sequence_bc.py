"""Behaviour cloning of a Transformer-XL policy on long sequences: what C-VPT and C-Steve-1 share.

Truncated BPTT: a batch holds long sequences (paper: 640 steps) that the module cuts into
windows of ``tbptt_len`` (64). The TrXL memory flows from one window into the next with
stop-gradient. The optimizer steps once per window (the paper's; STEVE-1's training loop,
which the paper says C-Steve-1 follows): forward, backward and one step per window, so one
step sees batch x tbptt_len frames (128 x 64 = 8,192 at the paper's sizes) and a 640-step
batch makes 10 steps. The memory carried into the next window was made by the weights before
the step, and activation memory is one window's whatever the sequence length.

The module steps its optimizer itself (Lightning's manual optimization), so gradient clipping
is the module's ``max_grad_norm`` (the paper's "Max Grad Norm", applied in
``on_before_optimizer_step`` where the gradients are unscaled), not
``trainer.gradient_clip_val``, and the LR schedule advances once per optimizer step;
``trainer.global_step`` and ``trainer.max_steps`` count optimizer steps.

A subclass builds ``self.model`` (called as ``model(frames, first, *conditions, state)``), says
which batch entries are its conditions (``condition_keys``: none for C-VPT, the goal for
C-Steve-1) and calls ``save_hyperparameters`` with lr, weight_decay, betas, warmup_steps,
cosine_steps, min_lr_ratio, label_smoothing, tbptt_len and max_grad_norm among them. Only parameters with ``requires_grad`` reach the
optimizer (C-Steve-1 trains LoRA and its conditioning layer alone).
"""

from __future__ import annotations

from collections.abc import Iterator
import lightning as L
import torch
from torch import nn
from torch.nn import functional as F
from torchmetrics import MetricCollection
from torchmetrics.classification import MulticlassAccuracy

from lit_models.init_weights import starting_weights
from lit_models.schedules import WarmupCosine

IGNORE_ACTION = -1  # the episode's final observation has no action


def accuracy_metrics(num_actions: int, prefix: str) -> MetricCollection:
    return MetricCollection(
        {
            "acc": MulticlassAccuracy(num_actions, average="micro", ignore_index=IGNORE_ACTION),
            "acc_macro": MulticlassAccuracy(
                num_actions, average="macro", ignore_index=IGNORE_ACTION
            ),
        },
        prefix=prefix,
    )


class SequenceBC(L.LightningModule):
    """Cross-entropy on expert actions over TBPTT windows (see the module docstring)."""

    model: nn.Module
    condition_keys: tuple[str, ...] = ()

    def __init__(self) -> None:
        super().__init__()
        self.automatic_optimization = False  # per-window steps: the module steps the optimizer

    _weights_ready = True  # False until a subclass given ``init_weights`` has loaded them

    def load_starting_weights(self, kind: str, title: str) -> None:
        """Load ``init_weights`` into the network once (``lit_models.init_weights``), unless a
        ``--ckpt_path`` restore already gave this run its own weights."""
        if not self._weights_ready:
            self.model.load_state_dict(
                starting_weights(self.hparams.init_weights, kind, self.model, title)
            )
            self._weights_ready = True

    def on_load_checkpoint(self, checkpoint: dict) -> None:
        self._weights_ready = True

    def setup_metrics(self, num_actions: int) -> None:
        self.train_metrics = accuracy_metrics(num_actions, "train/")
        self.val_metrics = accuracy_metrics(num_actions, "val/")
        self.test_metrics = accuracy_metrics(num_actions, "test/")

    def _windows(
        self, frames: torch.Tensor, first: torch.Tensor, conditions: tuple[torch.Tensor, ...]
    ) -> Iterator[tuple[slice, list[torch.Tensor]]]:
        """Each TBPTT window's slice of the time axis and the model inputs inside it."""
        for start in range(0, frames.shape[1], self.hparams.tbptt_len):
            window = slice(start, start + self.hparams.tbptt_len)
            yield window, [frames[:, window], first[:, window], *(c[:, window] for c in conditions)]

    def forward(
        self, frames: torch.Tensor, first: torch.Tensor, *conditions: torch.Tensor
    ) -> torch.Tensor:
        """Logits (B, T, num_actions) for whole sequences, window by window from empty memory."""
        state = self.model.initial_state(frames.shape[0], frames.device)
        window_logits = []
        for _, inputs in self._windows(frames, first, conditions):
            logits, state = self.model(*inputs, state)
            window_logits.append(logits)
        return torch.cat(window_logits, dim=1)

    def batch_logits(self, batch: dict[str, torch.Tensor]) -> torch.Tensor:
        return self(batch["frames"], batch["first"], *(batch[k] for k in self.condition_keys))

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

    def _optimizer_step(self, loss: torch.Tensor) -> None:
        """Backward ``loss`` from zeroed gradients, step the optimizer (which clips, in
        ``on_before_optimizer_step``) and the schedule."""
        optimizer = self.optimizers()
        optimizer.zero_grad(set_to_none=True)
        self.manual_backward(loss)
        optimizer.step()
        self.lr_schedulers().step()

    def on_before_optimizer_step(self, optimizer: torch.optim.Optimizer) -> None:
        """Clip to ``max_grad_norm`` here: under ``16-mixed`` Lightning unscales the gradients
        just before this hook, so a clip before ``optimizer.step()`` would see them scaled
        (by 65,536 at first) and shrink the true step by that factor."""
        if self.hparams.max_grad_norm is not None:
            self.clip_gradients(
                optimizer, gradient_clip_val=self.hparams.max_grad_norm,
                gradient_clip_algorithm="norm",
            )

    def _out_of_steps(self) -> bool:
        """True once ``trainer.max_steps`` optimizer steps are done (a batch may end early)."""
        max_steps = self.trainer.max_steps
        return max_steps is not None and 0 <= max_steps <= self.trainer.global_step

    def _train_per_window(
        self, batch: dict[str, torch.Tensor]
    ) -> tuple[torch.Tensor, torch.Tensor, int]:
        """One optimizer step per window: the windows' logits (detached), their mean loss and
        how many steps they cover (fewer than the batch's when ``max_steps`` ends it early)."""
        actions = batch["actions"]
        conditions = tuple(batch[k] for k in self.condition_keys)
        state = self.model.initial_state(actions.shape[0], actions.device)
        window_logits, loss_sum, counted = [], actions.new_zeros((), dtype=torch.float32), 0
        for window, inputs in self._windows(batch["frames"], batch["first"], conditions):
            if window_logits and self._out_of_steps():
                break
            logits, state = self.model(*inputs, state)
            loss = self._loss(logits, actions[:, window])
            self._optimizer_step(loss)
            count = int((actions[:, window] != IGNORE_ACTION).sum())
            loss_sum, counted = loss_sum + loss.detach() * count, counted + count
            window_logits.append(logits.detach())
        done = sum(w.shape[1] for w in window_logits)
        return torch.cat(window_logits, dim=1), loss_sum / max(counted, 1), done

    def training_step(self, batch: dict[str, torch.Tensor], batch_idx: int) -> torch.Tensor:
        logits, loss, done = self._train_per_window(batch)
        actions = batch["actions"][:, :done]
        batch_size = actions.shape[0]
        self._log_optimizer_step()
        self.log("train/loss", loss, prog_bar=True, batch_size=batch_size)
        self.log("train/lr", self.lr_schedulers().get_last_lr()[0], batch_size=batch_size)
        if actions.shape[1]:
            metrics = self.train_metrics(logits.flatten(0, 1), actions.flatten())
            self.log_dict(metrics, batch_size=batch_size)
        return loss

    def _log_optimizer_step(self) -> None:
        """Put this step's curves on the optimizer-step axis (``trainer.global_step``, which
        OnlineEvaluation's ``online/*`` use): a logged "step" is the x value Lightning hands
        the logger. Without it ``train/*`` and ``val/*`` sit at batches, 10x to the left of
        ``online/*`` at the paper's 10 windows per batch."""
        self.log("step", float(self.global_step), batch_size=1)

    def _eval_step(
        self, batch: dict[str, torch.Tensor], stage: str, metrics: MetricCollection
    ) -> torch.Tensor:
        """Log the loss and update the metrics of one evaluation batch; its logits."""
        self._log_optimizer_step()
        actions = batch["actions"]
        logits = self.batch_logits(batch)
        loss = self._loss(logits, actions)
        self.log(f"{stage}/loss", loss, prog_bar=True, batch_size=actions.shape[0], sync_dist=True)
        metrics.update(logits.flatten(0, 1), actions.flatten())
        self.log_dict(metrics, batch_size=actions.shape[0])
        return logits

    def validation_step(self, batch: dict[str, torch.Tensor], batch_idx: int) -> None:
        self._eval_step(batch, "val", self.val_metrics)

    def test_step(self, batch: dict[str, torch.Tensor], batch_idx: int) -> None:
        self._eval_step(batch, "test", self.test_metrics)

    def predict_step(
        self, batch: dict[str, torch.Tensor], batch_idx: int
    ) -> dict[str, torch.Tensor]:
        """Per step: the expert's action, the policy's distribution and its most likely action,
        with the episode and step they belong to (``zoo predict`` writes these)."""
        probs = torch.softmax(self.batch_logits(batch).float(), dim=-1)
        return {
            "episode": batch["episode"],
            "step": batch["step"],
            "action": batch["actions"],
            "predicted": probs.argmax(-1),
            "probs": probs,
        }

    def configure_optimizers(self):
        decay, no_decay = [], []
        for module in self.model.modules():
            for param in module.parameters(recurse=False):
                if not param.requires_grad:
                    continue
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
                f"{type(self).__name__} needs the cosine length: set model.init_args.cosine_steps"
                " or trainer.max_steps"
            )
        schedule = WarmupCosine(self.hparams.warmup_steps, total, self.hparams.min_lr_ratio)
        scheduler = torch.optim.lr_scheduler.LambdaLR(optimizer, schedule)
        return {
            "optimizer": optimizer,
            "lr_scheduler": {"scheduler": scheduler, "interval": "step"},
        }


__all__ = ["IGNORE_ACTION", "SequenceBC", "accuracy_metrics"]
