"""Zero-shot captioning with C-CLIP: which of the 61 CrafterCaption captions fits a clip best.

Works from a Lightning checkpoint of lit_models.cclip.CCLIP without importing Lightning: the
checkpoint's hyper-parameters rebuild the model and its "model." weights are loaded.
CLI: `zoo captions query` (zoo/captions/cli.py) calls ``run_query``.
"""

from __future__ import annotations

import argparse
import io
from pathlib import Path

import numpy as np
import torch
import zstandard

from zoo.captions.vocabulary import load_vocabulary
from zoo.models.cclip import CCLIPModel
from zoo.weights.export import load_model


def load_clip(path: str | Path) -> np.ndarray:
    """One clip from a .npy or zstd-compressed .npy.zst file (CrafterCaption's frame format)."""
    path = Path(path)
    raw = path.read_bytes()
    if path.name.endswith(".zst"):
        raw = zstandard.ZstdDecompressor().decompress(raw)
    return np.load(io.BytesIO(raw), allow_pickle=False)


@torch.no_grad()
def top_captions(
    model: CCLIPModel, frames: np.ndarray | torch.Tensor, k: int = 5
) -> list[tuple[str, float]]:
    """The k captions most similar to one clip (6, 144, 144, 3) uint8, best first.

    Scores are probabilities over all 61 template captions: softmax of the model's logit scale
    times cosine similarity, as in training.
    """
    frames = torch.as_tensor(frames)
    if frames.ndim == 4:
        frames = frames.unsqueeze(0)
    if frames.shape[0] != 1:
        raise ValueError(f"top_captions takes one clip (6, 144, 144, 3), got {tuple(frames.shape)}")
    captions = load_vocabulary().texts()
    video = model.encode_video(frames)
    text = model.encode_text(captions)
    probabilities = (model.logit_scale * video @ text.T).softmax(dim=-1)[0]
    scores, indices = probabilities.topk(min(k, len(captions)))
    return [(captions[i], float(s)) for s, i in zip(scores.tolist(), indices.tolist())]


def run_query(args: argparse.Namespace) -> int:
    """Print the best captions for the clip, one `score<TAB>caption` line each."""
    model = load_model(args.checkpoint, "cclip", args.device)
    for caption, score in top_captions(model, load_clip(args.clip), args.k):
        print(f"{score:.3f}\t{caption}")
    return 0
