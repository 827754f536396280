"""C-CLIP: a MineCLIP-style video-text model for Crafter (paper section 4.2).

A CLIP image tower embeds each of a clip's 6 frames, a temporal transformer pools them, and a
residual adapter gives the video embedding; a CLIP text tower gives the caption embedding. Both
towers come from open_clip with the ViT-B/16 layout (random init by default; a local 224-px CLIP
checkpoint can be loaded, its position grid resized to 144 px).
"""

from dataclasses import asdict, dataclass, replace
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
import open_clip
import torch
import torch.nn.functional as F
from open_clip.constants import OPENAI_DATASET_MEAN, OPENAI_DATASET_STD
from open_clip.factory import load_state_dict as load_clip_state_dict
from open_clip.model import CLIPTextCfg, CLIPVisionCfg, resize_pos_embed, resize_text_pos_embed
from torch import nn

from zoo.models.video_encoder import ResidualAdapter, TemporalPooling, TemporalTransformer

FRAME_CHANNELS = 3


@dataclass(frozen=True)
class CCLIPConfig:
    """Sizes of C-CLIP; `CCLIPConfig.from_name("vit_b16")` is the paper's model."""

    embed_dim: int = 512
    """Width of the shared video-text embedding space."""
    num_frames: int = 6
    """Frames per clip: o_{t-4..t+1} in CrafterCaption."""
    image_size: int = 144
    """Frame height and width in pixels (Crafter renders 144x144)."""
    patch_size: int = 16
    """ViT patch size; 144 / 16 gives a 9x9 patch grid."""
    vision_width: int = 768
    """Width of the image tower's transformer."""
    vision_layers: int = 12
    """Residual blocks in the image tower."""
    vision_head_width: int = 64
    """Width of one attention head in the image tower (heads = width / head_width)."""
    text_width: int = 512
    """Width of the text tower's transformer."""
    text_heads: int = 8
    """Attention heads in the text tower."""
    text_layers: int = 12
    """Residual blocks in the text tower."""
    context_length: int = 77
    """Text tokens per caption, start and end tokens included (CLIP uses 77)."""
    temporal_layers: int = 2
    """Transformer layers across the frame embeddings of a clip."""
    temporal_heads: int = 8
    """Attention heads of the temporal transformer."""
    temporal_pooling: TemporalPooling = "cls"
    """How the temporal transformer pools frames: a learned CLS token or the mean."""
    adapter_layers: int = 2
    """Linear layers of the residual video adapter."""
    init_logit_scale: float = float(np.log(1 / 0.07))
    """Initial log inverse temperature of the contrastive logits (CLIP's 1/0.07)."""
    max_logit_scale: float = float(np.log(100.0))
    """The logit scale is clamped to this (CLIP's 100) to keep training stable."""

    @classmethod
    def from_name(cls, name: str, **overrides: Any) -> "CCLIPConfig":
        """A named preset, optionally with some fields replaced."""
        if name not in CCLIP_PRESETS:
            raise ValueError(f"unknown C-CLIP preset {name!r}; choose from {sorted(CCLIP_PRESETS)}")
        unknown = set(overrides) - set(asdict(CCLIP_PRESETS[name]))
        if unknown:
            raise ValueError(f"unknown C-CLIP config fields {sorted(unknown)}")
        return replace(CCLIP_PRESETS[name], **overrides)

    @classmethod
    def from_hparams(cls, hparams: dict[str, Any]) -> "CCLIPConfig":
        """The config a training run used: its preset ``model`` plus its non-None size fields."""
        fields = set(asdict(CCLIP_PRESETS[hparams.get("model", "vit_b16")]))
        overrides = {k: v for k, v in hparams.items() if k in fields and v is not None}
        return cls.from_name(hparams.get("model", "vit_b16"), **overrides)

    def vision_cfg(self) -> CLIPVisionCfg:
        return CLIPVisionCfg(
            layers=self.vision_layers,
            width=self.vision_width,
            head_width=self.vision_head_width,
            patch_size=self.patch_size,
            image_size=self.image_size,
        )

    def text_cfg(self) -> CLIPTextCfg:
        return CLIPTextCfg(
            context_length=self.context_length,
            width=self.text_width,
            heads=self.text_heads,
            layers=self.text_layers,
        )


CCLIP_PRESETS: dict[str, CCLIPConfig] = {
    # open_clip's ViT-B-16 towers at 144 px (9x9 patches) plus MineCLIP's temporal head.
    "vit_b16": CCLIPConfig(),
    # Small towers that train on a CPU in minutes (tests, smoke configs).
    "smoke": CCLIPConfig(
        embed_dim=64,
        vision_width=64,
        vision_layers=2,
        vision_head_width=32,
        text_width=64,
        text_heads=2,
        text_layers=2,
        context_length=32,
        temporal_layers=1,
        temporal_heads=2,
        adapter_layers=1,
    ),
}


@lru_cache(maxsize=1)
def _clip_tokenizer() -> open_clip.tokenizer.SimpleTokenizer:
    """CLIP's byte-pair tokenizer (vocabulary ships with open_clip; no download)."""
    return open_clip.tokenizer.SimpleTokenizer()


