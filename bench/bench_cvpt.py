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
    preset, each in a fresh process whose peak is reset after the imports (Linux clear_refs);
  * a step's anatomy at the recipe's shape (bench/cvpt_profile.py, bench/cvpt_e2e.py): the CPU's
    fp32/bf16 matmul and conv peaks (``peaks``); the recipe's frames/s under the real `zoo fit`
    loop against model-only steps in the same run (``end_to_end``); ms per step of each model
    part, the optimizer, the data-loader wait and Lightning's loop (``profile``); FLOPs per
    frame and the share of the peaks each setting reaches (``flops``).

The full measurement (every key; ~10 minutes on a quiet 2-core machine), on the recipe's Craftax
data, with nothing else running:
  nice -n 10 .venv/bin/python bench/bench_cvpt.py --data data/crafterplay_plantsfirst_cx2k
A smoke run (tiny step counts; the 8-episode set has no validation episodes at the recipe's 5%,
hence the override), written outside bench/results:
  zoo data generate --expert scripted --env crafter --episodes 8 --max-steps 300 --seed 0 \
      --episodes-per-shard 4 --out data/bench_cvpt_smoke --workers 1
  .venv/bin/python bench/bench_cvpt.py --quick --data data/bench_cvpt_smoke \
      --out /tmp/cvpt_smoke.json --e2e-set data.init_args.val_fraction=0.25
--data defaults to data/crafterplay_smoke:
  zoo data generate --expert random --env crafter --episodes 16 --max-steps 200 --seed 0 \
      --episodes-per-shard 4 --chunk-length 64 --out data/crafterplay_smoke
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

import cvpt_e2e
import cvpt_levers
import cvpt_profile
import numpy as np
import torch
import yaml

from datamodules.crafterplay import CrafterPlayDataModule
from lit_models.cvpt import CVPT
from zoo.agents.cvpt_agent import CVPTPolicy
from zoo.envs.constants import NUM_ACTIONS
from zoo.models.cvpt import CVPTConfig, CVPTModel

RESULTS = Path(__file__).parent / "results" / "cvpt.json"
RECIPE = Path("configs/cvpt_tiny_cpu.yaml")


@dataclasses.dataclass(frozen=True)
class Sizes:
    """How long each measurement runs; ``QUICK`` is the --quick smoke run."""

    steps: int = 6  # timed steps of each training/precision measurement
    loader_frames: int = 8192
    inference_steps: int = 30
    presets: tuple[str, ...] = ("tiny", "base", "large")
    matmul: tuple[int, ...] = (1024, 2048, 4096)  # square matmul sizes of the peaks
    repeats: int = 5  # best of this many peak calls
    model_warmup: int = 3
    model_steps: int = 20  # model-only steps before `zoo fit` (half as many after it)
    profiler_steps: int = 3
    e2e_warmup: int = 10  # `zoo fit` steps left out of the steady state
    e2e_steps: int = 150
    e2e_epoch: int = 50  # steps between validations + checkpoints (the recipe: 250)


QUICK = Sizes(steps=2, loader_frames=2048, inference_steps=10, presets=("tiny",),
              matmul=(512, 1024), repeats=2, model_warmup=1, model_steps=3, profiler_steps=1,
              e2e_warmup=2, e2e_steps=8, e2e_epoch=5)


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
                  input_downsample=input_downsample)
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
                  input_downsample=input_downsample)
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


def _mean_run(runs: list[dict]) -> dict:
    """Step-weighted mean of ``ModelOnly.run`` results (before and after `zoo fit`)."""
    steps = sum(r["steps"] for r in runs)
    parts = {k: sum(r["parts_s"][k] * r["steps"] for r in runs) / steps for k in runs[0]["parts_s"]}
    frames = runs[0]["frames_per_s"] * runs[0]["s_per_step"]
    return {"steps": steps, "s_per_step": parts["total"], "frames_per_s": frames / parts["total"],
            "parts_s": parts, "frames_per_s_before_after": [r["frames_per_s"] for r in runs]}


