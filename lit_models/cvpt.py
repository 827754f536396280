"""C-VPT behaviour cloning (paper section 4.1): cross-entropy on expert actions.

The training loop (truncated BPTT over long sequences, the loss, metrics, AdamW with no decay
on norms/biases and a warmup-cosine schedule) is ``lit_models.sequence_bc.SequenceBC``, shared
with C-Steve-1; this module builds the network from a preset and optional starting weights.
"""

from __future__ import annotations

from lit_models.sequence_bc import SequenceBC
from zoo.envs.constants import NUM_ACTIONS
from zoo.models.cvpt import CVPTConfig, CVPTModel


class CVPT(SequenceBC):
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
        encoder: str | None = None,
        tile_size: int | None = None,
        tile_channels: int | None = None,
        memory_len: int | None = None,
        dropout: float | None = None,
        input_downsample: int | None = None,
        head_hidden: int | None = None,
        tbptt_len: int = 64,
        max_grad_norm: float | None = 5.0,
        lr: float = 5e-4,
        weight_decay: float = 1e-4,
        betas: tuple[float, float] = (0.9, 0.999),
        warmup_steps: int = 0,
        cosine_steps: int | None = None,
        min_lr_ratio: float = 0.0,
        label_smoothing: float = 0.0,
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
            encoder_hidden: dense layer after the encoder's features (None: 256).
            encoder: ``impala`` (None: the paper's ResNet) or ``tiles`` (one token per tile of
                Crafter's grid, ~9x fewer FLOPs: a CPU option; zoo/models/tiles.py).
            tile_size: pixels of one tile in the stored frame (None: 16; ``encoder: tiles``).
            tile_channels: channels of a tile's embedding (None: 32; ``encoder: tiles``).
            memory_len: TrXL memory and attention span in steps (None: 64).
            dropout: transformer dropout (None: 0).
            input_downsample: average-pool frames by this factor first (None: 1, the paper's).
            head_hidden: width of the policy head's hidden layer (None: 0, one linear layer;
                VPT's head has one, and C-Steve-1's head conditioning needs it).
            tbptt_len: window of truncated backprop; the sequence is cut into these.
            max_grad_norm: clip the gradient norm to this before each step (paper: 5; None:
                no clipping). Replaces ``trainer.gradient_clip_val``.
            lr: peak AdamW learning rate (paper: 5e-4 tiny/base, 1e-4 large).
            weight_decay: AdamW decay for weight matrices (norms, biases, embeddings: none).
            betas: AdamW betas.
            warmup_steps: optimizer steps of linear warmup (paper: 10M frames).
            cosine_steps: steps of the cosine decay (None: trainer.max_steps).
            min_lr_ratio: final LR as a fraction of ``lr``.
            label_smoothing: cross-entropy label smoothing.
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
            "encoder": encoder,
            "tile_size": tile_size,
            "tile_channels": tile_channels,
            "memory_len": memory_len,
            "dropout": dropout,
            "input_downsample": input_downsample,
            "head_hidden": head_hidden,
        }
        self.config = CVPTConfig.from_name(
            model, NUM_ACTIONS, **{k: v for k, v in overrides.items() if v is not None}
        )
        self.model = CVPTModel(self.config)
        self.setup_metrics(self.config.num_actions)
        self._weights_ready = init_weights is None

    def setup(self, stage: str) -> None:
        # A --ckpt_path resume restores its own weights after this (on_load_checkpoint).
        self.load_starting_weights("cvpt", "C-VPT")


__all__ = ["CVPT"]
