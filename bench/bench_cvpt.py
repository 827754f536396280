"""C-VPT speed and memory on this machine (CPU) -> bench/results/cvpt.json.

Measures:
  * CrafterPlayDataModule alone (decode + noop filter + pack + batch, one process) in
    frames/s, against one tiny-model training step (model only, frames in memory); the
    loader's share is its time to produce one step's frames over the step's time (goal <= 10%);
  * cached per-step inference (rolling TrXL memory) against recomputing the whole window of
    memory_len + 1 frames every step (goal >= 5x);
  * parameters and peak RSS of a no-grad forward of one sequence per preset (each preset in a
    fresh process, so peaks do not mix); large is forwarded, not trained.

  zoo data generate --expert random --env crafter --episodes 16 --max-steps 200 --seed 0 \
      --episodes-per-shard 4 --chunk-length 64 --out data/crafterplay_smoke
  nice -n 10 .venv/bin/python bench/bench_cvpt.py --data data/crafterplay_smoke
  (or --data data/crafterplay_scripted, the scripted-expert set of configs/cvpt_tiny_cpu.yaml)
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import torch

from datamodules.crafterplay import CrafterPlayDataModule
from lit_models.cvpt import CVPT
from zoo.agents.cvpt_agent import CVPTPolicy
from zoo.models.cvpt import CVPTConfig, CVPTModel

RESULTS = Path(__file__).parent / "results" / "cvpt.json"


def loader_frames_per_s(root: str, seq_len: int, batch_size: int, min_frames: int) -> dict:
    module = CrafterPlayDataModule(
        root, seq_len=seq_len, batch_size=batch_size, num_workers=0, val_fraction=0.0,
        test_fraction=0.0, train_batches_per_epoch=10**6,
    )
    frames, start = 0, time.perf_counter()
    for batch in module.dataset("train"):
        frames += batch["frames"].shape[0] * batch["frames"].shape[1]
        if frames >= min_frames:
            break
    seconds = time.perf_counter() - start
    return {"frames": frames, "seconds": seconds, "frames_per_s": frames / seconds,
            "samples_per_s": frames / seq_len / seconds, "workers": 0, "noop_filter": True}


def train_step_seconds(
    batch_size: int, seq_len: int, tbptt: int, steps: int, input_downsample: int = 1
) -> dict:
    torch.manual_seed(0)
    module = CVPT(
        model="tiny", tbptt_len=tbptt, cosine_steps=100, input_downsample=input_downsample
    )
    optimizer = module.configure_optimizers()["optimizer"]
    frames = torch.randint(0, 256, (batch_size, seq_len, 144, 144, 3), dtype=torch.uint8)
    actions = torch.randint(0, 17, (batch_size, seq_len))
    first = torch.zeros(batch_size, seq_len, dtype=torch.bool)
    module.train()
    times = []
    for _ in range(steps + 1):  # the first step warms up
        start = time.perf_counter()
        loss = module._loss(module(frames, first), actions)
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(module.parameters(), 5.0)
        optimizer.step()
        times.append(time.perf_counter() - start)
    seconds = float(np.median(times[1:]))
    frames_per_step = batch_size * seq_len
    return {"batch": batch_size, "seq_len": seq_len, "tbptt": tbptt,
            "input_downsample": input_downsample, "seconds": seconds,
            "frames_per_step": frames_per_step, "frames_per_s": frames_per_step / seconds}


def cached_vs_recompute(steps: int, num_envs: int) -> dict:
    torch.manual_seed(0)
    model = CVPTModel(CVPTConfig.from_name("tiny")).eval()
    policy = CVPTPolicy(model)
    memory = model.config.memory_len
    frames = np.random.default_rng(0).integers(0, 256, (steps, num_envs, 144, 144, 3), dtype=np.uint8)
    first = np.zeros(num_envs, bool)
    state = policy.initial_state(num_envs)
    policy.act(frames[0], state, first)  # warm-up
    start = time.perf_counter()
    for t in range(steps):
        _, state = policy.act(frames[t], state, first)
    cached = (time.perf_counter() - start) / steps
    window = torch.randint(0, 256, (num_envs, memory + 1, 144, 144, 3), dtype=torch.uint8)
    window_first = torch.zeros(num_envs, memory + 1, dtype=torch.bool)
    recompute_steps = max(2, steps // 10)
    with torch.no_grad():
        start = time.perf_counter()
        for _ in range(recompute_steps):
            model(window, window_first, model.initial_state(num_envs))
        recompute = (time.perf_counter() - start) / recompute_steps
    return {"num_envs": num_envs, "memory_len": memory, "cached_ms_per_step": 1e3 * cached,
            "recompute_ms_per_step": 1e3 * recompute, "speedup": recompute / cached}


def preset_memory(name: str, seq_len: int) -> dict:
    """Run in a fresh process: build the preset, forward one sequence without grad."""
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    model = CVPTModel(CVPTConfig.from_name(name)).eval()
    built = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    frames = torch.randint(0, 256, (1, seq_len, 144, 144, 3), dtype=torch.uint8)
    start = time.perf_counter()
    with torch.no_grad():
        model(frames, torch.zeros(1, seq_len, dtype=torch.bool), model.initial_state(1))
    seconds = time.perf_counter() - start
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return {"params": model.get_num_params(), "seq_len": seq_len, "forward_s": seconds,
            "rss_before_mib": before / 1024, "rss_after_build_mib": built / 1024,
            "peak_rss_mib": peak / 1024}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default="data/crafterplay_smoke")
    parser.add_argument("--preset-memory", help=argparse.SUPPRESS)  # child-process mode
    args = parser.parse_args()
    if args.preset_memory:
        print(json.dumps(preset_memory(args.preset_memory, seq_len=16)))
        return

    step = train_step_seconds(batch_size=2, seq_len=64, tbptt=64, steps=2)
    # configs/cvpt_tiny_cpu.yaml: frames pooled to 72 px, so the step is cheaper and the
    # loader's share larger
    step_72 = train_step_seconds(batch_size=2, seq_len=64, tbptt=64, steps=2, input_downsample=2)
    loader = loader_frames_per_s(args.data, seq_len=64, batch_size=2, min_frames=4 * step["frames_per_step"])
    loader_seconds_per_step = step["frames_per_step"] / loader["frames_per_s"]
    presets = {}
    for name in ("tiny", "base", "large"):
        out = subprocess.run(
            [sys.executable, __file__, "--preset-memory", name], check=True, capture_output=True, text=True
        )
        presets[name] = json.loads(out.stdout.strip().splitlines()[-1])
    results = {
        "machine": {"platform": platform.platform(), "cpus": os.cpu_count(),
                    "torch_threads": torch.get_num_threads(), "torch": torch.__version__,
                    "load_avg_1m": os.getloadavg()[0]},
        "train_step_tiny": step,
        "train_step_tiny_72px": step_72,
        "datamodule": loader,
        "loader_share_of_step": loader_seconds_per_step / step["seconds"],
        "loader_share_of_step_72px": loader_seconds_per_step / step_72["seconds"],
        "inference_tiny": cached_vs_recompute(steps=30, num_envs=1),
        "presets": presets,
    }
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps(results, indent=2) + "\n")
    print(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()
