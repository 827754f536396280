"""GPU acceptance run: each paper config at its real per-device batch -> bench/results/gpu.json.

For each training stage (configs/<stage>.yaml, built as `zoo scale` builds it: C-CLIP from random
init, C-Steve-1 on an in-memory C-VPT base) a few optimizer steps on synthetic batches of the
real shapes and dtypes, in the config's precision: seconds per step, frames (clips, pairs) per
second, peak GPU memory (torch.cuda.max_memory_allocated) and the achieved FLOP/s and MFU; with
``--data DIR`` the C-VPT stages also train from a real CrafterPlayDataModule over DIR for
``--data-seconds`` and report the share of time spent waiting for data. Beside each: the
projection of lit_models.scale for the same stage (FLOPs per unit, memory estimate, rate at 30%
and 15% MFU on this GPU). The PPO expert is bench/bench_ppo.py's (its time is the env's).
Takes under 10 minutes on one GPU.

    python bench/bench_gpu.py                                  # every stage, synthetic batches
    python bench/bench_gpu.py --data data/crafterplay          # + the data-wait share
    python bench/bench_gpu.py --projection runs/scale/scale.json   # reuse `zoo scale`'s numbers
    python bench/bench_gpu.py --tiny                           # CPU, batch 1: does it run?
"""

from __future__ import annotations

import argparse
import json
import platform
import tempfile
import time
from pathlib import Path

import torch

from lit_models.scale import modules, project
from lit_models.scale.measure import (
    Measurement,
    measure_torch_stage,
    train_step,
    trainable_optimizer,
)
from lit_models.scale.stages import QUICK_STAGES, STAGES, Stage, load_stage

RESULTS = Path(__file__).parent / "results" / "gpu.json"
TORCH_STAGES = tuple(name for name, (kind, _) in STAGES.items() if kind != "ppo")
# substrings of torch.cuda.get_device_name -> project.GPUS key (H200: H100's compute, more memory)
GPU_NAMES = (("4090", "rtx4090"), ("A6000", "a6000"), ("H100", "h100"), ("H200", "h100"))


def gpu_peak(device: torch.device) -> tuple[str, float | None]:
    """This device's name and the assumed bf16 dense peak (None: not in project.GPUS)."""
    if device.type != "cuda":
        return platform.processor() or platform.machine(), None
    name = torch.cuda.get_device_name(device)
    key = next((key for needle, key in GPU_NAMES if needle in name), None)
    return name, project.GPUS[key].bf16_dense_flops if key else None


