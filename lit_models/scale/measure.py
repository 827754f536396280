"""Measured on this machine, for one stage: FLOPs, activations saved for backward, CPU step time.

FLOPs are ``torch.utils.flop_counter.FlopCounterMode`` over a real forward and backward of the
module's loss (matmuls, convolutions and attention; elementwise ops are not counted, the usual
MFU convention). torch's counter knows the CUDA attention kernels but not the CPU one that
``F.scaled_dot_product_attention`` runs here (it would count 0), so ``CPU_ATTENTION`` counts it
as the math path is counted (taken when the mask needs a gradient, as C-VPT's learned bias does):
forward 2 matmuls (QK^T, AV) over every attended key, memory included, backward 4 (the grads of
the scores, V, Q and K): 3x forward, as for a linear layer. The flash kernel also recomputes QK^T
in backward, work the MFU convention (model FLOPs) leaves out. Activation bytes are the
distinct storages autograd saves for backward (``saved_tensors_hooks``), parameters and buffers
excluded, measured in the config's precision (CPU bf16 autocast for ``bf16-mixed``) at two batch
sizes so a fixed part (autocast's bf16 weight copies) and a per-sample part can be told apart.
The CPU step is timed in fp32 against the fp32 matmul peak measured right after it: the fraction
it reaches checks the FLOP model.
"""

from __future__ import annotations

import contextlib
import math
import time
from collections.abc import Callable, Iterable
from dataclasses import asdict, dataclass, field
from functools import partial

import torch
from torch.autograd.graph import saved_tensors_hooks
from torch.utils.flop_counter import FlopCounterMode, sdpa_flop_count

from lit_models.scale import modules
from lit_models.scale.stages import Stage

TIMED_FLOPS = 1e9  # the CPU step is timed at a batch of at least this many FLOPs
MIN_TIMED_S = 2.0  # cheap steps are repeated until this much has been timed
Shape = tuple[int, ...]


def _attention_flops(query: Shape, key: Shape, value: Shape, *_, **__) -> int:
    """Forward FLOPs of the CPU flash attention op (FlopCounterMode passes shapes)."""
    return sdpa_flop_count(query, key, value)


def _attention_backward_flops(grad: Shape, query: Shape, key: Shape, value: Shape, *_, **__) -> int:
    """Backward FLOPs of the CPU flash attention op: twice its forward, QK^T's recompute apart."""
    return 2 * sdpa_flop_count(query, key, value)


CPU_ATTENTION = {
    torch.ops.aten._scaled_dot_product_flash_attention_for_cpu: _attention_flops,
    torch.ops.aten._scaled_dot_product_flash_attention_for_cpu_backward: _attention_backward_flops,
}


@dataclass
class Measurement:
    """What ``zoo scale`` measured for one stage: measurements on this machine, except
    ``memory_batch`` (the config's) and ``extra_*`` (counted from shapes)."""

    params_trainable: int
    params_frozen: int
    flops_per_unit: float  # forward + backward FLOPs per unit (frame, clip, pair, env step)
    flops_batch: int  # samples in the counted pass (the count is scaled linearly from it)
    activation_bytes: dict[int, float]  # samples per device -> bytes saved for backward
    memory_batch: int  # samples per device the activations are extrapolated to
    extra_bytes_per_sample: float  # device bytes that grow with the batch besides activations
    extra_bytes_fixed: float  # device bytes that do not (PPO's rollout buffer and env states)
    cpu_step_s: float  # one optimizer step (forward, backward, clip, AdamW) on this CPU, fp32
    cpu_step_batch: int
    cpu_step_flops: float  # forward + backward FLOPs of that step
    cpu_peak_flops: float  # fp32 matmul FLOP/s measured right after it (the box is shared)
    notes: list[str] = field(default_factory=list)

    def to_dict(self) -> dict:
        return asdict(self)


class SavedTensors:
    """Bytes of the distinct storages autograd saves for backward inside the ``with`` block."""

    def __init__(self, exclude: Iterable[torch.Tensor]) -> None:
        self._skip = {t.untyped_storage().data_ptr() for t in exclude}
        self._sizes: dict[int, int] = {}
        self._hooks = saved_tensors_hooks(self._pack, lambda t: t)

    def _pack(self, tensor: torch.Tensor) -> torch.Tensor:
        storage = tensor.untyped_storage()
        if storage.data_ptr() not in self._skip:
            self._sizes[storage.data_ptr()] = storage.nbytes()
        return tensor

    def __enter__(self) -> SavedTensors:
        self._hooks.__enter__()
        return self

    def __exit__(self, *exc) -> None:
        self._hooks.__exit__(*exc)

    @property
    def bytes(self) -> int:
        return sum(self._sizes.values())


def autocast(device_type: str, mixed: bool) -> torch.autocast:
    """bf16 autocast for ``bf16-mixed`` configs (the only mixed precision the configs use)."""
    return torch.autocast(device_type, dtype=torch.bfloat16, enabled=mixed)


def train_step(
    stage: Stage, module: torch.nn.Module, optimizer: torch.optim.Optimizer, batch: dict,
    mixed: bool,
) -> torch.Tensor:
    """One optimizer step as training takes it: loss, backward, clip, AdamW."""
    with autocast(next(iter(batch.values())).device.type, mixed):
        value = modules.loss(stage, module, batch)
    optimizer.zero_grad(set_to_none=True)
    value.backward()
    if stage.grad_clip:
        torch.nn.utils.clip_grad_norm_(optimizer.param_groups[0]["params"], stage.grad_clip)
    optimizer.step()
    return value.detach()


