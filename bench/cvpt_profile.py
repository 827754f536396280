"""Where a C-VPT training step's time goes on this CPU, against what the CPU can do: the
``peaks``, ``profile`` and ``flops`` keys of bench/results/cvpt.json (bench/bench_cvpt.py).

* peaks: the best fp32 and bf16 ``torch.matmul`` GFLOP/s over square sizes and of the
  encoder's first and residual convs at the recipe's frames per step, with torch's threads, and
  the oneDNN kernels torch runs for them (``ONEDNN_VERBOSE``: AMX tiles or AVX512-BF16).
* model-only steps of the recipe's model on one in-memory batch (its precision, AdamW, clip),
  timed part by part: forward hooks mark the end of each part's forward, and gradient hooks on
  each part's output mark the start of its backward (autograd runs the parts' backward one
  after the other, head to encoder, so the time between two marks is one part's backward,
  its weight gradients included).
* torch.profiler's heaviest operators of the same step.
* FLOPs per frame by ``lit_models.scale.measure``'s counter (forward + backward, its CPU
  attention rule), in total and per part, and the GFLOP/s each part reaches.
"""

from __future__ import annotations

import importlib
import math
import os
import re
import subprocess
import sys
import time
from collections.abc import Callable
from functools import partial
from pathlib import Path
from statistics import mean

import torch
from torch import nn
from torch.utils.flop_counter import FlopCounterMode

from lit_models.scale.measure import CPU_ATTENTION, autocast, count

PARTS = ("encoder", "trxl", "policy_head")  # CVPTModel's submodules, in forward order
LABELS = {
    "encoder_forward": "IMPALA encoder forward (convs)", "trxl_forward": "Transformer-XL forward",
    "policy_head_forward": "policy head forward", "loss_forward": "loss forward",
    "zero_grad": "zero_grad", "loss_backward": "loss backward",
    "policy_head_backward": "policy head backward", "trxl_backward": "Transformer-XL backward",
    "encoder_backward": "IMPALA encoder backward", "clip": "clip grad norm",
    "adamw_step": "AdamW step + LR schedule",
}
CPU_FLAGS = ("avx512f", "avx512_bf16", "avx512_fp16", "amx_tile", "amx_bf16", "amx_int8")
KERNEL_PROBE = """
import torch
a = torch.randn(1024, 1024)
a @ a
a.bfloat16() @ a.bfloat16()
x = torch.randn(8, 3, 72, 72)
conv = torch.nn.Conv2d(3, 16, 3, padding=1)
conv(x)
conv.bfloat16()(x.bfloat16())
with torch.autocast("cpu", dtype=torch.bfloat16):
    torch.nn.Linear(128, 512)(torch.randn(512, 128))
"""


def cpu_state() -> dict:
    """The CPU and torch's oneDNN state: what decides whether bf16 runs on AMX."""
    info = Path("/proc/cpuinfo").read_text() if Path("/proc/cpuinfo").exists() else ""
    model = re.search(r"model name\s*:\s*(.*)", info)
    flags = set(re.search(r"flags\s*:\s*(.*)", info).group(1).split()) if "flags" in info else set()
    onednn = [line.strip(" -") for line in torch.__config__.show().splitlines() if "DNN" in line]
    return {
        "model": model.group(1) if model else None, "cpus": os.cpu_count(),
        "flags": {flag: flag in flags for flag in CPU_FLAGS},
        "torch": torch.__version__, "threads": torch.get_num_threads(),
        "cpu_capability": torch.backends.cpu.get_cpu_capability(),
        "mkldnn_available": torch.backends.mkldnn.is_available(),
        "mkldnn_enabled": torch.backends.mkldnn.enabled, "onednn": onednn[0] if onednn else None,
        "onednn_max_cpu_isa": os.environ.get("ONEDNN_MAX_CPU_ISA"),
    }


def onednn_kernels() -> dict:
    """The oneDNN primitives torch runs for fp32/bf16 matmul, conv and an autocast Linear, as
    ``primitive: implementation`` (fp32 matmul goes to MKL and prints none)."""
    env = {**os.environ, "ONEDNN_VERBOSE": "1"}
    out = subprocess.run([sys.executable, "-c", KERNEL_PROBE], env=env, capture_output=True,
                         text=True, check=True).stdout
    kernels: list[str] = []
    for line in out.splitlines():
        fields = line.split(",")
        if "exec" in fields and fields[0].startswith(("onednn_verbose", "dnnl_verbose")):
            i = fields.index("exec")
            kernel = f"{fields[i + 2]}: {fields[i + 3]}"  # after exec: engine, primitive, impl
            if not fields[i + 2].startswith("reorder") and kernel not in kernels:
                kernels.append(kernel)
    return {"kernels": kernels, "amx_used": any("amx" in k for k in kernels)}


