"""Which levers speed up the CPU recipe's training step: the ``levers`` key of
bench/results/cvpt.json (issue 49, item 1).

Each lever is one change to the recipe's model-only optimizer step (configs/cvpt_tiny_cpu.yaml:
batch 8 x 64 at 72 px, bf16 autocast, AdamW, clip 5) on one in-memory batch. The variants take
turns step by step (round robin), so load drifts on a shared machine hit all of them alike, and
each is reported as the ratio of its median step time to the recipe's:

- ``foreach_adamw`` / ``fused_adamw``: AdamW's multi-tensor and fused CPU kernels (the default
  on CPU is one small update per parameter);
- ``channels_last``: frames fed to the convs as NHWC views (no NCHW copy) with channels-last
  conv weights, oneDNN's preferred layout;
- ``pre_downsampled``: frames stored at 72 px (the rounded 2x2 mean, ``zoo.gym.batch.downsample``)
  so the encoder skips the 144-px pool; same parameter shapes, slightly different input;
- ``tile_encoder`` / ``tile_encoder_64ch``: the ``encoder: tiles`` option (zoo/models/tiles.py,
  one token per 16-px tile of the 144-px frame, 32 or 64 channels) in place of IMPALA: another
  model, so its speed alone does not make it better (docs/results/cvpt.md scores it);
- ``one_thread``: ``torch.set_num_threads(1)``, the step's cost of sharing cores;
- ``shape_16x32`` / ``shape_4x128``: batch x sequence at equal frames per step;
- ``compile`` (with ``--compile``): ``torch.compile`` (inductor) of the model.

Variants that compute the same function (all but the shapes, ``pre_downsampled`` and the tile encoders) are
checked to give the recipe's logits before they are timed.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from statistics import median

import torch
from torch import nn

from lit_models.scale.measure import autocast
from zoo.gym.batch import downsample

Step = Callable[[], None]


def lever_optimizer(module: nn.Module, **adamw: object) -> tuple[torch.optim.Optimizer, object]:
    """The module's own AdamW groups, hyperparameters and schedule, with ``adamw`` options
    (``foreach``, ``fused``) added. The groups are rebuilt from their params and weight decay
    alone: a built group carries every default (``foreach: None`` too), which would override
    the options given here."""
    setup = module.configure_optimizers()
    optimizer, scheduler = setup["optimizer"], setup["lr_scheduler"]["scheduler"]
    if adamw:
        groups = [{"params": g["params"], "weight_decay": g["weight_decay"]}
                  for g in optimizer.param_groups]
        defaults = {k: optimizer.defaults[k] for k in ("lr", "betas", "eps")}
        optimizer = torch.optim.AdamW(groups, **defaults, **adamw)
        scheduler = torch.optim.lr_scheduler.LambdaLR(optimizer, scheduler.lr_lambdas[0])
    return optimizer, scheduler


def channels_last_logits(model: nn.Module, frames: torch.Tensor, first: torch.Tensor,
                         state: object) -> torch.Tensor:
    """``model``'s logits with the frames handed to the encoder as an NHWC view (no copy)."""
    b, t, s = frames.shape[:3]
    x = model.encoder(frames.reshape(b * t, s, s, 3).permute(0, 3, 1, 2)).view(b, t, -1)
    hidden, _ = model.trxl(x, first.bool(), state)
    return model.policy_head(hidden)


def small_frame_logits(model: nn.Module, frames: torch.Tensor, first: torch.Tensor,
                       state: object) -> torch.Tensor:
    """Logits of a 72-px model (built for 144 px pooled by 2, its pool switched off) on frames
    stored at 72 px: the encoder's parameter shapes are the recipe's."""
    b, t, s = frames.shape[:3]
    x = model.encoder(frames.permute(0, 1, 4, 2, 3).reshape(b * t, 3, s, s)).view(b, t, -1)
    hidden, _ = model.trxl(x, first.bool(), state)
    return model.policy_head(hidden)


def _plain_logits(model: nn.Module, frames: torch.Tensor, first: torch.Tensor,
                  state: object) -> torch.Tensor:
    return model(frames, first, state)[0]


