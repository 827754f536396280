"""Craftax frames on the CPU, the numba renderer vs Craftax's JAX one -> bench/results/render.json.

Issue 36's goals, each measured for both renderers (``ZOO_RENDERER``) in one run, so the
ratios compare like with like on this shared machine. Parts, each in a fresh process:
  renderer  frames per CPU-second (per core) of both renderers on the same batch of states
            from scripted and random play (their own mix of day, night and sleep), 16 frames
            a call as decoding renders them, checked equal byte for byte, best of 4
            interleaved timings. JAX's CPU time is its process's (all its threads), numba's
            its thread's (pinning both to one core instead lets JAX's idle workers spin
            beside numba and evict its cache). And the night static both ways: numba's
            threefry per frame vs one jitted JAX call for a batch.
  data      as bench_frames.py (scripted expert, 32 episodes of <= 300 steps): raw play
            frames/s (env + frames + agent, nothing written), generation frames/s in both
            frame modes and their ratio to raw play (the median over --repeats rounds of raw
            play then each mode, each round's ratio to its own raw play, and their range), decode frames/s of the rendered shards
            read by each renderer; then the residual rate of rendered shards when the env
            draws the frames (an agent that asks for pixels, as a C-VPT learner does).
  eval      wall time of ``zoo eval`` of the shipped C-VPT (weights/cvpt_tiny_cpu) over 100
            Craftax episodes, as issue 36 asks (--eval-episodes; ~15 min of CPU for both).
  rl        C-VPT-RL env steps/s and the env's share of its time (bench_rl.measure), one
            torch thread.

    python bench/bench_render.py                     # ~45 min on a loaded 2-core box (eval ~15)
    python bench/bench_render.py --parts renderer    # rerun one part, keep the others
    python bench/bench_render.py --tiny              # does it run?
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
RESULTS = Path(__file__).parent / "results" / "render.json"
RENDERERS = ("jax", "numba")
PARTS = ("renderer", "data", "eval", "rl")


def use(renderer: str) -> None:
    os.environ["ZOO_RENDERER"] = renderer  # read whenever an env or a re-render is made


def played_states(num_envs: int, steps: int, every: int) -> tuple[dict, np.ndarray]:
    """Exported states and state_rng of scripted and random Craftax play, every few steps."""
    from zoo.agents.base import RandomAgent
    from zoo.envs.craftax_env import CraftaxEnv
    from zoo.experts.scripted import ScriptedExpert

    env = CraftaxEnv(num_envs, pixels=False)
    states, rngs = [], []
    for agent, seed in ((ScriptedExpert(num_envs), 0), (RandomAgent(num_envs), 1)):
        seeds = np.arange(num_envs) + 1000 * seed
        step = env.reset(seeds)
        agent.reset(seeds)
        for t in range(steps):
            step = env.step(np.asarray(agent.act(step)))
            if t % every == 0:
                states.append({k: np.array(v) for k, v in step.state.items()})
                rngs.append(np.array(env.raw_state.state_rng))
    return {k: np.concatenate([s[k] for s in states]) for k in states[0]}, np.concatenate(rngs)


def frames_per_s(fn, n: int, clock=time.process_time, min_s: float = 1.0) -> float:
    """n / seconds per call of fn(), repeated for at least min_s of ``clock``: CPU time of
    the process (JAX works on its own threads) or of this thread (numba works on it alone:
    the process clock would also count JAX's idle workers spinning on the same core)."""
    fn()
    start, calls = clock(), 0
    while clock() - start < min_s:
        fn()
        calls += 1
    return n * calls / (clock() - start)


def best_rates(rates: dict, rounds: int = 4) -> dict:
    """{name: best frames/s} over rounds of ``rates`` ({name: no-argument rate function}) run
    in turns: on a shared machine the best of a few interleaved runs compares like with like."""
    best = dict.fromkeys(rates, 0.0)
    for _ in range(rounds):
        for name, rate in rates.items():
            best[name] = max(best[name], rate())
    return best


def part_renderer(args) -> dict:
    """Both renderers through ``zoo.data.rerender.render_frames``, RENDER_BATCH frames a call
    as decoding calls them (whole-batch calls would time page faults of a fresh output)."""
    import jax

    from zoo.data.rerender import RENDER_BATCH, render_frames
    from zoo.envs.render.noise import uniform

    state, rng = played_states(16, args.steps, args.every)
    n = len(rng)
    night = state["light_level"] < 0.5
    out = {"states": n, "night_share": float(night.mean()),
           "asleep_share": float(state["player_sleeping"].mean()),
           "rates": "frames per CPU-second: JAX process time, numba thread time",
           "frames_per_call": RENDER_BATCH}

    def blocks(keep: np.ndarray) -> list:
        index = np.flatnonzero(keep)
        return [({k: v[i] for k, v in state.items()}, rng[i])
                for i in np.split(index, range(RENDER_BATCH, len(index), RENDER_BATCH))]

    def rate(renderer: str, keep: np.ndarray) -> float:
        parts = blocks(keep)

        def render_all() -> None:  # each block's frames freed at once, as decoding does
            for s, r in parts:
                render_frames(s, r, renderer)

        clock = time.thread_time if renderer == "numba" else time.process_time
        return frames_per_s(render_all, int(keep.sum()), clock)

    every = np.ones(n, bool)
    frames = {r: np.concatenate([render_frames(s, k, r) for s, k in blocks(every)])
              for r in RENDERERS}
    out["identical_frames"] = bool(np.array_equal(frames["jax"], frames["numba"]))
    out.update(best_rates({
        "jax_frames_per_s": lambda: rate("jax", every),
        "numba_frames_per_s": lambda: rate("numba", every),
        "numba_day_frames_per_s": lambda: rate("numba", ~night),
        "numba_night_frames_per_s": lambda: rate("numba", night),
    }))
    out["numba_over_jax"] = out["numba_frames_per_s"] / out["jax_frames_per_s"]
    noise = np.empty(112 * 144, np.float32)
    out["static_numba_us_per_frame"] = 1e6 / frames_per_s(
        lambda: uniform(rng[0, 0], rng[0, 1], noise), 1, time.thread_time)
    draw = jax.jit(jax.vmap(lambda k: jax.random.uniform(k, (112, 144)) * 95 + 32))
    for batch in (RENDER_BATCH, 256):
        keys = np.resize(rng, (batch, 2))
        out[f"static_jax_batch{batch}_us_per_frame"] = 1e6 / frames_per_s(
            lambda k=keys: jax.device_get(draw(k)), batch)
    return out


def _nonzero_residual_frames(root: Path) -> tuple[int, int, float]:
    """(frames, frames whose residual is not all zero, residual bytes per frame) of shards."""
    import zstandard

    frames = nonzero = size = 0
    for shard in sorted(root.glob("*.tar")):
        with tarfile.open(shard) as tar:
            for member in tar.getmembers():
                if member.name.endswith(".residual.zst"):
                    data = tar.extractfile(member).read()
                    planes = np.frombuffer(zstandard.ZstdDecompressor().decompress(data), np.uint8)
                    planes = planes.reshape(3, -1, 144 * 144)
                    frames += planes.shape[1]
                    nonzero += int(planes.any(axis=(0, 2)).sum())
                    size += len(data)
    return frames, nonzero, size / max(frames, 1)


def part_data(args) -> dict:
    import dataclasses

    from bench_data import play_without_writing, raw_env
    from bench_frames import decode_fps, warm_up

    from zoo.agents import dataset_agent
    from zoo.agents.base import RandomAgent
    from zoo.data.generate import GenerationConfig, ShardGenerator, generate
    from zoo.data.info import RAW_FRAME_BYTES, dataset_info

    class PixelRandomAgent(RandomAgent):
        needs_pixels = True  # the env draws the frames, as for a C-VPT learner

    stored = GenerationConfig(
        expert="scripted", episodes=args.episodes, seed=0, env="craftax",
        episodes_per_shard=args.episodes, chunk_length=256, max_steps=args.max_steps,
    )
    configs = {"stored": stored, "rendered": dataclasses.replace(stored, frames="rendered")}
    pixel_config = dataclasses.replace(configs["rendered"], expert="random")
    out = {"expert": "scripted", "episodes": args.episodes, "max_steps": args.max_steps,
           "num_envs": 8, "raw_frame_bytes": RAW_FRAME_BYTES}
    with tempfile.TemporaryDirectory() as tmp:
        roots = {}
        for renderer in RENDERERS:
            use(renderer)
            gens = {m: ShardGenerator(c, 8, dataset_agent) for m, c in configs.items()}
            raw = raw_env(gens["stored"])  # raw play draws every frame with this renderer
            warm_up(gens["stored"], raw)
            warm_up(gens["rendered"])
            rounds: dict[str, list[float]] = {"raw": [], **{mode: [] for mode in configs}}
            for attempt in range(args.repeats):  # raw play and each mode in turns
                start = time.perf_counter()
                frames = play_without_writing(gens["stored"], raw)
                rounds["raw"].append(frames / (time.perf_counter() - start))
                for mode, config in configs.items():
                    root = Path(tmp) / f"{renderer}-{mode}-{attempt}"
                    start = time.perf_counter()
                    generate(config, root, progress=False, generator=gens[mode])
                    rounds[mode].append(frames / (time.perf_counter() - start))
                    if (renderer, mode) in roots:  # the last round's copy is the one kept
                        shutil.rmtree(roots[renderer, mode])
                    roots[renderer, mode] = root
            row = {"rounds": args.repeats, "raw_fps": float(np.median(rounds["raw"]))}
            for mode in configs:
                # each round's ratio to the raw play just before it, then their median: the
                # same code moves by +-0.1 between runs of this shared 2-core box
                ratios = np.divide(rounds[mode], rounds["raw"])
                row[f"{mode}_generate_fps"] = float(np.median(rounds[mode]))
                row[f"{mode}_generate_over_raw"] = float(np.median(ratios))
                row[f"{mode}_generate_over_raw_range"] = [float(ratios.min()), float(ratios.max())]
                row[f"{mode}_generate_over_raw_rounds"] = [round(float(r), 3) for r in ratios]
                row[f"{mode}_frame_bytes_per_frame"] = dataset_info(
                    roots[renderer, mode])["frame_bytes_per_frame"]
            pixel_root = Path(tmp) / f"{renderer}-pixels"
            generate(pixel_config, pixel_root, progress=False,
                     generator=ShardGenerator(pixel_config, 8, lambda c, n: PixelRandomAgent(n)))
            total, nonzero, size = _nonzero_residual_frames(pixel_root)
            row["pixel_agent_residual"] = {"frames": total, "nonzero_frames": nonzero,
                                           "bytes_per_frame": size}
            out[f"written_with_{renderer}"] = row
        for writer in RENDERERS:
            for reader in RENDERERS:
                use(reader)
                decode_fps(roots[writer, "rendered"])  # warm: compile, textures
                out[f"written_with_{writer}"][f"decode_fps_read_with_{reader}"] = decode_fps(
                    roots[writer, "rendered"])
            use(writer)
            out[f"written_with_{writer}"]["stored_decode_fps"] = decode_fps(roots[writer, "stored"])
    return out


def part_eval(args) -> dict:
    """Each renderer twice, in turns; the second run of each counts (the first, of at most 8
    episodes, fills JAX's compilation cache, as any earlier ``zoo eval`` would have). One torch
    thread: two stall each other on a shared 2-core box (docs/results/benchmarks.md)."""
    out = {"episodes": args.eval_episodes, "num_envs": 8, "torch_threads": 1,
           "checkpoint": "weights/cvpt_tiny_cpu"}
    for attempt in range(2):
        episodes = args.eval_episodes if attempt else min(args.eval_episodes, 8)
        for renderer in RENDERERS:
            with tempfile.TemporaryDirectory() as tmp:
                cmd = [sys.executable, "-m", "zoo.cli", "eval", "--env", "craftax",
                       "--checkpoint", str(ROOT / "weights" / "cvpt_tiny_cpu"),
                       "--episodes", str(episodes), "--seed", "0", "--num-envs", "8",
                       "--out", tmp]
                env = {**os.environ, "ZOO_RENDERER": renderer, "OMP_NUM_THREADS": "1"}
                start = time.perf_counter()
                subprocess.run(cmd, check=True, env=env, stdout=subprocess.DEVNULL,
                               stderr=subprocess.DEVNULL)
                wall = time.perf_counter() - start
                stats = (Path(tmp) / "stats.jsonl").read_text().splitlines()
                lengths = [json.loads(line)["length"] for line in stats]
            out[renderer] = {"wall_s": wall, "env_steps": sum(lengths),
                             "env_steps_per_s": sum(lengths) / wall}
    out["speedup"] = out["jax"]["wall_s"] / out["numba"]["wall_s"]
    return out


def part_rl(args) -> dict:
    """One torch thread, as for eval: two stall each other on a shared 2-core box."""
    import torch
    from bench_rl import measure

    torch.set_num_threads(1)
    out = {"torch_threads": 1}
    for renderer in RENDERERS:
        use(renderer)
        row = measure("cvpt_rl", args.rl_envs, args.rl_updates)
        out[renderer] = {k: row[k] for k in ("num_envs", "env_steps_per_s", "env_share",
                                             "model_share", "update_share")}
    out["speedup"] = out["numba"]["env_steps_per_s"] / out["jax"]["env_steps_per_s"]
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--parts", nargs="+", choices=PARTS, default=list(PARTS))
    parser.add_argument("--steps", type=int, default=300, help="renderer: play steps per agent")
    parser.add_argument("--every", type=int, default=5, help="renderer: keep every k-th step")
    parser.add_argument("--episodes", type=int, default=32)
    parser.add_argument("--max-steps", type=int, default=300)
    parser.add_argument("--repeats", type=int, default=5,
                        help="data: rounds of raw play and generation (medians reported)")
    parser.add_argument("--eval-episodes", type=int, default=100,
                        help="eval: episodes of each zoo eval run (--tiny: 2)")
    parser.add_argument("--rl-envs", type=int, default=16)
    parser.add_argument("--rl-updates", type=int, default=3)
    parser.add_argument("--tiny", action="store_true", help="a smoke run of every part")
    parser.add_argument("--run-part", choices=PARTS, help=argparse.SUPPRESS)
    parser.add_argument("--part-out", type=Path, help=argparse.SUPPRESS)
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args()
    if args.tiny:
        args.steps, args.episodes, args.max_steps, args.repeats = 20, 2, 30, 1
        args.eval_episodes, args.rl_updates = 2, 1
    if args.run_part:
        sys.path.insert(0, str(Path(__file__).parent))
        result = globals()[f"part_{args.run_part}"](args)
        args.part_out.write_text(json.dumps(result))
        return
    # a run of some parts replaces those parts of an earlier run's results
    results = json.loads(args.out.read_text()) if args.out.exists() and not args.tiny else {}
    results["machine"] = {"processor": platform.processor() or platform.machine(),
                          "cpus": os.cpu_count(), "load_average_start": os.getloadavg()}
    results["date"] = time.strftime("%Y-%m-%d %H:%M")
    with tempfile.TemporaryDirectory() as tmp:
        for part in args.parts:
            part_out = Path(tmp) / f"{part}.json"
            argv = [a for a in sys.argv[1:] if a not in ("--parts", *PARTS)]
            subprocess.run([sys.executable, __file__, *argv, "--run-part", part,
                            "--part-out", str(part_out)], check=True)
            results[part] = {**json.loads(part_out.read_text()), "date": time.strftime("%H:%M")}
            print(part, json.dumps(results[part], indent=1), flush=True)
    results["machine"]["load_average_end"] = os.getloadavg()
    if not args.tiny:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(results, indent=1) + "\n")
        print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