def best_seconds(run: Callable[[], object], repeats: int) -> float:
    """Fastest of ``repeats`` calls after one untimed call (the box may be shared)."""
    run()
    best = math.inf
    for _ in range(repeats):
        start = time.perf_counter()
        run()
        best = min(best, time.perf_counter() - start)
    return best


def matmul_gflops(n: int, dtype: torch.dtype, repeats: int) -> float:
    a, b = torch.randn(n, n).to(dtype), torch.randn(n, n).to(dtype)
    out = torch.empty(n, n, dtype=dtype)
    return 2 * n**3 / best_seconds(lambda: torch.matmul(a, b, out=out), repeats) / 1e9


def conv_gflops(batch: int, cin: int, cout: int, size: int, dtype: torch.dtype,
                repeats: int) -> float:
    """Forward GFLOP/s of a 3x3, padding-1 conv on (batch, cin, size, size)."""
    conv = nn.Conv2d(cin, cout, 3, padding=1).to(dtype)
    x = torch.randn(batch, cin, size, size).to(dtype)
    with torch.no_grad():
        seconds = best_seconds(lambda: conv(x), repeats)
    return 2 * batch * cout * size * size * cin * 9 / seconds / 1e9


def peaks(sizes: tuple[int, ...], repeats: int, convs: dict[str, tuple[int, int, int]],
          frames: int) -> dict:
    """Matmul and conv GFLOP/s in fp32 and bf16; ``convs``: name -> (cin, cout, size)."""
    dtypes = {"fp32": torch.float32, "bf16": torch.bfloat16}
    matmul = {name: {str(n): matmul_gflops(n, dtype, repeats) for n in sizes}
              for name, dtype in dtypes.items()}
    return {
        "cpu": cpu_state(), "onednn": onednn_kernels(), "matmul_gflops": matmul,
        "fp32_gflops": max(matmul["fp32"].values()), "bf16_gflops": max(matmul["bf16"].values()),
        "conv_batch": frames,
        "conv_gflops": {name: {d: conv_gflops(frames, *shape, dtype, repeats)
                               for d, dtype in dtypes.items()} | {"cin_cout_size": list(shape)}
                        for name, shape in convs.items()},
    }


def encoder_convs(model: nn.Module) -> dict[str, tuple[int, int, int]]:
    """The first conv of the IMPALA stack and a residual conv of its first stage."""
    stage = model.encoder.stages[0]
    size = model.config.frame_size // model.config.input_downsample
    first, res = stage.conv, stage.res0.conv0
    half = (size + 1) // 2  # after the stage's stride-2 max-pool
    return {"first": (first.in_channels, first.out_channels, size),
            "residual": (res.in_channels, res.out_channels, half)}


def build(section: dict, **overrides: object) -> object:
    """A config section's ``class_path`` built with its ``init_args`` and ``overrides``."""
    module, _, name = section["class_path"].rpartition(".")
    return getattr(importlib.import_module(module), name)(**{**section["init_args"], **overrides})


class PartTimer:
    """Marks the end of each part's forward and the arrival of its output's gradient."""

    def __init__(self, model: nn.Module) -> None:
        self.marks: dict[str, float] = {}
        self._handles = [getattr(model, part).register_forward_hook(partial(self._forward, part))
                         for part in PARTS]

    def _forward(self, part: str, module: nn.Module, args: tuple, output: object) -> None:
        self.marks[f"{part}_forward"] = time.perf_counter()
        out = output[0] if isinstance(output, tuple) else output
        if out.requires_grad:
            out.register_hook(partial(self._grad, part))

    def _grad(self, part: str, grad: torch.Tensor) -> None:
        self.marks[f"{part}_grad"] = time.perf_counter()

    def remove(self) -> None:
        for handle in self._handles:
            handle.remove()


