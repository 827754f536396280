"""C-CLIP training (paper section 4.2, Appendix "C-CLIP"): multi-positive InfoNCE on CrafterCaption.

Each training clip is paired with a caption variant drawn uniformly from its template caption and
that caption's paraphrases (zoo.captions paraphrases.yaml). AdamW uses MineCLIP's layer-wise lr
decay over both CLIP towers; layers initialised from pretrained CLIP weights also get
``pretrained_lr_mult`` while new layers (temporal transformer, adapter, logit scale) train at the
full lr. Validation and test report video -> text retrieval over groups of 64 held-out clips
(zoo.eval.retrieval, gathered across DDP ranks by lit_models.retrieval_metric).
"""

from __future__ import annotations

import tempfile
from collections import defaultdict
from pathlib import Path

import lightning as L
import torch
from lightning.pytorch.loggers import WandbLogger

from lit_models.retrieval_metric import GroupedRetrieval
from lit_models.schedules import WarmupCosine
from zoo.captions.vocabulary import load_vocabulary
from zoo.eval.plots import write_gif
from zoo.eval.retrieval import top_captions
from zoo.models.cclip import CCLIPConfig, CCLIPModel
from zoo.models.contrastive import multi_positive_infonce


class CCLIP(L.LightningModule):
    """C-CLIP on CrafterCaption batches {frames uint8 (B,6,144,144,3), caption_id (B,)}."""

    def __init__(
        self,
        model: str = "vit_b16",
        embed_dim: int | None = None,
        patch_size: int | None = None,
        vision_width: int | None = None,
        vision_layers: int | None = None,
        vision_head_width: int | None = None,
        text_width: int | None = None,
        text_heads: int | None = None,
        text_layers: int | None = None,
        context_length: int | None = None,
        temporal_layers: int | None = None,
        temporal_heads: int | None = None,
        adapter_layers: int | None = None,
        pretrained_path: str | None = None,
        lr: float = 1.5e-4,
        warmup_steps: int = 100,
        cosine_steps: int | None = None,
        min_lr_ratio: float = 0.0,
        weight_decay: float = 0.2,
        layer_decay: float = 0.65,
        pretrained_lr_mult: float = 0.5,
        betas: tuple[float, float] = (0.9, 0.98),
        num_paraphrases: int | None = None,
        retrieval_group_size: int = 64,
        example_clips: int = 8,
    ) -> None:
        """Args:
            model: C-CLIP preset (vit_b16: the paper's ViT-B/16 towers; smoke: tiny CPU towers);
                the size arguments below override it.
            embed_dim: shared embedding width (None: the preset's).
            patch_size: ViT patch size (None: the preset's, 16).
            vision_width: image tower width (None: the preset's).
            vision_layers: image tower blocks (None: the preset's).
            vision_head_width: width per attention head of the image tower (None: the preset's).
            text_width: text tower width (None: the preset's).
            text_heads: text tower attention heads (None: the preset's).
            text_layers: text tower blocks (None: the preset's).
            context_length: caption tokens (None: the preset's; 77 to load CLIP weights as is).
            temporal_layers: temporal transformer layers (None: the preset's).
            temporal_heads: temporal transformer heads (None: the preset's).
            adapter_layers: residual video adapter layers (None: the preset's).
            pretrained_path: local open_clip/OpenAI CLIP checkpoint (224 px is fine: the position
                grid is resized); loaded when a fit/validate/test starts, never downloaded. None:
                random init.
            lr: peak AdamW learning rate of new layers and of the top tower layers (paper 1.5e-4).
            warmup_steps: optimizer steps of linear warmup (paper: 100).
            cosine_steps: steps of the cosine decay (None: trainer.max_steps).
            min_lr_ratio: final lr as a fraction of the peak.
            weight_decay: AdamW decay of weight matrices; none on norms, biases, logit scale.
            layer_decay: tower layer l of L gets lr * layer_decay ** (L - l) (paper: 0.65).
            pretrained_lr_mult: extra lr factor of tower layers loaded from ``pretrained_path``
                (paper: 0.5); unused without pretrained weights.
            betas: AdamW betas (CLIP's 0.9, 0.98).
            num_paraphrases: paraphrases per caption to sample from, besides the caption itself
                (None: all in paraphrases.yaml; 0: template captions only).
            retrieval_group_size: candidate captions per retrieval query (paper: 64).
            example_clips: held-out clips shown in a W&B table with their top-3 captions at
                each validation/test end (0: none; needs a WandbLogger).
        """
        super().__init__()
        self.save_hyperparameters()
        self.config = CCLIPConfig.from_hparams(dict(self.hparams))
        self.model = CCLIPModel(self.config)
        self._weights_ready = pretrained_path is None
        self._register_caption_variants(num_paraphrases)
        self.val_retrieval = GroupedRetrieval(retrieval_group_size, prefix="val/")
        self.test_retrieval = GroupedRetrieval(retrieval_group_size, prefix="test/")

    def _register_caption_variants(self, num_paraphrases: int | None) -> None:
        """Tokenise every caption variant once; row offsets[i] is template caption i itself."""
        if num_paraphrases is not None and num_paraphrases < 0:
            raise ValueError(f"num_paraphrases must be >= 0 or None, got {num_paraphrases}")
        vocabulary = load_vocabulary()
        texts, offsets, counts = [], [], []
        for caption in vocabulary.captions:
            variants = vocabulary.variants(caption.text)
            if num_paraphrases is not None:
                variants = variants[: 1 + num_paraphrases]
            offsets.append(len(texts))
            counts.append(len(variants))
            texts.extend(variants)
        self.register_buffer("variant_tokens", self.model.tokenize(texts), persistent=False)
        self.register_buffer("variant_offsets", torch.tensor(offsets), persistent=False)
        self.register_buffer("variant_counts", torch.tensor(counts), persistent=False)

    def caption_tokens(self, caption_ids: torch.Tensor, paraphrase: bool) -> torch.Tensor:
        """Token ids of each sample's caption: a uniform random variant, or the template."""
        if caption_ids.min() < 0 or caption_ids.max() >= len(self.variant_offsets):
            raise ValueError(
                f"caption ids must be in 0..{len(self.variant_offsets) - 1} (zoo.captions "
                f"captions.yaml), got {caption_ids.min().item()}..{caption_ids.max().item()}"
            )
        rows = self.variant_offsets[caption_ids]
        if paraphrase:
            counts = self.variant_counts[caption_ids]
            draw = torch.rand(caption_ids.shape, device=caption_ids.device)
            rows = rows + (draw * counts).long().clamp(max=counts - 1)
        return self.variant_tokens[rows]

    def setup(self, stage: str) -> None:
        # Loaded here, not in __init__, so load_from_checkpoint needs no CLIP file; a --ckpt_path
        # resume restores its own weights after setup.
        if not self._weights_ready:
            self.model.load_pretrained(self.hparams.pretrained_path)
            self._weights_ready = True

    def on_load_checkpoint(self, checkpoint: dict) -> None:
        self._weights_ready = True

    def forward(
        self, frames: torch.Tensor, tokens: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Unit-norm video and text embeddings."""
        return self.model.encode_video(frames), self.model.encode_text(tokens)

    def training_step(self, batch: dict, batch_idx: int) -> torch.Tensor:
        caption_ids = batch["caption_id"]
        video, text = self(batch["frames"], self.caption_tokens(caption_ids, paraphrase=True))
        loss = multi_positive_infonce(video, text, caption_ids, self.model.logit_scale)
        batch_size = len(caption_ids)
        self.log("train/loss", loss, prog_bar=True, batch_size=batch_size)
        self.log("train/logit_scale", self.model.logit_scale, batch_size=batch_size)
        # The peak lr: new layers and the top tower layers (lower tower layers get less).
        self.log("train/lr", max(self.lr_schedulers().get_last_lr()), batch_size=batch_size)
        return loss

    def _eval_step(self, batch: dict, stage: str, retrieval: GroupedRetrieval) -> None:
        caption_ids = batch["caption_id"]
        video, text = self(batch["frames"], self.caption_tokens(caption_ids, paraphrase=False))
        loss = multi_positive_infonce(video, text, caption_ids, self.model.logit_scale)
        self.log(f"{stage}/loss", loss, batch_size=len(caption_ids), sync_dist=True)
        if retrieval.update_count == 0:  # the epoch's first batch: keep a few clips to show
            self._examples = (batch["frames"][: self.hparams.example_clips].cpu(),
                              caption_ids[: self.hparams.example_clips].cpu(),
                              video[: self.hparams.example_clips].float().cpu())
        retrieval.update(video, text, caption_ids)

    def _log_examples(self, stage: str) -> None:
        """A W&B table: each kept clip (as a video), its caption and C-CLIP's top-3 captions."""
        loggers = [lg for lg in self.trainer.loggers if isinstance(lg, WandbLogger)]
        examples, self._examples = getattr(self, "_examples", None), None
        if not loggers or examples is None or not len(examples[0]) or not self.trainer.is_global_zero:
            return
        import wandb

        frames, caption_ids, video = examples
        texts = load_vocabulary().texts()
        with torch.no_grad():
            ids = torch.arange(len(texts), device=self.device)
            text = self.model.encode_text(self.caption_tokens(ids, paraphrase=False))
        tops = top_captions(video, text.cpu(), texts)
        with tempfile.TemporaryDirectory() as tmp:  # W&B copies the GIFs when they are logged
            rows = [
                [wandb.Video(str(write_gif(clip.numpy(), Path(tmp) / f"{i}.gif", fps=4)),
                             format="gif"), texts[int(cid)], *top]
                for i, (clip, cid, top) in enumerate(zip(frames, caption_ids, tops))
            ]
            table = wandb.Table(columns=["clip", "caption", "top-1", "top-2", "top-3"], data=rows)
            for logger in loggers:
                logger.experiment.log({f"{stage}/examples": table,
                                       "trainer/global_step": self.global_step})

    def _log_retrieval(self, stage: str, retrieval: GroupedRetrieval) -> None:
        """Log the epoch's retrieval metrics (every rank's clips) and start the next epoch afresh;
        compute() returns a dict, which Lightning cannot log or reset by itself."""
        self._log_examples(stage)
        self.log_dict(retrieval.compute())
        retrieval.reset()

    def validation_step(self, batch: dict, batch_idx: int) -> None:
        self._eval_step(batch, "val", self.val_retrieval)

    def on_validation_epoch_end(self) -> None:
        self._log_retrieval("val", self.val_retrieval)

    def test_step(self, batch: dict, batch_idx: int) -> None:
        self._eval_step(batch, "test", self.test_retrieval)

    def on_test_epoch_end(self) -> None:
        self._log_retrieval("test", self.test_retrieval)

    def predict_step(self, batch: dict, batch_idx: int) -> dict[str, torch.Tensor]:
        """Unit-norm video embeddings of the clips with their caption and source step, for
        retrieval or probing outside Lightning (``zoo predict`` writes these)."""
        return {
            "video_embedding": self.model.encode_video(batch["frames"]).float(),
            "caption_id": batch["caption_id"], "episode": batch["episode"], "step": batch["step"],
        }

    def parameter_groups(self) -> list[dict]:
        """AdamW groups: lr scale per tower layer (layer decay x pretrained multiplier), no decay
        on 1-D parameters (norms, biases, class/CLS tokens, logit scale, adapter gate)."""
        hp = self.hparams
        pretrained_mult = hp.pretrained_lr_mult if hp.pretrained_path is not None else 1.0
        groups: dict[tuple[float, float], list[torch.nn.Parameter]] = defaultdict(list)
        for name, param in self.model.named_parameters():
            if not param.requires_grad:
                continue
            layer = self.model.tower_layer(name)
            scale = 1.0
            if layer is not None:
                scale = pretrained_mult * hp.layer_decay ** (layer[1] - layer[0])
            decay = 0.0 if param.ndim < 2 else hp.weight_decay
            groups[(scale, decay)].append(param)
        return [
            {"params": params, "lr": hp.lr * scale, "lr_scale": scale, "weight_decay": decay}
            for (scale, decay), params in sorted(groups.items(), key=lambda item: item[0])
        ]

    def configure_optimizers(self):
        optimizer = torch.optim.AdamW(
            self.parameter_groups(), lr=self.hparams.lr, betas=tuple(self.hparams.betas)
        )
        total = self.hparams.cosine_steps or self.trainer.max_steps
        if total is None or total <= 0:
            raise ValueError(
                "CCLIP needs the cosine length: set model.init_args.cosine_steps or "
                "trainer.max_steps"
            )
        schedule = WarmupCosine(self.hparams.warmup_steps, total, self.hparams.min_lr_ratio)
        scheduler = torch.optim.lr_scheduler.LambdaLR(optimizer, schedule)
        return {
            "optimizer": optimizer,
            "lr_scheduler": {"scheduler": scheduler, "interval": "step"},
        }
