"""CrafterPlay frame modes, stored vs rendered, in one run -> bench/results/frames.json.

Scripted-expert Craftax play; per mode (`zoo data generate --frames stored|rendered`):
bytes per frame (frame members: images, or residual + state_rng) against raw 62,208 B;
decode frames/s of `iter_chunks` (a rendered chunk re-renders its states on the CPU);
generation frames/s over the raw play rate (env + render + agent without writing, as in
bench_data.py). Raw and the two generations alternate (``--repeats`` times, best kept)
because the box is shared. Decoded frames of the two modes are checked equal.
It also times the tiny 72-px bf16 training step here, the rate decoding must keep up with.
With the state-only scripted expert the rendered mode's env draws no frames: the re-render
that codes a chunk draws them, once.

    python bench/bench_frames.py           # 8 episodes of <= 300 steps (~2,400 frames)
    python bench/bench_frames.py --tiny    # 2 episodes of <= 30 steps: does it run?
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import platform
import tempfile
import time
from pathlib import Path

import numpy as np
from bench_data import play_without_writing, raw_env

from zoo.agents import dataset_agent
from zoo.data.generate import GenerationConfig, ShardGenerator, generate
from zoo.data.info import RAW_FRAME_BYTES, dataset_info
from zoo.data.reader import iter_chunks, list_shards
from zoo.data.rerender import render_frames, renderer_version
from zoo.envs.schema import empty_state

RESULTS = Path(__file__).parent / "results"
MODES = ("stored", "rendered")


def warm_up(gen: ShardGenerator, *envs) -> None:
    """Compile reset/step of ``gen``'s env and ``envs`` (e.g. ``raw_env(gen)``) and the
    re-render, so no timed run pays for compiling."""
    seeds = np.arange(gen.num_envs) + 10**6
    for env in (gen.env, *envs):
        step = env.reset(seeds)
        gen.agent.reset(seeds)
        for _ in range(20):
            step = env.step(np.asarray(gen.agent.act(step)))
    if not gen.pixels:  # frames drawn from the states: stored and rendered modes
        render_frames(empty_state(1), np.zeros((1, 2), np.uint32))


def decode_fps(root: Path) -> float:
    start, frames = time.perf_counter(), 0
    for chunk in iter_chunks(list_shards(root)):
        frames += len(chunk["frames"])
    return frames / (time.perf_counter() - start)


def same_frames(a: Path, b: Path) -> bool:
    chunks = zip(iter_chunks(list_shards(a)), iter_chunks(list_shards(b)), strict=True)
    return all(np.array_equal(x["frames"], y["frames"]) for x, y in chunks)


def training_frames_per_s(steps: int) -> float:
    """Frames/s of the tiny 72-px bf16 training step (configs/cvpt_tiny_cpu.yaml: batch 8 x 64)
    on this machine, now: what a decoder must keep up with."""
    from bench_cvpt import bf16_vs_fp32

    step = bf16_vs_fp32(batch_size=8, seq_len=64, steps=steps, input_downsample=2)
    return 8 * 64 / step["bf16_s_per_step"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=8)
    parser.add_argument("--max-steps", type=int, default=300)
    parser.add_argument("--chunk-length", type=int, default=256)
    parser.add_argument("--num-envs", type=int, default=8)
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--tiny", action="store_true",
                        help="2 episodes of <= 30 steps, 16-step chunks, one repeat (a smoke run)")
    parser.add_argument("--out", type=Path, default=RESULTS / "frames.json")
    args = parser.parse_args()
    if args.tiny:
        args.episodes, args.max_steps, args.chunk_length, args.repeats = 2, 30, 16, 1

    stored = GenerationConfig(
        expert="scripted", episodes=args.episodes, seed=args.seed, env="craftax",
        episodes_per_shard=args.episodes, chunk_length=args.chunk_length,
        max_steps=args.max_steps,
    )
    configs = {"stored": stored, "rendered": dataclasses.replace(stored, frames="rendered")}
    gens = {mode: ShardGenerator(cfg, args.num_envs, dataset_agent) for mode, cfg in configs.items()}
    raw = raw_env(gens["stored"])  # raw play draws every frame
    warm_up(gens["stored"], raw)
    warm_up(gens["rendered"])

    raw_fps: list[float] = []
    gen_fps: dict[str, list[float]] = {mode: [] for mode in MODES}
    rows = {}
    with tempfile.TemporaryDirectory() as tmp:
        outs = {}
        for attempt in range(args.repeats):
            start = time.perf_counter()
            frames = play_without_writing(gens["stored"], raw)
            raw_fps.append(frames / (time.perf_counter() - start))
            for mode in MODES:
                outs[mode] = Path(tmp) / f"{mode}-{attempt}"
                start = time.perf_counter()
                manifest = generate(configs[mode], outs[mode], progress=False, generator=gens[mode])
                seconds = time.perf_counter() - start
                written = sum(e["steps"] for e in manifest["shards"])
                if written != frames:
                    raise RuntimeError(f"{mode}: wrote {written} frames, raw play saw {frames}")
                gen_fps[mode].append(written / seconds)
        if not same_frames(outs["stored"], outs["rendered"]):
            raise RuntimeError("rendered frames decode differently from stored ones")
        for mode in MODES:
            info = dataset_info(outs[mode])
            rows[mode] = {
                "frame_bytes_per_frame": info["frame_bytes_per_frame"],
                "frame_bytes_fraction_of_raw": info["frame_bytes_per_frame"] / RAW_FRAME_BYTES,
                "shard_bytes_per_frame": info["bytes_per_frame"],
                "decode_fps": decode_fps(outs[mode]),
                "generate_fps": max(gen_fps[mode]),
                "generate_over_raw": max(gen_fps[mode]) / max(raw_fps),
                "generate_fps_runs": gen_fps[mode],
            }

    results = {
        "expert": "scripted", "env": "craftax", "frames": frames, "episodes": args.episodes,
        "max_steps": args.max_steps, "chunk_length": args.chunk_length,
        "num_envs": args.num_envs, "raw_frame_bytes": RAW_FRAME_BYTES,
        "raw_fps": max(raw_fps), "raw_fps_runs": raw_fps, "modes": rows,
        "renderer": renderer_version(),
        "training_tiny_72px_bf16_frames_per_s": training_frames_per_s(1 if args.tiny else 3),
        "machine": platform.processor() or platform.machine(),
        "date": time.strftime("%Y-%m-%d %H:%M"),
    }
    print(json.dumps(results, indent=1))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(results, indent=1) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
