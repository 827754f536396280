"""Goal-directed generation (``zoo data generate --instructions``) -> bench/results/instructions.json.

Three datasets of the same episodes, each generated once on one env batch built beforehand (so
JAX compiles outside the timing): normal play; the scripted expert told captions one after
another (``--instructions captions``); the same from the task suites' starting inventories
(``--start-states tasks``). Per run: frames/s of ``zoo.data.generate``, by the wall clock and
per second of this process's CPU time (all its threads: steadier on a shared box), and the mean
episode length; per scheduled run the share of steps taken under an instruction (the rest are rests),
and per caption how its instructions ended (completed, timed out, interrupted by a rest, episode
ended) and the mean actions a completed one took.

    python bench/bench_instructions.py                  # Craftax, 16 episodes of 1,000 steps
    python bench/bench_instructions.py --env crafter --episodes 4 --max-steps 200
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

from zoo.agents import dataset_agent
from zoo.agents.instructions import instruction_schedule
from zoo.data.generate import GenerationConfig, ShardGenerator, generate
from zoo.data.info import dataset_info
from zoo.data.reader import iter_chunks, list_shards
from zoo.experts.scripted.schedule import OUTCOMES

RESULTS = Path(__file__).parent / "results" / "instructions.json"


def bench_run(name: str, config: GenerationConfig, num_envs: int, out: Path) -> dict:
    gen = ShardGenerator(config, num_envs, dataset_agent)
    warm = np.arange(gen.num_envs) + 10**6
    step = gen.env.reset(warm)  # compile reset, step and the start edit; warm the agent
    gen.agent.reset(warm)
    for _ in range(20):
        step = gen.env.step(np.asarray(gen.agent.act(step)))
    t, cpu = time.perf_counter(), time.process_time()
    manifest = generate(config, out, progress=False, generator=gen)
    seconds, cpu_seconds = time.perf_counter() - t, time.process_time() - cpu
    info = dataset_info(out)
    lengths = [n for e in manifest["shards"] for n in e["episode_lengths"]]
    row = {
        "run": name, "frames": info["frames"], "seconds": seconds, "fps": info["frames"] / seconds,
        "cpu_seconds": cpu_seconds, "cpu_fps": info["frames"] / cpu_seconds,
        "mean_episode_length": float(np.mean(lengths)), "instructions": None,
    }
    if info["instructions"]:
        row["instructions"] = {}
        for caption, tally in info["instructions"].items():
            given = sum(tally[outcome] for outcome in OUTCOMES)
            row["instructions"][caption] = {
                "given": given,
                **{outcome: tally[outcome] / max(given, 1) for outcome in OUTCOMES},
                "mean_actions_to_complete": tally["completed_actions"] / tally["completed"]
                if tally["completed"] else None,
            }
        told = sum(int((c["instruction"] >= 0).sum()) for c in iter_chunks(list_shards(out)))
        row["instructed_share"] = told / info["steps"]
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="craftax", choices=("craftax", "crafter"))
    parser.add_argument("--num-envs", type=int, default=8)
    parser.add_argument("--episodes", type=int, default=16)
    parser.add_argument("--max-steps", type=int, default=1000)
    parser.add_argument("--timeout", type=int, default=300)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args()

    normal = GenerationConfig(
        expert="scripted", episodes=args.episodes, seed=args.seed, env=args.env,
        episodes_per_shard=args.episodes, max_steps=args.max_steps,
    )
    told = dataclasses.replace(normal, instructions=instruction_schedule("captions", args.timeout))
    runs = {"normal": normal, "instructions": told,
            "instructions_task_starts": dataclasses.replace(told, start_states="tasks")}
    results = {
        "env": args.env, "num_envs": args.num_envs, "episodes": args.episodes,
        "max_steps": args.max_steps, "timeout": args.timeout,
        "machine": platform.processor() or platform.machine(),
        "date": time.strftime("%Y-%m-%d %H:%M"), "runs": [],
    }
    with tempfile.TemporaryDirectory() as tmp:
        for name, config in runs.items():
            row = bench_run(name, config, args.num_envs, Path(tmp) / name)
            results["runs"].append(row)
            print(json.dumps(row, indent=1), flush=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(results, indent=1) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
