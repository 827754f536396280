"""CrafterCaption clips as torch batches (kept free of Lightning: spawned workers import it)."""

from __future__ import annotations

import numpy as np
import torch

TENSOR_KEYS = {
    "frames": torch.uint8, "caption_id": torch.int64, "episode": torch.int64, "step": torch.int64
}
TEXT_KEYS = ("caption", "rule", "category")


def collate_clips(samples: list[dict]) -> dict:
    """Decoded samples -> one batch (tensors for arrays and numbers, lists for strings)."""
    batch: dict = {
        key: torch.as_tensor(np.stack([np.asarray(s[key]) for s in samples]), dtype=dtype)
        for key, dtype in TENSOR_KEYS.items()
    }
    batch.update({key: [str(s[key]) for s in samples] for key in TEXT_KEYS})
    return batch
