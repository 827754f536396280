"""(video, text) C-CLIP embedding pairs for the CVAE prior (paper section 5.2, D_prior).

The prior is trained on embeddings only, so C-CLIP runs once over CrafterCaption's held-out
clips and the pairs go to one .npz; training the prior then takes minutes, not a C-CLIP pass
per epoch. Each clip gives one pair: its video embedding z_v and the text embedding z_t of its
template caption or, with ``paraphrases``, of one variant (template or paraphrase) drawn
uniformly per clip from a seeded generator, so the prior learns every wording an instruction
may come in. Each distinct text is encoded once.

File layout (``zoo goals prior-pairs``): ``OUT.npz`` with ``video`` and ``text`` float32 (N, D),
``caption_id``, ``variant`` (0: the template, i: its i-th paraphrase, as
``Vocabulary.variants`` lists them), ``episode`` and ``step`` int64 (N,); ``OUT.json`` beside it
records the checkpoint (path, sha256, embedding width), the source folder and split, the options
and the counts. Both are written to temp names and renamed, so a killed run leaves no half file.
"""

from __future__ import annotations

import argparse
import io
import json
from collections import Counter
from pathlib import Path

import numpy as np
import torch
import webdataset as wds
from tqdm import tqdm

from zoo.captions.dataset import decode_caption_sample, list_caption_shards
from zoo.captions.vocabulary import Vocabulary, load_vocabulary
from zoo.data.storage import read_bytes
from zoo.files import atomic_path, atomic_write_text
from zoo.models.cclip import CCLIPModel
from zoo.weights import load_model
from zoo.weights.export import checkpoint_sha256

PAIR_FIELDS = {"video": 2, "text": 2, "caption_id": 1, "variant": 1, "episode": 1, "step": 1}
"""Arrays of a pairs file and their number of dimensions."""


def sidecar_path(out: str | Path) -> Path:
    """``pairs.npz`` -> ``pairs.json``."""
    return Path(out).with_suffix(".json")


def split_size(src: Path, split: str) -> int:
    """Clips in one split of a CrafterCaption folder, from its manifest."""
    manifest_path = src / "manifest.json"
    if not manifest_path.is_file():
        raise FileNotFoundError(
            f"{manifest_path} does not exist; --src must be a CrafterCaption folder "
            "(zoo data caption --out DIR)"
        )
    list_caption_shards(src, split)  # a clear error naming the splits when ``split`` is absent
    return int(json.loads(manifest_path.read_text())["splits"][split]["samples"])


@torch.no_grad()
def encode_variants(
    model: CCLIPModel, vocabulary: Vocabulary, caption_ids: np.ndarray, variants: np.ndarray
) -> np.ndarray:
    """Text embeddings (N, D) of caption ``caption_ids[i]``'s variant ``variants[i]``; each
    distinct text is encoded once."""
    keys = sorted(set(zip(caption_ids.tolist(), variants.tolist())))
    texts = [vocabulary.variants(vocabulary.captions[c].text)[v] for c, v in keys]
    embeddings = torch.cat(
        [model.encode_text(texts[i: i + 256]) for i in range(0, len(texts), 256)]
    ).float().cpu().numpy()
    row = {key: i for i, key in enumerate(keys)}
    return embeddings[[row[key] for key in zip(caption_ids.tolist(), variants.tolist())]]


def _check_caption(sample: dict, vocabulary: Vocabulary, shard: str) -> int:
    """The sample's caption id, refused when the vocabulary calls that id something else."""
    caption_id = int(sample["caption_id"])
    if not 0 <= caption_id < len(vocabulary) or (
        vocabulary.captions[caption_id].text != sample["caption"]
    ):
        raise ValueError(
            f"{shard}: sample (episode {sample['episode']}, step {sample['step']}) has caption id "
            f"{caption_id} = {sample['caption']!r}, which zoo/captions/captions.yaml does not "
            "list under that id; regenerate the CrafterCaption data"
        )
    return caption_id


