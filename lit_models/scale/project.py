"""From what was measured on the CPU to what the paper's scale will cost on GPUs.

Everything assumed lives here, each with its source: GPU peaks and memory, the MFUs, the memory
margin, the CrafterPlay size and its noop filter. Measured inputs are a stage's ``Measurement``
and the loader rates of bench/results (``load_rates``, each with the JSON field it came from).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

from lit_models.scale.measure import Measurement
from lit_models.scale.stages import Stage

GIB = 1024**3


@dataclass(frozen=True)
class Gpu:
    name: str
    memory_gib: float
    bf16_dense_flops: float  # tensor-core peak, bf16 inputs with fp32 accumulate, no sparsity
    source: str


GPUS: dict[str, Gpu] = {
    "rtx4090": Gpu("RTX 4090", 24, 165.2e12, "NVIDIA Ada GPU architecture whitepaper, RTX 4090: "
                   "165.2 TFLOPS BF16 tensor, FP32 accumulate (330.3 with sparsity)"),
    "a6000": Gpu("RTX A6000", 48, 154.8e12, "NVIDIA RTX A6000 datasheet: 309.7 TFLOPS tensor "
                 "with sparsity, halved for dense"),
    "h100": Gpu("H100 SXM", 80, 989.4e12, "NVIDIA H100 datasheet: 1,979 TFLOPS BF16 with "
                "sparsity, halved for dense"),
}  # fmt: skip
MFUS = (0.30, 0.15)  # a fair share for small convs/matmuls, and a pessimistic one
MEMORY_MARGIN = 1.2  # allocator fragmentation, backward's transient buffers, cuDNN workspaces
CONTEXT_GIB = 1.0  # CUDA context and library handles (~0.5-1 GB)
PAPER_FRAMES = 180e6  # CrafterPlay: 20,000 episodes, ~180M steps (paper, Appendix)
# Frames decoded per frame trained: the noop filter drops ~58% (paper: noops 60% of actions,
# 4.6% after filtering; the C-VPT configs' header: ~75.6M of 180M frames are left).
DECODED_PER_TRAINED = 180 / 75.6
LOADER_GPU = "rtx4090"  # loader workers are sized for the paper's GPU when a stage has no run


def load_rates(bench: Path) -> dict:
    """Measured loader rates and bytes per frame from bench/results (missing file: none)."""
    rates: dict = {}
    frames, cclip = Path(bench) / "frames.json", Path(bench) / "cclip.json"
    if frames.is_file():
        modes = json.loads(frames.read_text())["modes"]
        for mode in ("stored", "rendered"):
            rates[f"crafterplay_{mode}"] = {
                "decode_per_worker": modes[mode]["decode_fps"],
                "source": f"{frames}: modes.{mode}.decode_fps",
                "bytes_per_frame": modes[mode]["shard_bytes_per_frame"],
                "bytes_source": f"{frames}: modes.{mode}.shard_bytes_per_frame",
            }
    if cclip.is_file():
        loaded = json.loads(cclip.read_text())["smoke_with_datamodule"]
        rates["craftercaption"] = {
            "decode_per_worker": loaded["datamodule_only_samples_per_s"] / loaded["workers"],
            "source": f"{cclip}: smoke_with_datamodule.datamodule_only_samples_per_s "
                      f"/ workers (clips/s)",
        }  # fmt: skip
    return rates


def extrapolate(points: dict[int, float], batch: float) -> float:
    """The line through two (batch, value) points, at ``batch``."""
    (b1, y1), (b2, y2) = sorted(points.items())[:2]
    return y1 + (y2 - y1) / (b2 - b1) * (batch - b1)


def memory(m: Measurement, batch: float) -> dict:
    """Estimated peak device bytes at ``batch`` samples: fp32 weights (bf16-mixed keeps fp32
    master weights), fp32 gradients and AdamW's two moments of the trainable ones, activations
    extrapolated from the two measured batches, inputs and fixed buffers; times the margin,
    plus the CUDA context."""
    parts = {
        "weights_grads_adamw": 4.0 * (m.params_trainable + m.params_frozen)
        + 12.0 * m.params_trainable,
        "activations": extrapolate(m.activation_bytes, batch),
        "inputs": m.extra_bytes_per_sample * batch,
        "fixed_buffers": m.extra_bytes_fixed,
    }
    total = sum(parts.values()) * MEMORY_MARGIN + CONTEXT_GIB * GIB
    return {**{k: v / GIB for k, v in parts.items()}, "total_gib": total / GIB}


def fit(m: Measurement, gpu: Gpu) -> dict:
    """Whether the per-device batch fits ``gpu``; if not, the micro-batch that does (and the
    gradient accumulation steps it needs) and how much activation checkpointing must save."""
    batch = m.memory_batch
    need = memory(m, batch)["total_gib"]
    out = {"gpu": gpu.name, "estimate_gib": need, "capacity_gib": gpu.memory_gib,
           "fits": need <= gpu.memory_gib}  # fmt: skip
    if out["fits"]:
        return out
    fixed = memory(m, 0)
    per_sample = memory(m, 1)["total_gib"] - fixed["total_gib"]
    micro = math.floor((gpu.memory_gib - fixed["total_gib"]) / per_sample)
    out["micro_batch"] = micro if micro >= 1 else None
    out["accumulation_steps"] = math.ceil(batch / micro) if micro >= 1 else None
    room = (gpu.memory_gib - CONTEXT_GIB) / MEMORY_MARGIN - (need - CONTEXT_GIB) / MEMORY_MARGIN
    activations = memory(m, batch)["activations"]
    left = activations + room  # activation bytes that would fit with everything else unchanged
    out["activation_cut_needed"] = activations / left if left > 0 else None
    return out


def hours(flops: float, gpu: Gpu, mfu: float, count: int = 1) -> float:
    """Wall hours of ``flops`` on ``count`` GPUs at ``mfu`` of the bf16 dense peak."""
    return flops / (gpu.bf16_dense_flops * mfu * count) / 3600


EXPLAIN = {
    "sequence": "the work is mostly IMPALA convolutions with 16-128 channels at 144 px, "
                "kernels that run far below the tensor-core peak; at the paper's pace the "
                "loaders must decode {decode} frames/s per GPU; and the reported hours include "
                "validation and evaluation",
    "ppo": "the projection counts the network only; PPO's time is the Craftax env simulated on "
           "the GPU (and the GRU's 64 sequential steps), not matmuls",
}  # fmt: skip


def compare(stage: Stage, m: Measurement) -> dict | None:
    """The paper's reported hours beside the projection on the paper's own GPUs."""
    paper = stage.paper
    if paper is None:
        return None
    gpu = GPUS[paper.gpu]
    units = paper.units or stage.total_units
    flops = units * m.flops_per_unit
    projected = {f"{mfu:.0%}": hours(flops, gpu, mfu, paper.gpus) for mfu in MFUS}
    ratio = paper.hours / projected[f"{MFUS[0]:.0%}"]
    out = {
        "paper_hours": paper.hours, "gpus": f"{paper.gpus}x {gpu.name}", "units": units,
        "source": paper.source, "projected_hours": projected, "paper_over_projected": ratio,
        "implied_mfu": flops / (paper.hours * 3600 * paper.gpus * gpu.bf16_dense_flops),
    }  # fmt: skip
    if ratio > 3:
        decode = units / (paper.hours * 3600 * paper.gpus) * DECODED_PER_TRAINED
        why = EXPLAIN.get(stage.kind, "the stage is not FLOP-bound at this size")
        out["comment"] = (
            f"the paper took {ratio:.1f}x the FLOP projection at {MFUS[0]:.0%} MFU "
            f"(implied MFU {out['implied_mfu']:.1%}), so it was not FLOP-bound: "
            + why.format(decode=f"{decode:,.0f}")
        )
    elif ratio < 1 / 3:
        out["comment"] = (
            f"the paper was {1 / ratio:.1f}x faster than the projection at {MFUS[0]:.0%} MFU "
            f"(implied MFU {out['implied_mfu']:.0%}): the FLOP count or the run's length differs"
        )
    return out


def loading(stage: Stage, m: Measurement, rates: dict) -> dict | None:
    """DataLoader workers per GPU to feed the projected rate (the paper's GPU at the first MFU)
    and the paper's observed rate, in each frame mode, from the measured per-worker decode."""
    if stage.data is None:
        return None
    gpu = GPUS[stage.paper.gpu if stage.paper else LOADER_GPU]
    pace = {f"projected ({gpu.name}, {MFUS[0]:.0%} MFU)":
            gpu.bf16_dense_flops * MFUS[0] / m.flops_per_unit}  # fmt: skip
    if stage.paper:
        pace["paper"] = stage.total_units / (stage.paper.hours * 3600 * stage.paper.gpus)
    decode = 1.0 if stage.data == "craftercaption" else DECODED_PER_TRAINED
    out: dict = {"unit": stage.unit, "decoded_per_trained": decode, "units_per_s_per_gpu": pace,
                 "workers_per_gpu": {}}  # fmt: skip
    for mode in ("stored", "rendered"):
        # CrafterCaption stores its clips' frames whichever mode CrafterPlay was built in
        rate = rates.get(stage.data if stage.data == "craftercaption" else f"{stage.data}_{mode}")
        if rate is None:
            continue
        out["workers_per_gpu"][mode] = {
            name: math.ceil(units * decode / rate["decode_per_worker"])
            for name, units in pace.items()
        }
        out.setdefault("sources", {})[mode] = rate["source"]
    return out


def disk(rates: dict) -> dict:
    """Bytes of the paper's 180M CrafterPlay frames in each mode, from measured bytes/frame."""
    return {
        mode: {"bytes_per_frame": rates[key]["bytes_per_frame"],
               "total_gb": PAPER_FRAMES * rates[key]["bytes_per_frame"] / 1e9,
               "source": rates[key]["bytes_source"]}
        for mode in ("stored", "rendered")
        if (key := f"crafterplay_{mode}") in rates
    }  # fmt: skip


def project(stage: Stage, m: Measurement, rates: dict) -> dict:
    """Everything projected for one stage (JSON-able)."""
    flops = stage.total_units * m.flops_per_unit
    achieved = m.cpu_step_flops / m.cpu_step_s
    return {
        "total_units": stage.total_units,
        "total_flops": flops,
        "memory_at_batch": memory(m, m.memory_batch),
        "fit": {key: fit(m, gpu) for key, gpu in GPUS.items()},
        "gpu_hours": {
            key: {f"{mfu:.0%}": hours(flops, gpu, mfu) for mfu in MFUS} for key, gpu in GPUS.items()
        },
        "paper": compare(stage, m),
        "loading": loading(stage, m, rates),
        "cpu_check": {"achieved_flops": achieved, "fraction_of_peak": achieved / m.cpu_peak_flops},
    }


def assumptions() -> dict:
    return {
        "gpus": {k: {"name": g.name, "memory_gib": g.memory_gib,
                     "bf16_dense_tflops": g.bf16_dense_flops / 1e12, "source": g.source}
                 for k, g in GPUS.items()},
        "mfu": list(MFUS),
        "memory_margin": MEMORY_MARGIN,
        "cuda_context_gib": CONTEXT_GIB,
        "paper_frames": PAPER_FRAMES,
        "decoded_per_trained_frame": DECODED_PER_TRAINED,
    }  # fmt: skip


__all__ = ["GPUS", "MFUS", "Gpu", "assumptions", "compare", "disk", "extrapolate", "fit",
           "hours", "load_rates", "loading", "memory", "project"]  # fmt: skip