def trainable_optimizer(module: torch.nn.Module) -> torch.optim.Optimizer:
    """AdamW over the trainable parameters: the cost of the module's own optimizer step (its
    parameter groups and schedule change the numbers, not the work)."""
    return torch.optim.AdamW([p for p in module.parameters() if p.requires_grad], lr=1e-5)


def cpu_peak_flops(size: int = 2048, repeats: int = 5) -> float:
    """Best fp32 matmul FLOP/s of ``repeats`` size x size products, with torch's threads."""
    a, b = torch.randn(size, size), torch.randn(size, size)
    a @ b
    best = math.inf
    for _ in range(repeats):
        start = time.perf_counter()
        a @ b
        best = min(best, time.perf_counter() - start)
    return 2 * size**3 / best


def count(
    run: Callable[[], torch.Tensor], exclude: Iterable[torch.Tensor], mixed: bool, flops: bool
) -> tuple[int, int]:
    """(forward + backward FLOPs, or 0 without ``flops``; bytes saved for backward) of the
    scalar ``run()`` returns, computed under CPU bf16 autocast when ``mixed``."""
    counter = FlopCounterMode(display=False, custom_mapping=CPU_ATTENTION) if flops else None
    with counter or contextlib.nullcontext(), SavedTensors(exclude) as saved:
        with autocast("cpu", mixed):
            value = run()
        if flops:
            value.backward()
    return (counter.get_total_flops() if counter else 0), saved.bytes


def count_stage(stage: Stage, module: torch.nn.Module, batch: dict, flops: bool) -> tuple[int, int]:
    """``count`` of the stage's training loss on ``batch``; gradients are dropped after."""
    exclude = [*module.parameters(), *module.buffers()]
    out = count(lambda: modules.loss(stage, module, batch), exclude, stage.mixed, flops)
    module.zero_grad(set_to_none=True)
    return out


def best_time(run: Callable[[], object], steps: int, warmup: int) -> float:
    """Fastest of at least ``steps`` timed calls after ``warmup`` untimed ones; cheap calls are
    repeated until MIN_TIMED_S have been timed (at most 10), as the machine may be shared."""
    for _ in range(warmup):
        run()
    times: list[float] = []
    while len(times) < steps or (sum(times) < MIN_TIMED_S and len(times) < 10):
        start = time.perf_counter()
        run()
        times.append(time.perf_counter() - start)
    return min(times)


def time_steps(
    stage: Stage, module: torch.nn.Module, batch: dict, steps: int, warmup: int
) -> float:
    """Seconds of one fp32 optimizer step (``best_time``)."""
    step = partial(train_step, stage, module, trainable_optimizer(module), batch, mixed=False)
    return best_time(step, steps, warmup)


def measure_torch_stage(
    stage: Stage, batches: tuple[int, int] = (1, 2), steps: int = 1, warmup: int = 1
) -> Measurement:
    """Count, measure and time one torch stage at the two small ``batches`` on the CPU."""
    torch.manual_seed(0)
    module = modules.build_module(stage)
    trainable = sum(p.numel() for p in module.parameters() if p.requires_grad)
    frozen = sum(p.numel() for p in module.parameters()) - trainable
    small, large = batches
    batch = modules.make_batch(stage, module, small, "cpu")
    flops, saved_small = count_stage(stage, module, batch, flops=True)
    bigger = modules.make_batch(stage, module, large, "cpu")
    _, saved_large = count_stage(stage, module, bigger, flops=False)
    del bigger
    # a step of >= ~1 GFLOP, so per-op overheads do not hide the arithmetic (the prior's MLP)
    timed = min(stage.per_device_batch, max(small, math.ceil(TIMED_FLOPS * small / flops)))
    if timed != small:
        batch = modules.make_batch(stage, module, timed, "cpu")
    seconds = time_steps(stage, module, batch, steps, warmup)
    notes = [f"FLOPs counted at batch {small} and scaled linearly"]
    if stage.mixed:
        notes.append("activations measured under CPU bf16 autocast (CUDA autocast's op lists "
                     "differ slightly)")  # fmt: skip
    return Measurement(
        params_trainable=trainable,
        params_frozen=frozen,
        flops_per_unit=flops / (small * stage.units_per_sample),
        flops_batch=small,
        activation_bytes={small: float(saved_small), large: float(saved_large)},
        memory_batch=stage.per_device_batch,
        extra_bytes_per_sample=float(modules.input_bytes_per_sample(stage, batch)),
        extra_bytes_fixed=0.0,
        cpu_step_s=seconds,
        cpu_step_batch=timed,
        cpu_step_flops=float(flops) * timed / small,
        cpu_peak_flops=cpu_peak_flops(),
        notes=notes,
    )


__all__ = [
    "CPU_ATTENTION", "Measurement", "SavedTensors", "autocast", "best_time", "count", "count_stage",
    "cpu_peak_flops", "measure_torch_stage", "time_steps", "train_step", "trainable_optimizer",
]  # fmt: skip
