"""C-VPT speed and memory on this machine (CPU) -> bench/results/cvpt.json.

Measures:
  * training throughput of the tiny model (fp32, and bf16 as configs/cvpt_tiny_cpu.yaml) fed by
    CrafterPlayDataModule (DataLoader workers decoding, filtering and packing in parallel)
    against the same steps on a batch already in memory; the loader's overhead is the extra time per step (goal <= 10%), at 144 px (the
    paper's input) and at 72 px (configs/cvpt_tiny_cpu.yaml, where the step is ~5x cheaper);
  * the datamodule alone (one process) in frames/s;
  * a tiny 72-px training step in fp32 against bf16 autocast (the CPU recipe's precision);
  * cached per-step inference (rolling TrXL memory) against recomputing the whole window of
    memory_len + 1 frames every step (goal >= 5x);
  * parameters and peak resident memory of one training step (forward + backward + AdamW) per
    preset, each in a fresh process whose peak is reset after the imports (Linux clear_refs).

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
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import torch

from datamodules.crafterplay import CrafterPlayDataModule
from lit_models.cvpt import CVPT
from zoo.agents.cvpt_agent import CVPTPolicy
from zoo.envs.constants import NUM_ACTIONS
from zoo.models.cvpt import CVPTConfig, CVPTModel

RESULTS = Path(__file__).parent / "results" / "cvpt.json"


def _datamodule(root: str, seq_len: int, batch_size: int, workers: int) -> CrafterPlayDataModule:
    return CrafterPlayDataModule(
        root, seq_len=seq_len, batch_size=batch_size, num_workers=workers, val_fraction=0.0,
        test_fraction=0.0, train_batches_per_epoch=10**6, pin_memory=False,
    )


def loader_frames_per_s(root: str, seq_len: int, batch_size: int, min_frames: int) -> dict:
    """The datamodule alone in this process: decode + noop filter + pack + batch."""
    frames, start = 0, time.perf_counter()
    for batch in _datamodule(root, seq_len, batch_size, 0).dataset("train"):
        frames += batch["frames"].shape[0] * batch["frames"].shape[1]
        if frames >= min_frames:
            break
    seconds = time.perf_counter() - start
    return {"frames": frames, "seconds": seconds, "frames_per_s": frames / seconds,
            "workers": 0, "noop_filter": True}


def _train_step(module: CVPT, optimizer: torch.optim.Optimizer, batch: dict, bf16: bool) -> None:
    """One optimizer step as Lightning runs it (precision 32 or bf16-mixed, clip 5)."""
    with torch.autocast("cpu", dtype=torch.bfloat16, enabled=bf16):
        loss = module._loss(module(batch["frames"], batch["first"]), batch["actions"])
    optimizer.zero_grad(set_to_none=True)
    loss.backward()
    torch.nn.utils.clip_grad_norm_(module.parameters(), 5.0)
    optimizer.step()


def bf16_vs_fp32(batch_size: int, seq_len: int, steps: int, input_downsample: int) -> dict:
    """Seconds per tiny training step on one in-memory batch, fp32 against bf16 autocast
    (configs/cvpt_tiny_cpu.yaml's precision); alternated so load drifts hit both alike."""
    torch.manual_seed(0)
    module = CVPT(model="tiny", tbptt_len=seq_len, cosine_steps=100,
                  input_downsample=input_downsample, activation_checkpointing=False)
    optimizer = module.configure_optimizers()["optimizer"]
    module.train()
    batch = {
        "frames": torch.randint(0, 256, (batch_size, seq_len, 144, 144, 3), dtype=torch.uint8),
        "first": torch.zeros(batch_size, seq_len, dtype=torch.bool),
        "actions": torch.randint(0, 17, (batch_size, seq_len)),
    }
    seconds = {False: 0.0, True: 0.0}
    for bf16 in (False, True):
        _train_step(module, optimizer, batch, bf16)  # warm-up (oneDNN kernels per dtype)
    for _ in range(steps):
        for bf16 in (False, True):
            start = time.perf_counter()
            _train_step(module, optimizer, batch, bf16)
            seconds[bf16] += time.perf_counter() - start
    flags = Path("/proc/cpuinfo").read_text().split()
    return {"batch": batch_size, "seq_len": seq_len, "input_downsample": input_downsample,
            "steps": steps, "fp32_s_per_step": seconds[False] / steps,
            "bf16_s_per_step": seconds[True] / steps, "speedup": seconds[False] / seconds[True],
            "cpu_amx_bf16": "amx_bf16" in flags, "cpu_avx512_bf16": "avx512_bf16" in flags}


def training_throughput(
    root: str, batch_size: int, seq_len: int, steps: int, input_downsample: int, workers: int,
    bf16: bool = False,
) -> dict:
    """Seconds per optimizer step on in-memory frames vs on the datamodule's batches."""
    torch.manual_seed(0)
    module = CVPT(model="tiny", tbptt_len=seq_len, cosine_steps=100,
                  input_downsample=input_downsample, activation_checkpointing=False)
    optimizer = module.configure_optimizers()["optimizer"]
    module.train()

    loader = iter(_datamodule(root, seq_len, batch_size, workers).train_dataloader())
    fixed = next(loader)
    _train_step(module, optimizer, fixed, bf16)  # warm-up
    start = time.perf_counter()
    for _ in range(steps):
        _train_step(module, optimizer, fixed, bf16)
    model_only = (time.perf_counter() - start) / steps
    start = time.perf_counter()
    for _ in range(steps):
        _train_step(module, optimizer, next(loader), bf16)
    with_data = (time.perf_counter() - start) / steps
    frames = batch_size * seq_len
    return {"batch": batch_size, "seq_len": seq_len, "input_downsample": input_downsample,
            "bf16": bf16, "workers": workers, "steps": steps, "model_only_s_per_step": model_only,
            "with_datamodule_s_per_step": with_data, "frames_per_s_model_only": frames / model_only,
            "frames_per_s_with_datamodule": frames / with_data,
            "loader_overhead": (with_data - model_only) / with_data}


def cached_vs_recompute(steps: int, num_envs: int) -> dict:
    torch.manual_seed(0)
    model = CVPTModel(CVPTConfig.from_name("tiny", NUM_ACTIONS)).eval()
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


def _proc_status_mib(field: str) -> float:
    """A memory field of /proc/self/status (VmRSS: now, VmHWM: peak since the last reset)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(f"{field}:"):
            return int(line.split()[1]) / 1024
    raise RuntimeError(f"no {field} in /proc/self/status (Linux only)")


def preset_memory(name: str, seq_len: int) -> dict:
    """Run in a fresh process: peak RSS of building the preset and one training step on one
    sequence of ``seq_len`` 144-px frames, above the imports' own footprint."""
    Path("/proc/self/clear_refs").write_text("5")  # reset VmHWM to the current RSS
    base = _proc_status_mib("VmRSS")
    model = CVPTModel(CVPTConfig.from_name(name, NUM_ACTIONS))
    built = _proc_status_mib("VmRSS")
    optimizer = torch.optim.AdamW(model.parameters(), lr=1e-4)
    frames = torch.randint(0, 256, (1, seq_len, 144, 144, 3), dtype=torch.uint8)
    first = torch.zeros(1, seq_len, dtype=torch.bool)
    start = time.perf_counter()
    logits, _ = model(frames, first, model.initial_state(1))
    logits.float().logsumexp(-1).mean().backward()
    optimizer.step()
    seconds = time.perf_counter() - start
    return {"params": model.get_num_params(), "seq_len": seq_len, "train_step_s": seconds,
            "rss_imports_mib": base, "model_mib": built - base,
            "peak_above_imports_mib": _proc_status_mib("VmHWM") - base}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default="data/crafterplay_smoke")
    parser.add_argument("--steps", type=int, default=6, help="timed steps per measurement")
    parser.add_argument("--workers", type=int, default=1, help="DataLoader workers")
    parser.add_argument("--preset-memory", help=argparse.SUPPRESS)  # child-process mode
    args = parser.parse_args()
    if args.preset_memory:
        print(json.dumps(preset_memory(args.preset_memory, seq_len=16)))
        return

    throughput = {
        "tiny_144px": training_throughput(args.data, 2, 64, args.steps, 1, args.workers),
        "tiny_72px": training_throughput(args.data, 8, 64, args.steps, 2, args.workers),
        "tiny_72px_bf16": training_throughput(args.data, 8, 64, args.steps, 2, args.workers, True),
    }
    loader = loader_frames_per_s(args.data, seq_len=64, batch_size=8, min_frames=8192)
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
        "training": throughput,
        "datamodule_alone": loader,
        "precision_tiny_72px": bf16_vs_fp32(8, 64, args.steps, 2),
        "inference_tiny": cached_vs_recompute(steps=30, num_envs=1),
        "presets": presets,
    }
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps(results, indent=2) + "\n")
    print(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()
