"""Caption generation speed and per-rule counts on a CrafterPlay set -> bench/results/captions.json.

Measures (1) the rule scan alone: episode steps checked per second by the 15 rules, from
decoded states; (2) the whole `zoo data caption` pipeline (read + rules + balance + clip
encoding + shard writing), in source steps per second. Also records the per-rule counts
before and after uniform balancing.

    python bench/bench_captions.py --src data/crafterplay-scripted   # an existing set
    python bench/bench_captions.py                                   # makes a small random set
"""

from __future__ import annotations

import argparse
import json
import platform
import tempfile
import time
from pathlib import Path

from zoo.captions.dataset import caption_dataset
from zoo.captions.rules import EpisodeView, all_rules, scan_episode
from zoo.cli import main as zoo_main
from zoo.data.reader import iter_episodes, list_shards

RESULTS = Path(__file__).parent / "results" / "captions.json"


def make_random_set(out: Path, episodes: int, max_steps: int) -> None:
    argv = ["data", "generate", "--expert", "random", "--env", "crafter", "--episodes",
            str(episodes), "--max-steps", str(max_steps), "--seed", "0", "--out", str(out)]
    if zoo_main(argv) != 0:
        raise SystemExit("generating the random CrafterPlay set failed")


def bench_rules(src: Path) -> dict:
    episodes = list(iter_episodes(list_shards(src)))
    rules = all_rules()
    steps, fired, seconds = 0, 0, 0.0
    for episode in episodes:
        start = time.perf_counter()
        view = EpisodeView(episode["actions"], episode["state"])
        fired += sum(1 for _ in scan_episode(view, rules))
        seconds += time.perf_counter() - start
        steps += len(episode["actions"])
    meta = episodes[0]["meta"]
    return {
        "episodes": len(episodes), "steps": steps, "captions_fired": fired,
        "seconds": round(seconds, 3), "steps_per_s": round(steps / seconds, 1),
        "env": meta.get("env"), "expert": meta.get("expert"),
    }


def bench_pipeline(src: Path, steps: int, heldout: int) -> dict:
    with tempfile.TemporaryDirectory() as out:
        start = time.perf_counter()
        manifest = caption_dataset(src, out, seed=0, heldout_episodes=heldout)
        seconds = time.perf_counter() - start
    return {
        "seconds": round(seconds, 2),
        "source_steps_per_s": round(steps / seconds, 1),
        "samples": {s: m["samples"] for s, m in manifest["splits"].items()},
        "rules": {
            split: {
                "before": m["counts_before"]["rules"],
                "after": m["counts_after"]["rules"],
            }
            for split, m in manifest["splits"].items()
        },
        "captions_before": {
            split: {c: n for c, n in m["counts_before"]["captions"].items() if n}
            for split, m in manifest["splits"].items()
        },
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--src", type=Path, help="CrafterPlay folder (default: make a random one)")
    parser.add_argument("--episodes", type=int, default=4, help="random set: episodes")
    parser.add_argument("--max-steps", type=int, default=500, help="random set: step limit")
    parser.add_argument("--heldout-episodes", type=int, default=1, help="episodes held out")
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        src = args.src
        if src is None:
            src = Path(tmp) / "play"
            make_random_set(src, args.episodes, args.max_steps)
        rules = bench_rules(src)
        pipeline = bench_pipeline(src, rules["steps"], args.heldout_episodes)
    result = {
        "source": str(args.src or f"random crafter, {args.episodes} x {args.max_steps} steps"),
        "machine": platform.platform(),
        "rule_scan": rules,
        "pipeline": pipeline,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=1))
    print(json.dumps({k: result[k] for k in ("source", "rule_scan")}, indent=1))
    print(json.dumps(pipeline["samples"]), f"pipeline {pipeline['source_steps_per_s']} steps/s")


if __name__ == "__main__":
    main()
