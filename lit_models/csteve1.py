"""C-Steve-1 training (paper §4.3): goal-conditioned behaviour cloning on relabelled CrafterPlay.

Loss -log pi(a_t | o_1:t, z_1:t) over TBPTT windows, the loop C-VPT uses
(``lit_models.sequence_bc.SequenceBC``); the network is ``zoo.models.csteve1.CSteve1Model``: a C-VPT
loaded from ``backbone`` (a ``zoo fit`` checkpoint or ``zoo export`` folder), LoRA on its
Transformer-XL and a zero-initialised conditioning layer, the only parameters that train.

The network is built in ``configure_model``: from the backbone file on a first build, which
writes the backbone's architecture into the hyper-parameters (``backbone_config``), so
``CSteve1.load_from_checkpoint(path)`` rebuilds it without that file. Building a module from a
config reads no file (``zoo fit --print_config`` and config checks work anywhere).
"""

from __future__ import annotations

import torch

from lit_models.sequence_bc import IGNORE_ACTION, SequenceBC
from zoo.envs.constants import NUM_ACTIONS
from zoo.models.cvpt import CVPTConfig, CVPTModel
from zoo.models.csteve1 import Conditioning, CSteve1Config, CSteve1Model
from zoo.weights import load_model


class CSteve1(SequenceBC):
    """Goal-conditioned C-VPT with LoRA, trained on CSteve1DataModule batches."""

    condition_keys = ("goal",)

    def __init__(
        self,
        backbone: str | None = None,
        goal_dim: int = 512,
        conditioning: Conditioning = "head",
        head_hidden: int = 0,
        goal_hidden: int = 0,
        lora_rank: int = 16,
        lora_alpha: float = 16.0,
        lora_dropout: float = 0.0,
        lora_targets: list[str] | None = None,
        tbptt_len: int = 64,
        max_grad_norm: float | None = 5.0,
        lr: float = 1e-5,
        weight_decay: float = 1e-4,
        betas: tuple[float, float] = (0.9, 0.999),
        warmup_steps: int = 0,
        cosine_steps: int | None = None,
        min_lr_ratio: float = 0.0,
        label_smoothing: float = 0.0,
        init_weights: str | None = None,
        backbone_config: dict | None = None,
    ) -> None:
        """Args:
        backbone: the C-VPT to start from: a ``zoo fit`` .ckpt or a ``zoo export`` folder.
        goal_dim: goal embedding width; must equal the C-CLIP embedding size of the data.
        conditioning: ``head`` (the paper's), ``trxl_input`` (STEVE-1's; the ablation) or
            ``film`` (scale and shift after the Transformer-XL: state-dependent, goal-free TrXL).
        head_hidden: width of a trainable hidden layer before C-VPT's linear policy head (VPT's
            head has one; 0: none, and head conditioning is one logit offset per goal).
        goal_hidden: width of nonlinear goal features relu(V z) the conditioning reads beside z
            (0: the goal enters linearly; see ``zoo.models.csteve1``).
        lora_rank: LoRA rank on the Transformer-XL (0: train the conditioning layer only).
        lora_alpha: LoRA scale numerator.
        lora_dropout: dropout on the LoRA branch.
        lora_targets: TrXL linear layers given LoRA (None: query, key_value, out, ff.0, ff.3).
        tbptt_len: window of truncated backprop (paper: 64).
        max_grad_norm: clip the gradient norm to this before each step (paper: 5; None: none).
            Replaces ``trainer.gradient_clip_val``.
        lr: peak AdamW learning rate (paper: 1e-5).
        weight_decay: AdamW decay of weight matrices (paper: 1e-4).
        betas: AdamW betas.
        warmup_steps: optimizer steps of linear warmup (paper: 10M frames).
        cosine_steps: steps of the cosine decay (None: trainer.max_steps).
        min_lr_ratio: final LR as a fraction of ``lr``.
        label_smoothing: cross-entropy label smoothing.
        init_weights: a C-Steve-1 ``.ckpt`` or ``zoo export`` folder of the same architecture
            whose weights start this run with a fresh optimizer and schedule (a DAgger round
            fine-tunes the last round's); a ``--ckpt_path`` resume keeps its own weights.
        backbone_config: the backbone's C-VPT config; filled in from ``backbone`` on first
            build (leave it unset).
        """
        super().__init__()
        self.save_hyperparameters()
        if backbone is None and backbone_config is None:
            raise ValueError(
                "model.init_args.backbone is required: a C-VPT .ckpt from `zoo fit` or a "
                "`zoo export` folder to start C-Steve-1 from"
            )
        self.setup_metrics(NUM_ACTIONS)
        self._weights_ready = init_weights is None

    def on_fit_start(self) -> None:
        data_dim = getattr(self.trainer.datamodule, "goal_dim", None)
        if data_dim is not None and data_dim != self.hparams.goal_dim:
            raise ValueError(
                f"model.init_args.goal_dim={self.hparams.goal_dim} but the data's goal embeddings "
                f"(data.init_args.embeddings) have {data_dim} dimensions: set goal_dim={data_dim}"
            )
        # after configure_model and a --ckpt_path restore, before the sanity check (the network
        # is built in configure_model, after setup); load_from_checkpoint never reads the file
        self.load_starting_weights("csteve1", "C-Steve-1")

    def configure_model(self) -> None:
        """Build the network (Lightning calls this before training and before loading a
        checkpoint): from the backbone file on a first build, else from ``backbone_config``."""
        if hasattr(self, "model"):
            return
        if self.hparams.backbone_config is None:
            cvpt = load_model(self.hparams.backbone, "cvpt").train()
            self.hparams["backbone_config"] = cvpt.config.to_dict()
        else:
            cvpt = CVPTModel(CVPTConfig.from_dict(self.hparams.backbone_config))
        self.model = CSteve1Model(cvpt, CSteve1Config.from_hparams(dict(self.hparams)))

    def validation_step(self, batch: dict[str, torch.Tensor], batch_idx: int) -> None:
        """The usual val/loss, plus how much the goal helps: on the steps that have a goal,
        the loss with it (val/loss_goal) and with it zeroed (val/loss_nogoal, the unconditional
        policy CFG subtracts). An untrained C-Steve-1 has the two equal."""
        logits = self._eval_step(batch, "val", self.val_metrics)
        has_goal = batch["goal_mask"] & (batch["actions"] != IGNORE_ACTION)
        if not has_goal.any():
            return
        actions = batch["actions"].masked_fill(~has_goal, IGNORE_ACTION)
        frames, first, goal = batch["frames"], batch["first"], batch["goal"]
        losses = {
            "val/loss_goal": self._loss(logits, actions),
            "val/loss_nogoal": self._loss(self(frames, first, torch.zeros_like(goal)), actions),
        }
        self.log_dict(losses, batch_size=actions.shape[0], sync_dist=True)


__all__ = ["CSteve1"]
