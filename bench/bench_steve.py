"""C-Steve-1 speed on this machine (CPU) -> bench/results/steve.json.

Measures, in one run on the same batch of N envs (frames 144 px, C-VPT tiny at 72 px as in
configs/csteve1_cpu.yaml):
  * one acting step of C-VPT (``CVPTPolicy.act``) against C-Steve-1 with classifier-free
    guidance (``CSteve1Policy.act``, both passes in one forward) and C-Steve-1 without guidance
    (cfg_scale 0), for head conditioning (the paper's) and TrXL-input conditioning (whose two
    passes both run the Transformer-XL), and head conditioning over a C-VPT with VPT's hidden
    head layer (``head_hidden``; its C-VPT step is timed too); goal: guidance costs <= 1.3x a
    C-VPT step;
  * one C-Steve-1 training step (LoRA + conditioning, encoder frozen) against one C-VPT
    training step on the same batch.
Acting policies take turns step by step; each reports its fastest and median turn, and ratios
use the fastest (the step's own cost on a machine shared with other jobs).

  nice -n 10 .venv/bin/python bench/bench_steve.py
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import time
from pathlib import Path

import numpy as np
import torch

from zoo.agents.cvpt_agent import CVPTPolicy
from zoo.agents.csteve1_agent import CSteve1Policy
from zoo.envs.constants import NUM_ACTIONS
from zoo.models.cvpt import CVPTConfig, CVPTModel
from zoo.models.csteve1 import CSteve1Config, CSteve1Model

RESULTS = Path(__file__).parent / "results" / "steve.json"


def _median_seconds(fn, repeats: int, warmup: int = 3) -> float:
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


VPT_HEAD_HIDDEN = 256  # the VPT-head C-VPT of docs/results/cvpt.md


def _backbone(seed: int = 0, head_hidden: int = 0) -> CVPTModel:
    torch.manual_seed(seed)
    return CVPTModel(CVPTConfig.from_name("tiny", NUM_ACTIONS, input_downsample=2, head_hidden=head_hidden))


def acting(num_envs: int, repeats: int) -> dict:
    """Seconds per acting step for N envs; the policies take turns step by step, so a load
    change on a shared machine hits all of them alike (medians of ``repeats`` turns)."""
    rng = np.random.default_rng(0)
    frames = rng.integers(0, 256, (num_envs, 144, 144, 3), dtype=np.uint8)
    goals = torch.nn.functional.normalize(torch.randn(num_envs, 512), dim=-1)
    uniforms = rng.random(num_envs)
    steps, base_of = {}, {}  # base_of: the C-VPT step each C-Steve-1 step is compared with
    for name, head_hidden in (("cvpt", 0), ("cvpt_vpthead", VPT_HEAD_HIDDEN)):
        steps[name] = _stepper(
            CVPTPolicy(_backbone(head_hidden=head_hidden)),
            num_envs,
            lambda p, s: p.act(frames, s, uniforms=uniforms)[1],
        )
    variants = (("head", 0, "head", "cvpt"), ("trxl_input", 0, "trxl_input", "cvpt"),
                ("head", VPT_HEAD_HIDDEN, "head_vpthead", "cvpt_vpthead"))
    for conditioning, head_hidden, label, base in variants:
        for scale in (1.5, 0.0):
            base_of[f"steve_{label}_cfg{scale}"] = base
            steve = CSteve1Policy(
                CSteve1Model(
                    _backbone(head_hidden=head_hidden),
                    CSteve1Config(goal_dim=512, conditioning=conditioning),
                ),
                cfg_scale=scale,
            )
            steps[f"steve_{label}_cfg{scale}"] = _stepper(
                steve, num_envs, lambda p, s: p.act(frames, goals, s, uniforms=uniforms)[1]
            )
    times: dict[str, list[float]] = {name: [] for name in steps}
    for turn in range(repeats + 3):
        for name, step in steps.items():
            start = time.perf_counter()
            step()
            if turn >= 3:  # warm-up turns
                times[name].append(time.perf_counter() - start)
    # the fastest turn is the step's own cost; medians also carry the other jobs' load
    out = {f"{name}_min_s": min(t) for name, t in times.items()}
    out.update({f"{name}_median_s": statistics.median(t) for name, t in times.items()})
    for name, base in base_of.items():
        out[f"{name}_over_cvpt"] = out[f"{name}_min_s"] / out[f"{base}_min_s"]
    out["cvpt_vpthead_over_cvpt"] = out["cvpt_vpthead_min_s"] / out["cvpt_min_s"]
    return out


def _stepper(policy, num_envs: int, act):
    """A no-argument step of ``policy`` that carries its own TrXL state from call to call."""
    state = [policy.initial_state(num_envs)]

    def step() -> None:
        state[0] = act(policy, state[0])

    return step


def training(batch: int, seq_len: int, repeats: int) -> dict:
    """Seconds per forward + backward + AdamW step on one in-memory batch."""
    g = torch.Generator().manual_seed(0)
    frames = torch.randint(0, 256, (batch, seq_len, 144, 144, 3), dtype=torch.uint8, generator=g)
    first = torch.zeros(batch, seq_len, dtype=torch.bool)
    first[:, 0] = True
    actions = torch.randint(0, 17, (batch, seq_len), generator=g)
    goal = torch.randn(batch, seq_len, 512, generator=g)

    def step_fn(model, inputs, params):
        optimizer = torch.optim.AdamW(params, lr=1e-4)

        def step() -> None:
            with torch.autocast("cpu", dtype=torch.bfloat16):
                logits, _ = model(*inputs, model.initial_state(batch))
            loss = torch.nn.functional.cross_entropy(logits.flatten(0, 1).float(), actions.flatten())
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()

        return step

    cvpt = _backbone().train()
    steve = CSteve1Model(_backbone(), CSteve1Config(goal_dim=512)).train()
    cvpt_s = _median_seconds(step_fn(cvpt, (frames, first), cvpt.parameters()), repeats, 1)
    steve_s = _median_seconds(
        step_fn(steve, (frames, first, goal), steve.trainable_parameters().values()), repeats, 1
    )
    return {"batch": batch, "seq_len": seq_len, "cvpt_train_s": cvpt_s, "steve_train_s": steve_s,
            "steve_over_cvpt": steve_s / cvpt_s,
            "trainable_params": sum(p.numel() for p in steve.trainable_parameters().values()),
            "all_params": sum(p.numel() for p in steve.parameters())}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--num-envs", type=int, default=16)
    parser.add_argument("--repeats", type=int, default=30)
    parser.add_argument("--threads", type=int, default=1)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    with torch.no_grad():
        act = acting(args.num_envs, args.repeats)
    results = {
        "machine": {"cpu": platform.processor() or platform.machine(), "threads": args.threads},
        "acting": {"num_envs": args.num_envs, **act},
        "training": training(8, 64, max(3, args.repeats // 6)),
    }
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps(results, indent=2) + "\n")
    print(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()