def write_prior_pairs(
    checkpoint: str | Path,
    src: str | Path,
    out: str | Path,
    split: str = "test",
    max_pairs: int | None = None,
    paraphrases: bool = False,
    seed: int = 0,
    batch_size: int = 64,
    device: str = "cpu",
    progress: bool = True,
) -> dict:
    """Embed one CrafterCaption split's clips and captions with C-CLIP; returns the sidecar.

    ``max_pairs`` keeps a seeded uniform subset of the split's clips (without replacement), and
    only those are decoded; ``seed`` also draws the paraphrases.
    """
    checkpoint, src, out = Path(checkpoint), Path(src), Path(out)
    if max_pairs is not None and max_pairs < 1:
        raise ValueError(f"max_pairs must be >= 1, got {max_pairs}")
    if out.suffix != ".npz":
        raise ValueError(f"--out {out} must end in .npz")
    total = split_size(src, split)
    urls = list_caption_shards(src, split)
    rng = np.random.default_rng(seed)
    keep = np.ones(total, bool)
    if max_pairs is not None and max_pairs < total:
        keep[:] = False
        keep[rng.choice(total, max_pairs, replace=False)] = True
    model = load_model(checkpoint, "cclip", device)
    vocabulary = load_vocabulary()
    counts = np.array([len(vocabulary.variants(c.text)) for c in vocabulary.captions])

    columns: dict[str, list] = {name: [] for name in PAIR_FIELDS}
    clips: list[np.ndarray] = []

    @torch.no_grad()
    def flush() -> None:
        if clips:
            video = model.encode_video(torch.from_numpy(np.stack(clips)))
            columns["video"].append(video.float().cpu().numpy())
            clips.clear()

    stream = wds.DataPipeline(wds.SimpleShardList(urls), wds.tarfile_to_samples())
    bar = tqdm(total=int(keep.sum()), desc="C-CLIP pairs", unit="clip", disable=not progress)
    index = -1
    for index, raw in enumerate(stream):
        if index >= total:
            raise ValueError(f"{src}/manifest.json lists {total} {split!r} clips, the shards more")
        if not keep[index]:
            continue
        sample = decode_caption_sample(raw)
        caption_id = _check_caption(sample, vocabulary, raw.get("__url__", str(src)))
        variant = int(rng.integers(counts[caption_id])) if paraphrases else 0
        columns["caption_id"].append(caption_id)
        columns["variant"].append(variant)
        columns["episode"].append(int(sample["episode"]))
        columns["step"].append(int(sample["step"]))
        clips.append(sample["frames"])
        if len(clips) == batch_size:
            flush()
        bar.update()
    flush()
    bar.close()
    if index + 1 != total:
        raise ValueError(f"{src}/manifest.json lists {total} {split!r} clips, the shards {index + 1}")

    arrays = {name: np.asarray(columns[name], np.int64) for name in ("caption_id", "variant",
                                                                     "episode", "step")}
    arrays["video"] = np.concatenate(columns["video"]).astype(np.float32)
    arrays["text"] = encode_variants(model, vocabulary, arrays["caption_id"], arrays["variant"])
    info = {
        "checkpoint": str(checkpoint.resolve()),
        "checkpoint_sha256": checkpoint_sha256(checkpoint),
        "embed_dim": int(arrays["video"].shape[1]),
        "source": str(src.resolve()),
        "split": split,
        "split_clips": total,
        "max_pairs": max_pairs,
        "paraphrases": paraphrases,
        "seed": seed,
        "pairs": len(arrays["caption_id"]),
        "episodes": len(np.unique(arrays["episode"])),
        "captions": {
            vocabulary.captions[i].text: n
            for i, n in sorted(Counter(arrays["caption_id"].tolist()).items())
        },
    }
    out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(out) as tmp, open(tmp, "wb") as file:  # numpy adds .npz to a path
        np.savez(file, **arrays)
    atomic_write_text(sidecar_path(out), json.dumps(info, indent=1) + "\n")
    return info


def read_prior_pairs(path: str | Path, embed_dim: int | None = None) -> dict[str, np.ndarray]:
    """A pairs file's arrays, checked: every field present with one row per pair, and both
    embeddings ``embed_dim`` wide when given. ``path`` may be a URL (``zoo.data.storage``)."""
    try:
        raw = read_bytes(path)
    except FileNotFoundError:
        raise FileNotFoundError(
            f"{path} does not exist; write it with `zoo goals prior-pairs`"
        ) from None
    with np.load(io.BytesIO(raw), allow_pickle=False) as data:
        missing = sorted(set(PAIR_FIELDS) - set(data.files))
        if missing:
            raise ValueError(f"{path} lacks {missing}; expected a `zoo goals prior-pairs` file")
        arrays = {name: data[name] for name in PAIR_FIELDS}
    rows = len(arrays["caption_id"])
    for name, ndim in PAIR_FIELDS.items():
        if arrays[name].ndim != ndim or len(arrays[name]) != rows:
            raise ValueError(
                f"{path}: {name!r} has shape {arrays[name].shape}, expected {ndim} dimension(s) "
                f"and {rows} rows (one per pair)"
            )
    width = arrays["video"].shape[1]
    if arrays["text"].shape[1] != width or (embed_dim is not None and width != embed_dim):
        expected = embed_dim if embed_dim is not None else width
        raise ValueError(
            f"{path}: embeddings are video {arrays['video'].shape[1]}-d and text "
            f"{arrays['text'].shape[1]}-d, expected both {expected}-d (the prior's embed_dim "
            "must be the C-CLIP checkpoint's embedding width)"
        )
    return arrays


def run_prior_pairs(args: argparse.Namespace) -> int:
    """`zoo goals prior-pairs`: write the file and print its counts."""
    info = write_prior_pairs(
        args.checkpoint, args.src, args.out, split=args.split, max_pairs=args.max_pairs,
        paraphrases=args.paraphrases, seed=args.seed, batch_size=args.batch_size,
        device=args.device, progress=not args.no_progress,
    )
    print(
        f"{args.out}: {info['pairs']} pairs from {info['episodes']} episodes "
        f"({info['embed_dim']}-d, {len(info['captions'])} captions); {sidecar_path(args.out)}"
    )
    return 0
