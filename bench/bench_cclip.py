"""C-CLIP speed on this machine -> bench/results/cclip.json.

Measures (CPU unless a GPU is present):
  * smoke-tower training samples/s with clips already in memory (model only),
  * the same fed by CrafterCaptionDataModule from a CrafterCaption folder (``--data``), and the
    datamodule alone (decode + batch) to see which side limits,
  * ViT-B/16 (paper towers at 144 px) forward time for a batch of clips, and one training step.

  nice -n 10 .venv/bin/python bench/bench_cclip.py --data data/craftercaption_smoke
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import torch

from datamodules.craftercaption import CrafterCaptionDataModule
from zoo.models.cclip import build_cclip
from zoo.models.contrastive import multi_positive_infonce

RESULTS = Path(__file__).parent / "results" / "cclip.json"


def train_step(model, optimizer, frames: torch.Tensor, caption_ids: torch.Tensor, tokens) -> float:
    video, text = model.encode_video(frames), model.encode_text(tokens)
    loss = multi_positive_infonce(video, text, caption_ids, model.logit_scale)
    optimizer.zero_grad(set_to_none=True)
    loss.backward()
    optimizer.step()
    return loss.item()


def random_batch(batch: int, device: torch.device) -> tuple[torch.Tensor, torch.Tensor]:
    frames = torch.randint(0, 256, (batch, 6, 144, 144, 3), dtype=torch.uint8, device=device)
    return frames, torch.arange(batch, device=device) % 61


def bench_model_only(preset: str, batch: int, steps: int, device: torch.device) -> dict:
    model = build_cclip(preset).to(device).train()
    optimizer = torch.optim.AdamW(model.parameters(), lr=1e-4)
    frames, ids = random_batch(batch, device)
    tokens = model.tokenize([f"caption {i}" for i in ids.tolist()])
    train_step(model, optimizer, frames, ids, tokens)  # warm-up
    _sync(device)
    start = time.perf_counter()
    for _ in range(steps):
        train_step(model, optimizer, frames, ids, tokens)
    _sync(device)
    seconds = time.perf_counter() - start
    return {"batch": batch, "steps": steps, "samples_per_s": batch * steps / seconds,
            "s_per_step": seconds / steps, "params": model.num_params()}  # fmt: skip


def bench_with_datamodule(
    data: str, batch: int, steps: int, workers: int, device: torch.device
) -> dict:
    module = CrafterCaptionDataModule(
        data, batch_size=batch, num_workers=workers, shuffle_buffer=256,
        train_batches_per_epoch=steps + 1,
    )  # fmt: skip
    start = time.perf_counter()
    loaded = sum(len(b["caption_id"]) for b in module.train_dataloader())
    loader_rate = loaded / (time.perf_counter() - start)

    model = build_cclip("smoke").to(device).train()
    optimizer = torch.optim.AdamW(model.parameters(), lr=1e-4)
    batches = iter(module.train_dataloader())
    first = next(batches)  # worker start-up and warm-up are not timed
    train_step(model, optimizer, first["frames"].to(device), first["caption_id"].to(device),
               model.tokenize(first["caption"]))  # fmt: skip
    _sync(device)
    start, samples = time.perf_counter(), 0
    for batch_data in batches:
        ids = batch_data["caption_id"].to(device)
        frames, tokens = batch_data["frames"].to(device), model.tokenize(batch_data["caption"])
        train_step(model, optimizer, frames, ids, tokens)
        samples += len(ids)
    _sync(device)
    return {"batch": batch, "workers": workers, "steps": steps,
            "samples_per_s": samples / (time.perf_counter() - start),
            "datamodule_only_samples_per_s": loader_rate}  # fmt: skip


def bench_vit_b16(batch: int, device: torch.device) -> dict:
    model = build_cclip("vit_b16").to(device)
    frames, ids = random_batch(batch, device)
    with torch.no_grad():
        model.eval()
        model.encode_video(frames)  # warm-up
        _sync(device)
        start = time.perf_counter()
        model.encode_video(frames)
        _sync(device)
        forward = time.perf_counter() - start
    model.train()
    optimizer = torch.optim.AdamW(model.parameters(), lr=1e-5)
    tokens = model.tokenize([f"caption {i}" for i in ids.tolist()])
    start = time.perf_counter()
    train_step(model, optimizer, frames, ids, tokens)
    _sync(device)
    step = time.perf_counter() - start
    return {"batch_clips": batch, "images": batch * 6, "params": model.num_params(),
            "forward_video_s": forward, "train_step_s_first": step}  # fmt: skip


def _sync(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize()


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawTextHelpFormatter
    )
    parser.add_argument("--data", help="CrafterCaption folder for the datamodule runs")
    parser.add_argument("--batch", type=int, default=16, help="smoke training batch")
    parser.add_argument("--steps", type=int, default=10, help="timed smoke training steps")
    parser.add_argument("--workers", type=int, default=1, help="DataLoader workers")
    parser.add_argument("--vit-batch", type=int, default=4, help="ViT-B/16 clips; 0: skip")
    args = parser.parse_args()
    device = torch.device("cuda" if torch.cuda.is_available() else "cpu")
    torch.manual_seed(0)
    results: dict = {
        "device": torch.cuda.get_device_name() if device.type == "cuda" else platform.machine(),
        "torch_threads": torch.get_num_threads(),
        "smoke_model_only": bench_model_only("smoke", args.batch, args.steps, device),
    }
    if args.data:
        results["smoke_with_datamodule"] = bench_with_datamodule(
            args.data, args.batch, args.steps, args.workers, device
        )
    if args.vit_batch > 0:
        results["vit_b16"] = bench_vit_b16(args.vit_batch, device)
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps(results, indent=1) + "\n")
    print(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
