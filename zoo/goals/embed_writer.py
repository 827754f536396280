"""`zoo goals embed`: C-CLIP goal embeddings and step captions for a CrafterPlay folder.

Each clip o_{t-4..t+1} shares 5 of its 6 frames with its neighbour, so the image tower runs
once per frame (``encode_frames`` on the episode's frames grouped by 6) and only the small
temporal head and adapter run per clip, on the overlapping windows of per-frame features:
6x fewer image-tower passes than ``encode_video`` on explicit clips, with the same result
(the tower embeds each frame independently; tests/zoo/data/test_embed.py checks it).

Shard i of the output depends only on CrafterPlay shard i and the checkpoint, so a run is
resumable like `zoo data generate`: a shard is written to a temp name and renamed, finished
shards are verified by sha256 and skipped, and a rerun with another checkpoint or another
CrafterPlay manifest into the same folder is refused.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from zoo.captions.rules import CATEGORIES, EpisodeView
from zoo.captions.vocabulary import load_vocabulary
from zoo.data.manifest import MANIFEST, load_manifest
from zoo.data.reader import CorruptShardError, iter_episodes
from zoo.data.tar_writer import tar_member, write_tar
from zoo.envs.schema import FRAME_SHAPE
from zoo.files import atomic_write_text, sha256_file
from zoo.goals.embed import (
    CAPTION_PRIORITY,
    CLIP,
    FORMAT,
    FORMAT_VERSION,
    GOAL_DTYPE,
    SHARD_PATTERN,
    EmbeddingMismatchError,
    clip_indices,
    load_embedding_manifest,
    read_embedding_shard,
    sample_members,
    step_captions,
)
from zoo.models.cclip import CCLIPModel
from zoo.weights.export import checkpoint_sha256


class ClipEmbedder:
    """Video embeddings of every step's clip of an episode, each frame through the tower once.

    Args:
        model: a C-CLIP in eval mode, for 144-px frames and 6-frame clips.
        batch_size: frames per image-tower call (rounded down to whole groups of 6, at least
            one group) and clips per temporal-head call.
    """

    def __init__(self, model: CCLIPModel, batch_size: int = 240) -> None:
        cfg = model.config
        clip_length = CLIP["history"] + CLIP["future"] + 1
        if cfg.image_size != FRAME_SHAPE[0]:
            raise ValueError(
                f"the C-CLIP checkpoint takes {cfg.image_size}x{cfg.image_size} frames, "
                f"CrafterPlay frames are {FRAME_SHAPE[0]}x{FRAME_SHAPE[1]}; C-CLIP is trained "
                "on CrafterCaption's 144-px frames, so use a checkpoint with image_size 144"
            )
        if cfg.num_frames != clip_length:
            raise ValueError(
                f"the C-CLIP checkpoint takes {cfg.num_frames}-frame clips, goal embeddings use "
                f"{clip_length}-frame clips o_(t-{CLIP['history']}..t+{CLIP['future']})"
            )
        self.model = model
        self.group = cfg.num_frames
        self.batch_size = max(self.group, batch_size // self.group * self.group)

    @property
    def embed_dim(self) -> int:
        return self.model.config.embed_dim

    def _device_frames(self, frames: np.ndarray) -> torch.Tensor:
        return torch.from_numpy(np.ascontiguousarray(frames)).to(self.model.pixel_mean.device)

    @torch.inference_mode()
    def frame_features(self, frames: np.ndarray) -> torch.Tensor:
        """(T, 144, 144, 3) uint8 -> (T, D) per-frame image-tower features (the last group is
        padded with the last frame and the padding dropped)."""
        parts = []
        for start in range(0, len(frames), self.batch_size):
            chunk = frames[start : start + self.batch_size]
            pad = -len(chunk) % self.group
            if pad:
                chunk = np.concatenate([chunk, np.repeat(chunk[-1:], pad, axis=0)])
            grouped = self._device_frames(chunk).view(-1, self.group, *chunk.shape[1:])
            parts.append(self.model.encode_frames(grouped).flatten(0, 1)[: len(chunk) - pad])
        return torch.cat(parts)

    @torch.inference_mode()
    def __call__(self, frames: np.ndarray) -> np.ndarray:
        """(T, 144, 144, 3) uint8 -> (T, D) float32 unit-norm embeddings of the clamped clips."""
        features = self.frame_features(frames)
        index = torch.from_numpy(clip_indices(len(frames))).to(features.device)
        out = []
        for start in range(0, len(index), self.batch_size):
            clips = features[index[start : start + self.batch_size]]
            pooled = self.model.temporal(clips)
            out.append(F.normalize(self.model.video_adapter(pooled), dim=-1))
        return torch.cat(out).float().cpu().numpy()

    @torch.inference_mode()
    def naive(self, frames: np.ndarray) -> np.ndarray:
        """The reference: ``encode_video`` on each explicit clip (6 tower passes per step)."""
        index = clip_indices(len(frames))
        per_call = self.batch_size // self.group
        out = [
            self.model.encode_video(self._device_frames(frames[index[start : start + per_call]]))
            for start in range(0, len(index), per_call)
        ]
        return torch.cat(out).float().cpu().numpy()


def _write_shard(path: Path, samples: list[list[tuple[str, bytes]]]) -> str:
    """Fixed-header tar (bytes depend on content only) via a temp name; returns its sha256."""
    return write_tar(path, (tar_member(name, data) for members in samples for name, data in members))


def embed_shard(embedder: ClipEmbedder, src: Path, entry: dict, out: Path, advance=None) -> dict:
    """Embed CrafterPlay shard ``entry`` (its manifest entry) into ``out``; its new entry."""
    vocab = load_vocabulary()
    url = src / entry["file"]
    samples, steps = [], 0
    for episode in iter_episodes(str(url)):
        frames, meta = episode["frames"], episode["meta"]
        goal = embedder(frames).astype(GOAL_DTYPE)
        caption = step_captions(EpisodeView(episode["actions"], episode["state"]), vocab)
        samples.append(sample_members(int(meta["episode"]), int(meta["seed"]), goal, caption))
        steps += len(frames)
        if advance:
            advance(len(frames))
    if (len(samples), steps) != (entry["episodes"], entry["steps"]):
        raise CorruptShardError(
            f"{url}: {len(samples)} episodes / {steps} steps read, its manifest lists "
            f"{entry['episodes']} / {entry['steps']}"
        )
    path = out / SHARD_PATTERN.format(index=entry["index"])
    return {
        "index": entry["index"], "file": path.name, "source_file": entry["file"],
        "source_sha256": entry["sha256"], "episodes": len(samples), "steps": steps,
        "sha256": _write_shard(path, samples),
    }


def _caption_counts(path: Path) -> np.ndarray:
    """Steps per caption id (index 0) and uncaptioned steps (last index) of one written shard."""
    captions = [e["caption"] for e in read_embedding_shard(path).values()]
    ids = np.concatenate(captions).astype(np.int64)
    return np.bincount(np.where(ids < 0, len(load_vocabulary()), ids),
                       minlength=len(load_vocabulary()) + 1)


def _stats(shards: list[dict], counts: dict[int, np.ndarray], run: dict | None) -> dict:
    """Caption shares over the embedded steps, per category of the chosen caption."""
    vocab = load_vocabulary()
    total = sum((counts[e["index"]] for e in shards), np.zeros(len(vocab) + 1, np.int64))
    steps = int(total.sum())
    captioned = steps - int(total[-1])
    per_category = {c: 0 for c in CATEGORIES}
    for caption in vocab.captions:
        per_category[caption.category] += int(total[caption.id])
    return {
        "episodes": sum(e["episodes"] for e in shards),
        "steps": steps,
        "captioned_steps": captioned,
        "captioned_share": captioned / max(steps, 1),
        "categories": {
            c: {"steps": n, "share": n / max(steps, 1)} for c, n in per_category.items()
        },
        "captions": {c.text: int(total[c.id]) for c in vocab.captions if total[c.id]},
        **({"last_run": run} if run else {}),
    }


def _save(out: Path, manifest: dict) -> None:
    manifest["shards"] = sorted(manifest["shards"], key=lambda e: e["index"])
    atomic_write_text(out / MANIFEST, json.dumps(manifest, indent=1, sort_keys=True) + "\n")


def _check_same_run(out: Path, stored: dict, settings: dict) -> None:
    for field, what in (("source", "CrafterPlay manifest"), ("checkpoint", "checkpoint")):
        key = "manifest_sha256" if field == "source" else "sha256"
        if stored[field][key] != settings[field][key]:
            raise EmbeddingMismatchError(
                f"{out} already holds goal embeddings of another {what} ({field}.{key} "
                f"{stored[field][key][:12]}... there, {settings[field][key][:12]}... now: "
                f"{stored[field]['path' if field == 'checkpoint' else 'root']}); use another --out"
            )
    for field in ("embed_dim", "dtype", "clip", "caption_priority"):
        if stored.get(field) != settings[field]:
            raise EmbeddingMismatchError(
                f"{out / MANIFEST}: {field} is {stored.get(field)!r}, this zoo writes "
                f"{settings[field]!r}; use another --out"
            )


def embed_dataset(
    checkpoint: str | Path,
    src: str | Path,
    out: str | Path,
    batch_size: int = 240,
    device: str = "cpu",
    shards: tuple[int, int] | None = None,
    progress: bool = True,
) -> dict:
    """Write (or finish) the goal embeddings of CrafterPlay ``src`` in ``out``; the manifest.

    ``shards`` (start, stop) limits this run to CrafterPlay shard indices in [start, stop).
    """
    from tqdm import tqdm

    from zoo.weights import load_model

    src, out = Path(src), Path(out)
    play = load_manifest(src)
    if play is None:
        raise FileNotFoundError(f"{src / MANIFEST} not found: not a CrafterPlay folder")
    model = load_model(checkpoint, "cclip", device)
    embedder = ClipEmbedder(model, batch_size)
    settings = {
        "format": FORMAT, "version": FORMAT_VERSION, "embed_dim": embedder.embed_dim,
        "dtype": GOAL_DTYPE.name, "clip": dict(CLIP), "caption_priority": list(CAPTION_PRIORITY),
        "source": {"root": str(src), "manifest_sha256": sha256_file(src / MANIFEST)},
        "checkpoint": {"path": str(checkpoint), "sha256": checkpoint_sha256(checkpoint)},
    }
    out.mkdir(parents=True, exist_ok=True)
    manifest = {**settings, "shards": [], "stats": {}}
    if (out / MANIFEST).exists():
        manifest = load_embedding_manifest(out)
        _check_same_run(out, manifest, settings)
    for tmp in out.glob("embed-*.tar.tmp-*"):
        tmp.unlink()
    source = {e["index"]: e for e in play["shards"]}
    manifest["shards"] = [
        e for e in manifest["shards"]
        if (out / e["file"]).exists() and sha256_file(out / e["file"]) == e["sha256"]
        and e["index"] in source and source[e["index"]]["sha256"] == e["source_sha256"]
    ]
    counts = {e["index"]: _caption_counts(out / e["file"]) for e in manifest["shards"]}
    done = set(counts)
    start, stop = shards or (0, max(source, default=-1) + 1)
    todo = [source[i] for i in sorted(source) if start <= i < stop and i not in done]
    run = manifest["stats"].get("last_run")
    manifest["stats"] = _stats(manifest["shards"], counts, run)
    _save(out, manifest)

    bar = tqdm(total=sum(e["steps"] for e in todo), unit="clip", unit_scale=True,
               desc=f"embed {out.name}", disable=not progress, dynamic_ncols=True)
    began, clips = time.perf_counter(), 0
    try:
        for entry in todo:
            new = embed_shard(embedder, src, entry, out, bar.update)
            clips += new["steps"]
            seconds = time.perf_counter() - began
            run = {"clips": clips, "seconds": round(seconds, 2),
                   "clips_per_s": round(clips / seconds, 1), "batch_size": embedder.batch_size,
                   "device": device, "threads": torch.get_num_threads()}
            counts[new["index"]] = _caption_counts(out / new["file"])
            manifest["shards"].append(new)
            manifest["stats"] = _stats(manifest["shards"], counts, run)
            _save(out, manifest)
    finally:
        bar.close()
    return manifest


__all__ = ["ClipEmbedder", "embed_dataset", "embed_shard"]
