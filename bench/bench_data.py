"""CrafterPlay writer speed and size -> bench/results/data.json.

For each expert, on one env batch built once (so JAX compiles once):
(a) raw: env step + render + agent act, frames/s, playing the same episodes without writing;
(b) generation through the writer (`zoo.data.generate`), frames/s, and the ratio b/a;
(c) stored bytes per frame (frame members only, and whole shards) against raw 62,208 B;
(d) decode: frames/s of `iter_chunks` (frames + states + steps decoded).
Raw and generation runs alternate (twice each, best kept) because the box is shared.

    python bench/bench_data.py                       # scripted (if present) and random, Craftax
    python bench/bench_data.py --experts random --env crafter --episodes 4 --max-steps 200
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import platform
import tempfile
import time
from pathlib import Path

import numpy as np

from zoo.agents import dataset_agent
from zoo.data.generate import GenerationConfig, ShardGenerator, generate
from zoo.data.info import RAW_FRAME_BYTES, dataset_info
from zoo.data.reader import iter_chunks, list_shards
from zoo.envs.base import episode_seed

RESULTS = Path(__file__).parent / "results" / "data.json"


def raw_env(gen: ShardGenerator):
    """An env of ``gen``'s game that draws every frame, for raw play (env + frames + agent).
    ``gen.env`` itself draws none where a state-only expert plays Craftax: generation then
    draws the frames from the states on its encoder thread."""
    if gen.pixels:
        return gen.env
    from zoo.envs import make_env
    from zoo.envs.tasks.starts import TaskStartEnv

    cfg = gen.config
    env = make_env(cfg.env, gen.num_envs, pixels=True, max_steps=cfg.max_steps)
    return TaskStartEnv(env) if cfg.start_states == "tasks" else env


def play_without_writing(gen: ShardGenerator, env=None) -> int:
    """Play every episode of the dataset as `generate` schedules them, in ``env`` (default
    ``gen.env``; ``raw_env(gen)`` for raw play); return frames seen."""
    cfg, n = gen.config, gen.num_envs
    env = gen.env if env is None else env
    frames = 0
    for index in range(cfg.num_shards):
        pending = iter(cfg.shard_episodes(index))
        active = np.zeros(n, bool)
        seeds = np.zeros(n, np.int64)
        for slot in range(n):
            episode = next(pending, None)
            if episode is not None:
                active[slot], seeds[slot] = True, episode_seed(cfg.seed, episode)
        step = env.reset(seeds)
        gen.agent.reset(seeds)
        frames += int(active.sum())
        while active.any():
            step = env.step(np.asarray(gen.agent.act(step)))
            frames += int(active.sum())
            restart = np.zeros(n, bool)
            for slot in np.flatnonzero(active & step.done):
                episode = next(pending, None)
                if episode is None:
                    active[slot] = False
                else:
                    restart[slot], seeds[slot] = True, episode_seed(cfg.seed, episode)
            if restart.any():
                step = env.reset(seeds, mask=restart)
                gen.agent.reset(seeds, mask=restart)
                frames += int(restart.sum())
    return frames


def bench_expert(expert: str, args, workdir: Path) -> dict:
    config = GenerationConfig(
        expert=expert, episodes=args.episodes, seed=args.seed, env=args.env,
        episodes_per_shard=args.episodes, chunk_length=args.chunk_length, max_steps=args.max_steps,
    )
    gen = ShardGenerator(config, args.num_envs, dataset_agent)
    raw = raw_env(gen)
    for env in [gen.env] if raw is gen.env else [gen.env, raw]:  # compile, warm the agent
        step = env.reset(np.arange(gen.num_envs) + 10**6)
        gen.agent.reset(np.arange(gen.num_envs) + 10**6)
        for _ in range(20):
            step = env.step(np.asarray(gen.agent.act(step)))
    raw_fps, gen_fps, out = [], [], None
    for attempt in range(args.repeats):
        t = time.perf_counter()
        frames = play_without_writing(gen, raw)
        raw_fps.append(frames / (time.perf_counter() - t))
        out = workdir / f"{expert}-{attempt}"
        t = time.perf_counter()
        manifest = generate(config, out, progress=False, generator=gen)
        seconds = time.perf_counter() - t
        written = sum(e["steps"] for e in manifest["shards"])
        if written != frames:
            raise RuntimeError(f"generation wrote {written} frames, the raw run played {frames}")
        gen_fps.append(written / seconds)
    info = dataset_info(out)
    t = time.perf_counter()
    decoded = sum(len(c["frames"]) for c in iter_chunks(list_shards(out)))
    decode_fps = decoded / (time.perf_counter() - t)
    return {
        "expert": expert,
        "frames": info["frames"],
        "episodes": info["episodes"],
        "raw_fps": max(raw_fps),
        "generate_fps": max(gen_fps),
        "generate_over_raw": max(gen_fps) / max(raw_fps),
        "raw_fps_runs": raw_fps,
        "generate_fps_runs": gen_fps,
        "frame_bytes_per_frame": info["frame_bytes_per_frame"],
        "frame_compression_ratio": info["compression_ratio_frames"],
        "shard_bytes_per_frame": info["bytes_per_frame"],
        "shard_compression_ratio": RAW_FRAME_BYTES / info["bytes_per_frame"],
        "decode_fps": decode_fps,
        "noop_ratio_before": info["noop_ratio_before"],
        "noop_ratio_after": info["noop_ratio_after"],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    scripted = importlib.util.find_spec("zoo.experts.scripted") is not None
    parser.add_argument("--experts", default="scripted,random" if scripted else "random")
    parser.add_argument("--env", default="craftax", choices=("craftax", "crafter"))
    parser.add_argument("--num-envs", type=int, default=8)
    parser.add_argument("--episodes", type=int, default=8)
    parser.add_argument("--max-steps", type=int, default=300)
    parser.add_argument("--chunk-length", type=int, default=256)
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args()

    results = {
        "env": args.env, "num_envs": args.num_envs, "episodes": args.episodes,
        "max_steps": args.max_steps, "chunk_length": args.chunk_length,
        "raw_frame_bytes": RAW_FRAME_BYTES, "machine": platform.processor() or platform.machine(),
        "date": time.strftime("%Y-%m-%d %H:%M"), "experts": [],
    }
    with tempfile.TemporaryDirectory() as tmp:
        for expert in args.experts.split(","):
            row = bench_expert(expert, args, Path(tmp))
            results["experts"].append(row)
            print(json.dumps(row, indent=1))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(results, indent=1) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