class CCLIPModel(nn.Module):
    """Video encoder E_V and text encoder E_T in one embedding space."""

    def __init__(self, config: CCLIPConfig) -> None:
        super().__init__()
        self.config = config
        self.clip = open_clip.CLIP(
            embed_dim=config.embed_dim,
            vision_cfg=config.vision_cfg(),
            text_cfg=config.text_cfg(),
            init_logit_scale=config.init_logit_scale,
        )
        self.temporal = TemporalTransformer(
            width=config.embed_dim,
            num_frames=config.num_frames,
            layers=config.temporal_layers,
            heads=config.temporal_heads,
            pooling=config.temporal_pooling,
        )
        self.video_adapter = ResidualAdapter(config.embed_dim, config.adapter_layers)
        mean = torch.tensor(OPENAI_DATASET_MEAN).view(1, 3, 1, 1) * 255.0
        std = torch.tensor(OPENAI_DATASET_STD).view(1, 3, 1, 1) * 255.0
        self.register_buffer("pixel_mean", mean, persistent=False)
        self.register_buffer("pixel_std", std, persistent=False)
        self.pretrained_path: str | None = None

    @property
    def logit_scale(self) -> torch.Tensor:
        """exp(learned log scale), clamped to exp(max_logit_scale)."""
        return self.clip.logit_scale.clamp(max=self.config.max_logit_scale).exp()

    def num_params(self) -> int:
        return sum(p.numel() for p in self.parameters())

    def tokenize(self, texts: list[str]) -> torch.Tensor:
        """Captions -> (B, context_length) int64 token ids (truncated to the context)."""
        if isinstance(texts, str) or not all(isinstance(text, str) for text in texts):
            raise ValueError("encode_text expects a list of caption strings")
        tokens = _clip_tokenizer()(list(texts), context_length=self.config.context_length)
        return tokens.to(self.pixel_mean.device)

    def check_clip(self, frames: torch.Tensor | np.ndarray) -> torch.Tensor:
        """Validate a batch of clips and return it as a uint8 tensor on the model's device."""
        cfg = self.config
        expected = (cfg.num_frames, cfg.image_size, cfg.image_size, FRAME_CHANNELS)
        shape = tuple(frames.shape)
        if len(shape) != 5 or shape[1:] != expected:
            raise ValueError(
                f"frames must have shape (batch, {', '.join(map(str, expected))}) "
                f"(clips of {cfg.num_frames} RGB {cfg.image_size}x{cfg.image_size} frames), "
                f"got {shape}"
            )
        frames = torch.as_tensor(frames)
        if frames.dtype != torch.uint8:
            raise ValueError(f"frames must be uint8 pixels in 0..255, got dtype {frames.dtype}")
        return frames.to(self.pixel_mean.device)

    def encode_frames(self, frames: torch.Tensor | np.ndarray) -> torch.Tensor:
        """(B, T, H, W, 3) uint8 -> (B, T, embed_dim) per-frame embeddings (not normalised)."""
        frames = self.check_clip(frames)
        batch, num_frames = frames.shape[:2]
        images = frames.flatten(0, 1).permute(0, 3, 1, 2).to(self.pixel_mean.dtype)
        images = (images - self.pixel_mean) / self.pixel_std
        return self.clip.encode_image(images).view(batch, num_frames, -1)

    def encode_video(self, frames: torch.Tensor | np.ndarray) -> torch.Tensor:
        """(B, 6, 144, 144, 3) uint8 clips -> (B, embed_dim) unit-norm video embeddings."""
        pooled = self.temporal(self.encode_frames(frames))
        return F.normalize(self.video_adapter(pooled), dim=-1)

    def encode_text(self, texts: list[str] | torch.Tensor) -> torch.Tensor:
        """Captions (strings, or token ids from `tokenize`) -> (B, embed_dim) unit-norm."""
        tokens = texts if isinstance(texts, torch.Tensor) else self.tokenize(texts)
        return self.clip.encode_text(tokens, normalize=True)

    def load_pretrained(self, path: str | Path) -> None:
        """Load open_clip/OpenAI CLIP weights from a local file into both towers.

        The checkpoint may be for 224-px images: its position embedding grid is interpolated to this
        model's grid (14x14 -> 9x9 for ViT-B/16 at 144 px). Nothing is ever downloaded.
        """
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"pretrained CLIP checkpoint {path} does not exist")
        state_dict = load_clip_state_dict(str(path))
        resize_pos_embed(state_dict, self.clip)
        resize_text_pos_embed(state_dict, self.clip)
        if "logit_scale" in state_dict:
            shape = self.clip.logit_scale.shape
            state_dict["logit_scale"] = state_dict["logit_scale"].reshape(shape)
        try:
            self.clip.load_state_dict(state_dict, strict=True)
        except RuntimeError as error:
            raise ValueError(
                f"{path} does not fit the C-CLIP towers {self.config}: {error}"
            ) from error
        self.pretrained_path = str(path)

    def tower_layer(self, name: str) -> tuple[int, int] | None:
        """(layer id, top layer id) of a CLIP-tower parameter for layer-wise lr decay; None if new.

        Layer 0 holds the embeddings (patch/token and position), layer i+1 the i-th residual
        block, and the top layer the final norm and projection; the temporal transformer, the
        adapter and the logit scale are not tower layers.
        """
        if not name.startswith("clip.") or name == "clip.logit_scale":
            return None
        name = name.removeprefix("clip.")
        if name.startswith("visual."):
            return _layer_id(name.removeprefix("visual."), self.config.vision_layers)
        return _layer_id(name, self.config.text_layers)


def _layer_id(name: str, num_blocks: int) -> tuple[int, int]:
    top = num_blocks + 1
    if name.startswith("transformer.resblocks."):
        return int(name.split(".")[2]) + 1, top
    embeddings = (
        "conv1.", "class_embedding", "positional_embedding", "ln_pre.", "token_embedding."
    )
    if name.startswith(embeddings):
        return 0, top
    return top, top


def build_cclip(
    preset: str = "vit_b16",
    pretrained_path: str | Path | None = None,
    **overrides: Any,
) -> CCLIPModel:
    """A C-CLIP from a preset name, with optional local CLIP weights."""
    model = CCLIPModel(CCLIPConfig.from_name(preset, **overrides))
    if pretrained_path is not None:
        model.load_pretrained(pretrained_path)
    return model