def _sync(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def synthetic_steps(
    stage: Stage, module: torch.nn.Module, batch: int, steps: int, device: torch.device
) -> dict:
    """Seconds per optimizer step on one synthetic batch, after two warm-up steps."""
    data = modules.make_batch(stage, module, batch, str(device))
    optimizer = trainable_optimizer(module)
    if device.type == "cuda":
        torch.cuda.reset_peak_memory_stats(device)
    for _ in range(2):
        train_step(stage, module, optimizer, data, stage.mixed)
    _sync(device)
    start = time.perf_counter()
    for _ in range(steps):
        train_step(stage, module, optimizer, data, stage.mixed)
    _sync(device)
    seconds = (time.perf_counter() - start) / steps
    out = {"batch": batch, "steps": steps, "s_per_step": seconds,
           "units_per_s": batch * stage.units_per_sample / seconds}  # fmt: skip
    if device.type == "cuda":
        out["peak_allocated_gib"] = torch.cuda.max_memory_allocated(device) / project.GIB
        out["peak_reserved_gib"] = torch.cuda.max_memory_reserved(device) / project.GIB
    return out


def data_wait(
    stage: Stage, module: torch.nn.Module, root: Path, batch: int, seq_len: int, workers: int,
    seconds: float, device: torch.device,
) -> dict:
    """Train window by window from a real CrafterPlayDataModule over ``root``: the share of the
    time spent waiting for batches (the first batch, which pays for worker start-up, apart)."""
    from datamodules.crafterplay import CrafterPlayDataModule

    init = dict(stage.config["data"]["init_args"])
    init.update(root=str(root), batch_size=batch, seq_len=seq_len, num_workers=workers,
                val_fraction=0.0, test_fraction=0.0, train_batches_per_epoch=10**6)  # fmt: skip
    loader = iter(CrafterPlayDataModule(**init).train_dataloader())
    optimizer = trainable_optimizer(module)
    start = time.perf_counter()
    next(loader)
    first = time.perf_counter() - start
    waited = trained = 0.0
    frames = 0
    window = stage.units_per_sample
    while waited + trained < seconds:
        start = time.perf_counter()
        data = {k: v.to(device, non_blocking=True) for k, v in next(loader).items()
                if k in ("frames", "first", "actions")}  # fmt: skip
        _sync(device)
        ready = time.perf_counter()
        for t in range(0, data["frames"].shape[1], window):
            train_step(stage, module, optimizer, {k: v[:, t : t + window] for k, v in data.items()},
                       stage.mixed)  # fmt: skip
        _sync(device)
        waited, trained = waited + ready - start, trained + time.perf_counter() - ready
        frames += data["frames"].shape[0] * data["frames"].shape[1]
    return {"root": str(root), "workers": workers, "seq_len": seq_len, "first_batch_s": first,
            "frames": frames, "frames_per_s": frames / (waited + trained),
            "data_wait_share": waited / (waited + trained)}  # fmt: skip


def projection(stage: Stage, measured: Measurement, batch: int, peak: float | None) -> dict:
    """lit_models.scale's numbers for this stage at ``batch`` on this device."""
    memory = project.memory(measured, batch)
    out = {"flops_per_unit": measured.flops_per_unit, "memory_estimate_gib": memory["total_gib"],
           "memory_parts_gib": {k: v for k, v in memory.items() if k != "total_gib"}}  # fmt: skip
    if peak:
        out["units_per_s"] = {f"{mfu:.0%}": peak * mfu / measured.flops_per_unit
                              for mfu in project.MFUS}  # fmt: skip
    return out


def load_projection(path: Path | None, stage: Stage) -> Measurement:
    """The stage's measurement from a `zoo scale` scale.json, or measured now (CPU, quick)."""
    if path is not None:
        entry = json.loads(path.read_text())["stages"].get(stage.name)
        if entry is not None:
            measured = dict(entry["measured"])
            measured["activation_bytes"] = {int(k): v for k, v in
                                            measured["activation_bytes"].items()}  # fmt: skip
            return Measurement(**measured)
    return measure_torch_stage(stage, steps=1, warmup=0)


def bench_stage(
    name: str, args: argparse.Namespace, device: torch.device, peak: float | None
) -> dict:
    stage = load_stage(name, args.configs)
    measured = load_projection(args.projection, stage)
    batch = 1 if args.tiny else stage.per_device_batch
    torch.manual_seed(0)
    module = modules.build_module(stage).to(device)
    row: dict = {"stage": name, "unit": stage.unit, "precision": stage.precision}
    try:
        row["synthetic"] = synthetic_steps(stage, module, batch, args.steps, device)
    except torch.cuda.OutOfMemoryError as err:
        row["synthetic"] = {"batch": batch, "oom": str(err).splitlines()[0]}
    if args.data and stage.data == "crafterplay" and stage.name.startswith("cvpt"):
        seq_len = stage.units_per_sample * (1 if args.tiny else stage.samples_per_batch_len)
        workers = args.workers or stage.config["data"]["init_args"]["num_workers"]
        workers = 0 if args.tiny else workers
        row["data"] = data_wait(stage, module, args.data, batch, seq_len, workers,
                                args.data_seconds, device)  # fmt: skip
    rate = row["synthetic"].get("units_per_s")
    if rate and peak:
        row["synthetic"]["mfu"] = rate * measured.flops_per_unit / peak
    row["projection"] = projection(stage, measured, batch, peak)
    del module
    if device.type == "cuda":
        torch.cuda.empty_cache()
    return row


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--stages", nargs="+", choices=TORCH_STAGES,
                        help="default: all (with --tiny: " + " ".join(QUICK_STAGES) + ")")
    parser.add_argument("--configs", type=Path, default=Path("configs"))
    parser.add_argument("--steps", type=int, default=5, help="timed steps per stage")
    parser.add_argument("--data", type=Path, help="a CrafterPlay folder: time the real loader")
    parser.add_argument("--workers", type=int, help="loader workers (default: the config's)")
    parser.add_argument("--data-seconds", type=float, default=45.0)
    parser.add_argument("--projection", type=Path, help="a `zoo scale` scale.json to compare "
                        "with (default: measure the stages on the CPU now, quick)")
    parser.add_argument("--tiny", action="store_true",
                        help="CPU, batch 1, 1 step, loader without workers: a smoke run")
    parser.add_argument("--out", type=Path, help=f"default: {RESULTS} (--tiny: a temp file)")
    args = parser.parse_args(argv)
    if args.tiny:
        args.steps, args.data_seconds = 1, min(args.data_seconds, 5.0)
    device = torch.device("cpu" if args.tiny or not torch.cuda.is_available() else "cuda")
    name, peak = gpu_peak(device)
    start = time.perf_counter()
    rows = [bench_stage(s, args, device, peak)
            for s in args.stages or (QUICK_STAGES if args.tiny else TORCH_STAGES)]  # fmt: skip
    results = {
        "mode": "cpu-tiny" if args.tiny else device.type, "device": name,
        "assumed_bf16_dense_peak": peak, "torch": torch.__version__,
        "date": time.strftime("%Y-%m-%d %H:%M"), "seconds": time.perf_counter() - start,
        "stages": rows,
    }  # fmt: skip
    out = args.out or (Path(tempfile.gettempdir()) / "gpu_tiny.json" if args.tiny else RESULTS)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(results, indent=1) + "\n")
    print(json.dumps(results, indent=1))
    return results


if __name__ == "__main__":
    main()
