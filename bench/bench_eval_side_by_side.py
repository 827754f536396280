"""Two ``zoo eval`` runs side by side on a small machine, with and without OMP_WAIT_POLICY=PASSIVE
-> bench/results/eval_side_by_side.json.

Why: on 2 cores two evaluations at once ran ~10x slower than one alone. Torch's OpenMP threads
spin at barriers by default, and the other process's threads (torch's and JAX's) wait for
those cores. ``zoo fit`` sets PASSIVE already. Whether ``zoo eval`` should too depends on what
PASSIVE costs one run alone, so both are measured in one run, taking turns.

How: ``zoo eval --checkpoint CKPT --env ENV --episodes N --no-gif`` as subprocesses; the wall
time of each. "alone" runs one at a time; "pair" starts two (seeds S and S+1) and waits for
both. Each setting runs ``--rounds`` times in turn with the other; the JSON keeps every time,
and the medians.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bench_cvpt import machine

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "bench" / "results" / "eval_side_by_side.json"


def eval_command(args: argparse.Namespace, seed: int, out: Path) -> list[str]:
    return [sys.executable, "-m", "zoo.cli", "eval", "--checkpoint", args.checkpoint,
            "--env", args.env, "--episodes", str(args.episodes), "--seed", str(seed),
            "--out", str(out), "--no-gif", "--overwrite"]


def run_together(commands: list[list[str]], passive: bool) -> list[float]:
    """Start ``commands`` at once; the wall seconds of each, in order."""
    env = dict(os.environ)
    env.pop("OMP_WAIT_POLICY", None)
    if passive:
        env["OMP_WAIT_POLICY"] = "PASSIVE"
    start = time.perf_counter()
    procs = [subprocess.Popen(c, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                              text=True) for c in commands]
    walls = []
    for proc in procs:
        _, err = proc.communicate()
        if proc.returncode != 0:
            raise RuntimeError(f"zoo eval failed ({proc.returncode}): {err[-2000:]}")
        walls.append(time.perf_counter() - start)
    return walls


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--checkpoint", default=str(ROOT / "weights" / "cvpt_tiny_cpu"))
    parser.add_argument("--env", default="craftax")
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--seed", type=int, default=11)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args()
    times: dict[str, list[float]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        outs = [Path(tmp) / "a", Path(tmp) / "b"]
        for _ in range(args.rounds):
            for passive in (False, True):
                policy = "passive" if passive else "default"
                alone = run_together([eval_command(args, args.seed, outs[0])], passive)
                times.setdefault(f"alone_{policy}", []).extend(alone)
                pair = run_together([eval_command(args, args.seed + i, outs[i])
                                     for i in range(2)], passive)
                times.setdefault(f"pair_{policy}", []).extend(pair)
    medians = {k: statistics.median(v) for k, v in times.items()}
    results = {
        "method": __doc__.split("How: ")[1].strip(),
        "command": eval_command(args, args.seed, Path("OUT"))[2:],
        "machine": machine(),
        "wall_s": times, "median_wall_s": medians,
        "pair_slowdown_default": medians["pair_default"] / medians["alone_default"],
        "pair_slowdown_passive": medians["pair_passive"] / medians["alone_passive"],
        "passive_cost_alone": medians["alone_passive"] / medians["alone_default"],
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(results, indent=2) + "\n")
    print(json.dumps({k: v for k, v in results.items() if k != "method"}, indent=2))


if __name__ == "__main__":
    main()