def make_step(module: nn.Module, batch: dict[str, torch.Tensor], bf16: bool,
              logits_fn: Callable = _plain_logits, **adamw: object) -> Step:
    """One optimizer step as ``SequenceBC`` takes it per window, on ``batch``."""
    optimizer, scheduler = lever_optimizer(module, **adamw)
    params = [p for group in optimizer.param_groups for p in group["params"]]
    clip = module.hparams.max_grad_norm
    model = module.model

    def step() -> None:
        with autocast("cpu", bf16):
            state = model.initial_state(batch["frames"].shape[0])
            logits = logits_fn(model, batch["frames"], batch["first"], state)
            loss = module._loss(logits, batch["actions"])
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        if clip is not None:
            torch.nn.utils.clip_grad_norm_(params, clip)
        optimizer.step()
        scheduler.step()

    return step


def reshaped(batch: dict[str, torch.Tensor], seq_len: int) -> dict[str, torch.Tensor]:
    """The batch as sequences of ``seq_len`` (equal frames per step; a cut sequence's second
    half starts mid-episode, which costs the same)."""
    return {k: v.reshape(-1, seq_len, *v.shape[2:]) for k, v in batch.items()}


def pooled(batch: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """The batch with frames stored at half size (uint8 rounded 2x2 mean)."""
    frames = batch["frames"]
    b, t = frames.shape[:2]
    small = downsample(frames.reshape(b * t, *frames.shape[2:]).numpy())
    return {**batch, "frames": torch.from_numpy(small).view(b, t, *small.shape[1:])}


def _same_logits(module: nn.Module, batch: dict, logits_fn: Callable) -> bool:
    model = module.model
    with torch.no_grad():
        state = model.initial_state(batch["frames"].shape[0])
        want = _plain_logits(model, batch["frames"], batch["first"], state)
        got = logits_fn(model, batch["frames"], batch["first"], state)
    return bool(torch.allclose(want, got, atol=1e-4, rtol=1e-4))


def levers(build: Callable[..., nn.Module], batch: dict[str, torch.Tensor], bf16: bool,
           steps: int, warmup: int, compile_model: bool = False) -> dict:
    """Median seconds per step of the recipe and each lever, taking turns; ratios to the
    recipe. ``build(**overrides)`` makes a fresh module from the recipe's model section."""
    threads = torch.get_num_threads()
    variants: dict[str, tuple[Step, int]] = {}  # name -> (step, threads)
    variants["recipe"] = (make_step(build(), batch, bf16), threads)
    variants["foreach_adamw"] = (make_step(build(), batch, bf16, foreach=True), threads)
    variants["fused_adamw"] = (make_step(build(), batch, bf16, fused=True), threads)
    last = build()
    last.model.to(memory_format=torch.channels_last)
    if not _same_logits(last, batch, channels_last_logits):
        raise RuntimeError("channels_last changed the logits: the lever is not the same model")
    variants["channels_last"] = (make_step(last, batch, bf16, channels_last_logits), threads)
    small = build()
    small.model.encoder.downsample = 1
    variants["pre_downsampled"] = (make_step(small, pooled(batch), bf16, small_frame_logits),
                                   threads)
    for name, channels in (("tile_encoder", 32), ("tile_encoder_64ch", 64)):  # 144 px, no pool
        tiles = build(encoder="tiles", tile_channels=channels, input_downsample=1)
        variants[name] = (make_step(tiles, batch, bf16), threads)
    variants["one_thread"] = (make_step(build(), batch, bf16), 1)
    frames = batch["actions"].numel()
    for b, t in ((16, 32), (4, 128)):  # the recipe's 64-step memory, one window per sequence
        variants[f"shape_{b}x{t}"] = (make_step(build(), reshaped(batch, t), bf16), threads)
    if compile_model:
        fast = build()
        fast.model = torch.compile(fast.model)
        variants["compile"] = (make_step(fast, batch, bf16), threads)

    times: dict[str, list[float]] = {name: [] for name in variants}
    for i in range(warmup + steps):
        for name, (step, n) in variants.items():
            torch.set_num_threads(n)
            start = time.perf_counter()
            step()
            if i >= warmup:
                times[name].append(time.perf_counter() - start)
    torch.set_num_threads(threads)
    base = median(times["recipe"])
    return {
        "method": "model-only steps on one in-memory batch, variants in turn, median of "
                  f"{steps} after {warmup} warm-up each; speedup = recipe s / variant s",
        "frames_per_step": frames,
        "threads": threads,
        "variants": {
            name: {"s_per_step": median(t), "frames_per_s": frames / median(t),
                   "speedup": base / median(t)}
            for name, t in times.items()
        },
    }
