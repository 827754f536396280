"""`zoo goals embed` speed -> bench/results/embed.json.

Measures, in one run on the same episodes and checkpoint:
  * clips/s of the embedding with per-frame sharing (each frame through the image tower once,
    the temporal head on overlapping windows) vs naive ``encode_video`` on every explicit clip,
    their ratio, and the largest difference between the two (float32);
  * clips/s of the whole `zoo goals embed` pipeline (read + decode + captions + embed + write)
    over the first ``--pipeline-shards`` CrafterPlay shards.

  nice -n 10 .venv/bin/python bench/bench_embed.py \\
      --checkpoint runs/cclip_cpu/20261202-003219-20701/checkpoints/best-step2400.ckpt \\
      --src data/crafterplay_scripted_early
"""

from __future__ import annotations

import argparse
import itertools
import json
import platform
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

from zoo.data.reader import iter_episodes, list_shards
from zoo.goals.embed_writer import ClipEmbedder, embed_dataset
from zoo.weights import load_model

RESULTS = Path(__file__).parent / "results" / "embed.json"


def bench_embedders(embedder: ClipEmbedder, episodes: list[np.ndarray]) -> dict:
    clips = sum(len(frames) for frames in episodes)
    embedder(episodes[0][:12])  # warm-up
    out = {"episodes": len(episodes), "clips": clips}
    results = {}
    for name, fn in (("shared", embedder), ("naive", embedder.naive)):
        start = time.perf_counter()
        results[name] = [fn(frames) for frames in episodes]
        seconds = time.perf_counter() - start
        out[f"{name}_seconds"] = round(seconds, 2)
        out[f"{name}_clips_per_s"] = round(clips / seconds, 1)
    out["speedup"] = round(out["shared_clips_per_s"] / out["naive_clips_per_s"], 2)
    diff = max(float(np.abs(a - b).max()) for a, b in zip(results["shared"], results["naive"]))
    out["max_abs_diff"] = diff
    return out


def bench_pipeline(checkpoint: Path, src: Path, shards: int, batch_size: int) -> dict:
    with tempfile.TemporaryDirectory() as out:
        start = time.perf_counter()
        manifest = embed_dataset(checkpoint, src, out, batch_size, shards=(0, shards),
                                 progress=False)
        seconds = time.perf_counter() - start
    steps = manifest["stats"]["steps"]
    return {"shards": shards, "clips": steps, "seconds": round(seconds, 2),
            "clips_per_s": round(steps / seconds, 1),
            "captioned_share": round(manifest["stats"]["captioned_share"], 4)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--checkpoint", type=Path, required=True, help="C-CLIP .ckpt")
    parser.add_argument("--src", type=Path, required=True, help="CrafterPlay folder")
    parser.add_argument("--episodes", type=int, default=2, help="episodes for shared vs naive")
    parser.add_argument("--pipeline-shards", type=int, default=1, help="shards for the pipeline")
    parser.add_argument("--batch-size", type=int, default=240, help="frames per tower pass")
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args()

    model = load_model(args.checkpoint, "cclip")
    embedder = ClipEmbedder(model, args.batch_size)
    episodes = [e["frames"] for e in
                itertools.islice(iter_episodes(list_shards(args.src)), args.episodes)]
    result = {
        "machine": platform.platform(),
        "torch_threads": torch.get_num_threads(),
        "checkpoint": str(args.checkpoint),
        "embed_dim": embedder.embed_dim,
        "source": str(args.src),
        "batch_size": embedder.batch_size,
        "date": time.strftime("%Y-%m-%d %H:%M"),
        "embedding": bench_embedders(embedder, episodes),
        "pipeline": bench_pipeline(args.checkpoint, args.src, args.pipeline_shards,
                                   args.batch_size),
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=1) + "\n")
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