class ModelOnly:
    """The recipe's optimizer step on one in-memory batch, as ``SequenceBC`` takes it per
    window (forward, loss, zero_grad, backward, clip, AdamW, LR schedule), timed by part."""

    def __init__(self, module: nn.Module, batch: dict[str, torch.Tensor], bf16: bool) -> None:
        self.module, self.batch, self.bf16 = module.train(), batch, bf16
        setup = module.configure_optimizers()
        self.optimizer = setup["optimizer"]
        self.scheduler = setup["lr_scheduler"]["scheduler"]
        self.params = [p for group in self.optimizer.param_groups for p in group["params"]]
        self.clip = module.hparams.max_grad_norm
        self.timer = PartTimer(module.model)

    def step(self) -> dict[str, float]:
        """One step; seconds per part (LABELS' keys) and ``total``."""
        marks, model, batch = self.timer.marks, self.module.model, self.batch
        marks.clear()
        start = time.perf_counter()
        with autocast("cpu", self.bf16):
            state = model.initial_state(batch["frames"].shape[0])
            logits, _ = model(batch["frames"], batch["first"], state)
            loss = self.module._loss(logits, batch["actions"])
        loss_end = time.perf_counter()
        self.optimizer.zero_grad(set_to_none=True)
        backward_start = time.perf_counter()
        loss.backward()
        backward_end = time.perf_counter()
        if self.clip is not None:
            torch.nn.utils.clip_grad_norm_(self.params, self.clip)
        clip_end = time.perf_counter()
        self.optimizer.step()
        self.scheduler.step()
        end = time.perf_counter()
        forward = [start, *(marks[f"{p}_forward"] for p in PARTS), loss_end]
        backward = [backward_start, *(marks[f"{p}_grad"] for p in reversed(PARTS)), backward_end]
        parts = {f"{p}_forward": b - a for p, a, b in zip(PARTS, forward, forward[1:])}
        parts["loss_forward"] = loss_end - forward[-2]
        parts["zero_grad"] = backward_start - loss_end
        parts["loss_backward"] = backward[1] - backward[0]
        for p, a, b in zip(reversed(PARTS), backward[1:], backward[2:]):
            parts[f"{p}_backward"] = b - a
        parts.update(clip=clip_end - backward_end, adamw_step=end - clip_end, total=end - start)
        return parts

    def run(self, steps: int, warmup: int) -> dict:
        """Mean seconds per part over ``steps`` steps after ``warmup`` untimed ones."""
        for _ in range(warmup):
            self.step()
        records = [self.step() for _ in range(steps)]
        parts = {key: mean(r[key] for r in records) for key in records[0]}
        frames = self.batch["actions"].numel()
        return {"steps": steps, "warmup": warmup, "s_per_step": parts["total"],
                "frames_per_s": frames / parts["total"], "parts_s": parts}


def top_ops(step: Callable[[], object], steps: int, k: int) -> list[dict]:
    """torch.profiler's ``k`` operators of most self CPU time over ``steps`` calls."""
    from torch.profiler import ProfilerActivity, profile

    with profile(activities=[ProfilerActivity.CPU]) as prof:
        for _ in range(steps):
            step()
    events = sorted(prof.key_averages(), key=lambda e: e.self_cpu_time_total, reverse=True)
    total = sum(e.self_cpu_time_total for e in events)
    return [{"op": e.key, "self_ms_per_step": e.self_cpu_time_total / 1e3 / steps,
             "calls_per_step": e.count / steps, "share": e.self_cpu_time_total / total}
            for e in events[:k]]


def flops_per_frame(module: nn.Module, batch: dict[str, torch.Tensor], bf16: bool) -> dict:
    """Forward + backward FLOPs per frame: in total by ``measure.count`` (as `zoo scale`
    counts), per part by the same counter's module breakdown; on the batch's first sequence."""
    model = module.model
    one = {k: v[:1] for k, v in batch.items()}
    frames = one["actions"].numel()

    def loss() -> torch.Tensor:
        logits, _ = model(one["frames"], one["first"], model.initial_state(1))
        return module._loss(logits, one["actions"])

    total, _ = count(loss, [*model.parameters(), *model.buffers()], bf16, flops=True)
    counter = FlopCounterMode(display=False, custom_mapping=CPU_ATTENTION)
    with counter:
        with autocast("cpu", bf16):
            value = loss()
        value.backward()
    model.zero_grad(set_to_none=True)
    counts, root = counter.get_flop_counts(), type(model).__name__
    parts = {p: sum(counts.get(f"{root}.{p}", {}).values()) / frames for p in PARTS}
    return {"total": total / frames, "parts": parts, "counted_frames": frames}


def _share(value: float | None, whole: float | None) -> float | None:
    return None if value is None or not whole else value / whole