def step_anatomy(recipe_path: Path, data: str, sizes: Sizes, overrides: list[str]) -> dict:
    """The peaks, end_to_end, profile and flops keys: the recipe's model and batch shape,
    model-only steps before and after its `zoo fit` run (load on a shared box drifts)."""
    recipe = yaml.safe_load(recipe_path.read_text())
    bf16 = str(recipe["trainer"].get("precision", "")).startswith("bf16")
    torch.manual_seed(0)
    module = cvpt_profile.build(recipe["model"])
    datamodule = cvpt_profile.build(recipe["data"], root=data, sources=None, num_workers=0,
                                    train_batches_per_epoch=None)
    batch = next(iter(datamodule.dataset("train")))
    frames = batch["actions"].numel()
    counted = cvpt_profile.flops_per_frame(module, batch, bf16)
    peaks = cvpt_profile.peaks(sizes.matmul, sizes.repeats,
                               cvpt_profile.encoder_convs(module.model), frames)
    steps = cvpt_profile.ModelOnly(module, batch, bf16)
    before = steps.run(sizes.model_steps, sizes.model_warmup)
    top_ops = cvpt_profile.top_ops(steps.step, sizes.profiler_steps, k=15)
    threads = torch.get_num_threads()  # one thread: how much the step suffers from sharing cores
    torch.set_num_threads(1)
    one_thread = steps.run(max(1, sizes.model_steps // 4), warmup=1)
    torch.set_num_threads(threads)
    e2e = cvpt_e2e.run_fit(recipe_path, data, sizes.e2e_warmup, sizes.e2e_steps, sizes.e2e_epoch,
                           overrides)
    model_only = _mean_run([before, steps.run(max(1, sizes.model_steps // 2), warmup=0)])
    e2e |= {"model_only_frames_per_s": model_only["frames_per_s"],
            "ratio_to_model_only": e2e["frames_per_s"] / model_only["frames_per_s"],
            "recipe_ratio_to_model_only": e2e["recipe_frames_per_s"] / model_only["frames_per_s"]}
    profile = {
        "shape": {"batch": batch["actions"].shape[0], "seq_len": batch["actions"].shape[1],
                  "px": module.config.frame_size // module.config.input_downsample, "bf16": bf16},
        "method": "forward: hooks at each part's end; backward: gradient hooks on each part's "
                  "output (autograd runs the parts' backward in turn); data wait, training "
                  "batch and loop: `zoo fit` with SimpleProfiler",
        "model_only": model_only,
        "model_only_1_thread": one_thread,
        "lightning_overhead_ms": 1e3 * (e2e["s_per_step"] - model_only["s_per_step"]),
        "rows": cvpt_profile.profile_rows(model_only["parts_s"], e2e),
        "top_ops": top_ops,
    }
    flops = cvpt_profile.flops_summary(counted, model_only, e2e, peaks)
    return {"peaks": peaks, "end_to_end": e2e, "profile": profile, "flops": flops}


def recipe_levers(recipe_path: Path, data: str, quick: bool, compile_model: bool) -> dict:
    """cvpt_levers.levers on the recipe's model and one batch of ``data``."""
    recipe = yaml.safe_load(recipe_path.read_text())
    bf16 = str(recipe["trainer"].get("precision", "")).startswith("bf16")
    datamodule = cvpt_profile.build(recipe["data"], root=data, sources=None, num_workers=0,
                                    train_batches_per_epoch=None)
    batch = next(iter(datamodule.dataset("train")))

    def build(**overrides: object) -> torch.nn.Module:
        torch.manual_seed(0)
        return cvpt_profile.build(recipe["model"], **overrides).train()

    return cvpt_levers.levers(build, batch, bf16, steps=3 if quick else 12,
                              warmup=1 if quick else 2, compile_model=compile_model)


def machine() -> dict:
    """What the numbers were measured on (the CPU model and its bf16 units matter most)."""
    return {"platform": platform.platform(), "load_avg_1m": os.getloadavg()[0],
            **cvpt_profile.cpu_state()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default="data/crafterplay_smoke")
    parser.add_argument("--steps", type=int, help="timed steps per training measurement")
    parser.add_argument("--workers", type=int, default=1, help="DataLoader workers")
    parser.add_argument("--quick", action="store_true", help="tiny step counts: a smoke run")
    parser.add_argument("--out", type=Path, default=RESULTS, help="the results JSON")
    parser.add_argument("--config", type=Path, default=RECIPE, help="the recipe `zoo fit` runs")
    parser.add_argument("--e2e-steps", type=int, help="timed `zoo fit` steps after the warm-up")
    parser.add_argument("--e2e-set", action="append", default=[], metavar="KEY=VALUE",
                        help="override a recipe value for `zoo fit` (repeatable), e.g. "
                             "data.init_args.val_fraction=0.25")
    parser.add_argument("--levers-only", action="store_true",
                        help="measure only the levers (cvpt_levers.py) into --out's `levers`")
    parser.add_argument("--compile", action="store_true", help="add torch.compile to the levers")
    parser.add_argument("--old-code", type=Path, metavar="DIR",
                        help="with --against: run --config on the package code of DIR (a "
                             "checkout of the commit before a change: `git worktree add DIR REV`)")
    parser.add_argument("--loader-only", action="store_true",
                        help="measure only the datamodule alone into --out's `datamodule_alone`")
    parser.add_argument("--against", type=Path, metavar="CONFIG",
                        help="measure only `zoo fit` of --config against CONFIG, taking turns, "
                             "into --out's `recipes` (old = --config, new = CONFIG)")
    parser.add_argument("--preset-memory", help=argparse.SUPPRESS)  # child-process mode
    args = parser.parse_args()
    if args.preset_memory:
        print(json.dumps(preset_memory(args.preset_memory, seq_len=16)))
        return
    if args.levers_only:
        results = json.loads(args.out.read_text()) if args.out.exists() else {}
        results["levers"] = recipe_levers(args.config, args.data, args.quick, args.compile)
        results["levers"]["machine"] = machine()
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(results, indent=2) + "\n")
        print(json.dumps(results["levers"], indent=2))
        return
    sizes = QUICK if args.quick else Sizes()
    given = {"steps": args.steps, "e2e_steps": args.e2e_steps}
    sizes = dataclasses.replace(sizes, **{k: v for k, v in given.items() if v is not None})
    if args.loader_only:
        results = json.loads(args.out.read_text()) if args.out.exists() else {}
        results["datamodule_alone"] = loader_frames_per_s(
            args.data, seq_len=64, batch_size=8, min_frames=sizes.loader_frames)
        results["datamodule_alone"]["machine"] = machine()
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(results, indent=2) + "\n")
        print(json.dumps(results["datamodule_alone"]["frames_per_s"]))
        return
    if args.against:
        results = json.loads(args.out.read_text()) if args.out.exists() else {}
        key = "recipes_vs_old_code" if args.old_code else "recipes"
        results[key] = cvpt_e2e.compare_recipes(
            args.config, args.against, args.data, sizes.e2e_warmup, sizes.e2e_steps,
            sizes.e2e_epoch, args.e2e_set, rounds=1 if args.quick else 2, old_code=args.old_code)
        results[key]["machine"] = machine()
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(results, indent=2) + "\n")
        print(json.dumps({k: v for k, v in results[key].items() if k not in ("old", "new")},
                         indent=2))
        return

    throughput = {
        "tiny_144px": training_throughput(args.data, 2, 64, sizes.steps, 1, args.workers),
        "tiny_72px": training_throughput(args.data, 8, 64, sizes.steps, 2, args.workers),
        "tiny_72px_bf16": training_throughput(args.data, 8, 64, sizes.steps, 2, args.workers, True),
    }
    loader = loader_frames_per_s(args.data, seq_len=64, batch_size=8,
                                 min_frames=sizes.loader_frames)
    presets = {}
    for name in sizes.presets:
        out = subprocess.run(
            [sys.executable, __file__, "--preset-memory", name], check=True, capture_output=True, text=True
        )
        presets[name] = json.loads(out.stdout.strip().splitlines()[-1])
    results = {
        "machine": machine(),
        "training": throughput,
        "datamodule_alone": loader,
        "precision_tiny_72px": bf16_vs_fp32(8, 64, sizes.steps, 2),
        "inference_tiny": cached_vs_recompute(steps=sizes.inference_steps, num_envs=1),
        "presets": presets,
        **step_anatomy(args.config, args.data, sizes, args.e2e_set),
        "levers": recipe_levers(args.config, args.data, args.quick, args.compile),
        "run": {"quick": args.quick, "sizes": dataclasses.asdict(sizes),
                "load_avg_1m_end": os.getloadavg()[0]},
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(results, indent=2) + "\n")
    print(json.dumps(results, indent=2))
    print(cvpt_profile.table(results))


if __name__ == "__main__":
    main()