def profile_rows(parts_s: dict[str, float], end_to_end: dict | None) -> list[dict]:
    """ms per step and share of one step at the recipe's cadence: the model-only parts, then
    what `zoo fit` adds (data wait, Lightning's batch and loop, epoch boundaries); without an
    end-to-end run the model-only total is the whole."""
    rows = [(LABELS[key], parts_s[key]) for key in LABELS]
    total = parts_s["total"]
    if end_to_end:
        e2e = end_to_end
        rows += [
            ("data loader wait", e2e["data_wait_s_per_step"]),
            ("training_step beyond model-only (metrics, logging, contention)",
             e2e["training_batch_s_per_step"] - total),
            ("Lightning loop between batches (hooks, logger, progress bar)",
             e2e["loop_between_batches_s_per_step"]),
            (f"epoch boundary (validation, checkpoints) / {e2e['recipe_epoch_steps']} steps",
             e2e["recipe_s_per_step"] - e2e["s_per_step"]),
        ]
        total = e2e["recipe_s_per_step"]
    return [{"part": name, "ms": 1e3 * s, "share": s / total} for name, s in rows]


def flops_summary(counted: dict, model_only: dict, end_to_end: dict | None, peak: dict) -> dict:
    """GFLOP/s each setting (and each model part, fwd + bwd) reaches, against the peaks."""
    per_frame = counted["total"]
    settings = {"model_only": model_only["frames_per_s"]}
    if end_to_end:
        settings |= {"zoo_fit_steady": end_to_end["frames_per_s"],
                     "zoo_fit_recipe_cadence": end_to_end["recipe_frames_per_s"]}
    achieved = {}
    for name, frames_per_s in settings.items():
        gflops = per_frame * frames_per_s / 1e9
        achieved[name] = {"gflops": gflops, "of_bf16_peak": _share(gflops, peak["bf16_gflops"]),
                          "of_fp32_peak": _share(gflops, peak["fp32_gflops"])}
    frames, parts_s = model_only["frames_per_s"] * model_only["s_per_step"], model_only["parts_s"]
    parts = {}
    for p in PARTS:
        seconds = parts_s[f"{p}_forward"] + parts_s[f"{p}_backward"]
        gflops = counted["parts"][p] * frames / seconds / 1e9
        parts[p] = {"flops_per_frame": counted["parts"][p], "fwd_bwd_ms": 1e3 * seconds,
                    "gflops": gflops, "of_bf16_peak": _share(gflops, peak["bf16_gflops"])}
    return {"per_frame": per_frame, "per_step": per_frame * frames,
            "counter": "lit_models.scale.measure.count (forward + backward)",
            "achieved": achieved, "parts": parts}


def table(results: dict) -> str:
    """A short human summary of the new keys."""
    peak, e2e, flops = results["peaks"], results.get("end_to_end"), results["flops"]
    profile = results["profile"]
    convs = ", ".join(f"{n} {c['fp32']:.0f}/{c['bf16']:.0f}"
                      for n, c in peak["conv_gflops"].items())
    lines = [
        f"CPU {peak['cpu']['model']} ({peak['cpu']['threads']} threads); oneDNN: "
        + "; ".join(peak["onednn"]["kernels"]),
        f"peak GFLOP/s  matmul fp32 {peak['fp32_gflops']:.0f}  bf16 {peak['bf16_gflops']:.0f}"
        f"  | conv fp32/bf16: {convs}",
        f"frames/s  model-only {profile['model_only']['frames_per_s']:.0f}"
        f" (1 thread: {profile['model_only_1_thread']['frames_per_s']:.0f})",
    ]
    if e2e:
        lines[-1] += (f"  zoo fit steady {e2e['frames_per_s']:.0f}  at the recipe's cadence "
                      f"{e2e['recipe_frames_per_s']:.0f}  (ratio {e2e['ratio_to_model_only']:.2f})")
    lines.append(f"{'part':<66}{'ms/step':>9}{'share':>8}")
    lines += [f"{r['part']:<66}{r['ms']:>9.1f}{r['share']:>8.1%}" for r in profile["rows"]]
    achieved = [f"{name} {a['gflops']:.0f} GFLOP/s = {a['of_bf16_peak']:.0%} of bf16 peak"
                for name, a in flops["achieved"].items()]
    lines.append(f"FLOPs/frame {flops['per_frame'] / 1e6:.0f} M (fwd+bwd); " + "; ".join(achieved))
    parts = [f"{p} {v['gflops']:.0f} GFLOP/s ({v['of_bf16_peak']:.0%})"
             for p, v in flops["parts"].items()]
    lines.append("per part (fwd+bwd): " + "; ".join(parts))
    return "\n".join(lines)


__all__ = ["ModelOnly", "PartTimer", "build", "encoder_convs", "flops_per_frame", "flops_summary",
           "onednn_kernels", "peaks", "profile_rows", "table", "top_ops"]
