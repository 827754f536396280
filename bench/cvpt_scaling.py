"""What bounds the CPU C-VPT's Crafter Score: frames, unique episodes or episode length (issue 49).

Runs a plan (configs/studies/cvpt_scaling.yaml) cell by cell, a cell being one point trained
with one seed: its datasets are generated if missing (`zoo data generate`, which finishes an
interrupted folder), the plan's recipe is trained for the point's steps on them (`zoo fit`, a
full cosine over those steps), and the last checkpoint is scored in each game (`zoo eval`, eval
seed and episodes from the plan). Each finished cell is written to the results JSON at once,
so a stopped run goes on with the next unfinished cell; ``--plot`` draws the three curves.

  .venv/bin/python bench/cvpt_scaling.py --plan configs/studies/cvpt_scaling.yaml [--only P]
  .venv/bin/python bench/cvpt_scaling.py --plan configs/studies/cvpt_scaling.yaml --plot
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
import yaml

RESULTS = Path(__file__).parent / "results" / "cvpt_scaling.json"
PLOT = Path(__file__).parents[1] / "docs" / "results" / "cvpt_scaling.png"
AXES = {"frames": "frames seen (millions)", "episodes": "unique episodes in the data",
        "horizon": "episode length cap (steps)"}


@dataclass(frozen=True)
class Cell:
    """One point of the plan trained with one seed."""

    point: str
    seed: int
    steps: int
    data: dict[str, float]  # dataset name -> sampling weight
    axes: tuple[str, ...]

    @property
    def name(self) -> str:
        return f"{self.point}_seed{self.seed}"


def load_plan(path: Path) -> dict:
    """The plan, checked: every point's datasets exist and every axis is known."""
    plan = yaml.safe_load(path.read_text())
    for key in ("recipe", "seeds", "eval", "datasets", "points"):
        if key not in plan:
            raise ValueError(f"{path}: missing key {key!r}")
    for point, spec in plan["points"].items():
        unknown = sorted(set(spec["data"]) - set(plan["datasets"]))
        if unknown:
            raise ValueError(f"{path}: point {point!r} uses undefined datasets {unknown}")
        bad = sorted(set(spec["axes"]) - set(AXES))
        if bad:
            raise ValueError(f"{path}: point {point!r} has unknown axes {bad}; known: {list(AXES)}")
    return plan


def cells(plan: dict) -> list[Cell]:
    """Every point with every seed, seeds outermost, so one pass over the first seed gives
    every curve before the second seed starts."""
    return [Cell(point, int(seed), int(spec["steps"]), dict(spec["data"]), tuple(spec["axes"]))
            for seed in plan["seeds"] for point, spec in plan["points"].items()]


def data_root(name: str, spec: dict, data_dir: Path) -> Path:
    """A dataset's folder: its ``root`` (the recipe's own data, say), else data_dir/name."""
    return Path(spec["root"]) if "root" in spec else data_dir / name


def generate_command(name: str, spec: dict, data_dir: Path, workers: int) -> list[str]:
    """`zoo data generate` of one dataset (scripted, plants first, the recipe's shard size)."""
    return [sys.executable, "-m", "zoo.cli", "data", "generate", "--expert", "scripted",
            "--env", spec["env"], "--episodes", str(spec["episodes"]),
            "--max-steps", str(spec["max_steps"]), "--seed", str(spec["seed"]),
            "--episodes-per-shard", "16", "--out", str(data_root(name, spec, data_dir)),
            "--workers", str(workers), "--expert-option", "plants_first=true", "--no-progress"]


def fit_command(plan: dict, cell: Cell, data_dir: Path, run_dir: Path) -> list[str]:
    """`zoo fit` of the recipe on the cell's data for its steps, a cosine over all of them."""
    sources = [{"root": str(data_root(name, plan["datasets"][name], data_dir)), "weight": weight}
               for name, weight in cell.data.items()]
    return [sys.executable, "-m", "zoo.cli", "fit", "--config", plan["recipe"],
            f"--seed_everything={cell.seed}", f"--trainer.max_steps={cell.steps}",
            f"--model.init_args.cosine_steps={cell.steps}",
            f"--trainer.default_root_dir={run_dir}",
            "--data.init_args.root=null", f"--data.init_args.sources={json.dumps(sources)}"]


def eval_command(plan: dict, checkpoint: Path, game: str, out: Path) -> list[str]:
    spec = plan["eval"]
    return [sys.executable, "-m", "zoo.cli", "eval", "--checkpoint", str(checkpoint),
            "--env", game, "--episodes", str(spec["episodes"]), "--seed", str(spec["seed"]),
            "--out", str(out), "--no-gif"]


def run(command: list[str], log: Path) -> float:
    """Run ``command`` with its output in ``log``; seconds it took. A failure names the log."""
    log.parent.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    with log.open("w") as out:
        done = subprocess.run(command, stdout=out, stderr=subprocess.STDOUT,
                              env={k: v for k, v in os.environ.items() if k != "ZOO_RUN_DIR"})
    if done.returncode:
        tail = log.read_text()[-2000:]
        raise RuntimeError(f"{' '.join(command[2:5])} exited {done.returncode} (log: {log}):\n{tail}")
    return time.perf_counter() - start


def dataset_steps(root: Path) -> dict[str, int]:
    """Episodes and steps a dataset's manifest lists."""
    shards = json.loads((root / "manifest.json").read_text())["shards"]
    return {"episodes": sum(s["episodes"] for s in shards), "steps": sum(s["steps"] for s in shards)}


def last_checkpoint(run_dir: Path) -> Path:
    found = sorted(run_dir.glob("*/checkpoints/last.ckpt"), key=lambda p: p.stat().st_mtime)
    if not found:
        raise FileNotFoundError(f"no */checkpoints/last.ckpt under {run_dir}")
    return found[-1]


def run_cell(plan: dict, cell: Cell, data_dir: Path, runs: Path, workers: int) -> dict:
    """Data (if missing), training and evaluation of one cell; its record."""
    for name in cell.data:
        spec = plan["datasets"][name]
        root = data_root(name, spec, data_dir)
        if not (root / "manifest.json").exists() or dataset_steps(root)["episodes"] < spec["episodes"]:
            # missing or interrupted: the same command finishes it
            run(generate_command(name, spec, data_dir, workers), runs / "logs" / f"generate_{name}.log")
    run_dir = runs / cell.name
    fit_s = run(fit_command(plan, cell, data_dir, run_dir), run_dir / "fit.log")
    checkpoint = last_checkpoint(run_dir)
    step = torch.load(checkpoint, map_location="cpu", weights_only=True)["global_step"]
    if step != cell.steps:
        raise RuntimeError(f"{checkpoint} is at step {step}, not the cell's {cell.steps}: steps "
                           f"must be a multiple of the recipe's epoch (train_batches_per_epoch)")
    scores = {}
    for game in plan["eval"]["games"]:
        out = run_dir / f"eval_{game}"
        eval_s = run(eval_command(plan, checkpoint, game, out), run_dir / f"eval_{game}.log")
        report = json.loads((out / "report.json").read_text())
        scores[game] = {"crafter_score": report["crafter_score"]["mean"],
                        "crafter_score_std": report["crafter_score"]["std"],
                        "return": report["normalized_return"]["mean"],
                        "episode_length": report["episode_length"]["mean"],
                        "episode_end_percent": report["episode_end_percent"], "eval_s": eval_s}
    data = {name: dataset_steps(data_root(name, plan["datasets"][name], data_dir))
            for name in cell.data}
    return {"point": cell.point, "seed": cell.seed, "axes": list(cell.axes), "steps": cell.steps,
            "frames": cell.steps * frames_per_step(plan), "data": data,
            "weights": cell.data, "unique_episodes": sum(d["episodes"] for d in data.values()),
            "data_steps": sum(d["steps"] for d in data.values()),
            "max_steps": max(plan["datasets"][n]["max_steps"] for n in cell.data),
            "fit_s": fit_s, "checkpoint": str(checkpoint), "scores": scores,
            "finished": time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime())}


def frames_per_step(plan: dict) -> int:
    data = yaml.safe_load(Path(plan["recipe"]).read_text())["data"]["init_args"]
    return int(data["batch_size"]) * int(data["seq_len"])


def save(results: dict, path: Path) -> None:
    """Atomic write: an interrupted save never leaves a half-written results file."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(results, indent=2) + "\n")
    tmp.replace(path)


def axis_value(record: dict, axis: str) -> float:
    return {"frames": record["frames"] / 1e6, "episodes": record["unique_episodes"],
            "horizon": record["max_steps"]}[axis]


def axis_means(results: dict, axis: str, game: str) -> dict[float, list[float]]:
    """Per point on ``axis``: the Crafter Scores in ``game`` of its seeds."""
    out: dict[float, list[float]] = {}
    for record in results["cells"].values():
        if axis in record["axes"] and game in record["scores"]:
            out.setdefault(axis_value(record, axis), []).append(
                record["scores"][game]["crafter_score"])
    return dict(sorted(out.items()))


def log_fit(points: dict[float, list[float]], at: float) -> dict[str, float]:
    """Least squares of score = a + b log10(x) over every seed's score (each seed one sample),
    and its value at ``at``: the slope per tenfold x and what it extrapolates to. Needs two
    distinct x."""
    xs = np.log10([x for x, ys in points.items() for _ in ys])
    ys = np.array([y for values in points.values() for y in values])
    if len(set(xs.tolist())) < 2:
        raise ValueError(f"a log fit needs two distinct x, got {sorted(points)}")
    slope, intercept = np.polyfit(xs, ys, 1)
    residual = ys - (intercept + slope * xs)
    return {"per_tenfold": float(slope), "intercept": float(intercept),
            "rms_residual": float(np.sqrt(np.mean(residual**2))), "at": at,
            "extrapolated": float(intercept + slope * np.log10(at))}


def table(results: dict) -> str:
    """The finished cells as a markdown table: each point's data and steps, and per game the
    Crafter Score (± std over 5 chunks of 20) of each seed."""
    games = results["plan"]["eval"]["games"]
    seeds = results["plan"]["seeds"]
    head = ["point", "frames", "unique episodes", "data steps", "cap"] + [
        f"{g} seed {s}" for g in games for s in seeds]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    points: dict[str, dict[int, dict]] = {}
    for record in results["cells"].values():
        points.setdefault(record["point"], {})[record["seed"]] = record
    for point, by_seed in points.items():
        any_record = next(iter(by_seed.values()))
        cells = [point, f"{any_record['frames'] / 1e6:.2f}M", f"{any_record['unique_episodes']:,}",
                 f"{any_record['data_steps']:,}", f"{any_record['max_steps']:,}"]
        for game in games:
            for seed in seeds:
                score = by_seed.get(seed, {}).get("scores", {}).get(game)
                cells.append("not run" if score is None else
                             f"{score['crafter_score']:.1f} ± {score['crafter_score_std']:.1f}")
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def plot(results: dict, out: Path) -> None:
    """One panel per axis: each seed's Crafter Score per game (dots) and their mean (line)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    records = list(results["cells"].values())
    games = sorted({g for r in records for g in r["scores"]})
    fig, panels = plt.subplots(1, len(AXES), figsize=(4.2 * len(AXES), 3.6), sharey=True)
    for panel, (axis, label) in zip(panels, AXES.items()):
        on_axis = [r for r in records if axis in r["axes"]]
        for game, marker in zip(games, "os"):
            xs = sorted({axis_value(r, axis) for r in on_axis})
            means = []
            for x in xs:
                ys = [r["scores"][game]["crafter_score"] for r in on_axis
                      if axis_value(r, axis) == x and game in r["scores"]]
                panel.scatter([x] * len(ys), ys, marker=marker, alpha=0.5, s=18)
                means.append(sum(ys) / len(ys))
            panel.plot(xs, means, marker=marker, label=game)
        panel.set_xscale("log")
        ticks = sorted({axis_value(r, axis) for r in on_axis})
        panel.set_xticks(ticks, [f"{x:g}" for x in ticks])  # the points, not log decades
        panel.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        panel.set_xlabel(label)
        panel.grid(alpha=0.3)
    panels[0].set_ylabel("Crafter Score (%)")
    panels[0].legend()
    fig.suptitle(f"C-VPT tiny ({Path(results['plan']['recipe']).stem}), "
                 f"{results['plan']['eval']['episodes']} eval episodes per dot")
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=120)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--plan", type=Path, default=Path("configs/studies/cvpt_scaling.yaml"))
    parser.add_argument("--out", type=Path, default=RESULTS, help="the results JSON")
    parser.add_argument("--data-dir", type=Path, default=Path("data/scaling"))
    parser.add_argument("--runs", type=Path, default=Path("runs/scaling"))
    parser.add_argument("--workers", type=int, default=2, help="data generation processes")
    parser.add_argument("--only", nargs="+", metavar="CELL", help="run these cells (POINT_seedS)")
    parser.add_argument("--list", action="store_true", help="print the cells and their state")
    parser.add_argument("--plot", type=Path, nargs="?", const=PLOT, metavar="PNG",
                        help=f"draw the curves from --out (default {PLOT}) and stop")
    parser.add_argument("--table", action="store_true",
                        help="print the finished cells as a markdown table, and stop")
    parser.add_argument("--fit", type=float, nargs="?", const=180e6, metavar="FRAMES",
                        help="print each axis' and game's log-linear fit of the score (per "
                        "tenfold), the frames line's value at FRAMES (default the paper's "
                        "180M), and stop")
    args = parser.parse_args(argv)
    plan = load_plan(args.plan)
    results: dict[str, Any] = (json.loads(args.out.read_text()) if args.out.exists()
                               else {"plan": plan, "cells": {}})
    if args.plot:
        plot(results, args.plot)
        print(f"wrote {args.plot}")
        return 0
    if args.table:
        print(table(results))
        return 0
    if args.fit:
        for axis in AXES:
            for game in results["plan"]["eval"]["games"]:
                points = axis_means(results, axis, game)
                if axis == "frames":
                    points = {x * 1e6: ys for x, ys in points.items()}
                if len(points) >= 2:
                    at = args.fit if axis == "frames" else max(points)
                    print(axis, game, json.dumps(log_fit(points, at)))
        return 0
    todo = [c for c in cells(plan) if c.name not in results["cells"]]
    if args.only:
        unknown = sorted(set(args.only) - {c.name for c in cells(plan)})
        if unknown:
            raise SystemExit(f"--only: unknown cells {unknown}")
        todo = [c for c in todo if c.name in args.only]
    if args.list:
        for c in cells(plan):
            print(f"{'done' if c.name in results['cells'] else 'todo'}  {c.name}")
        return 0
    for i, cell in enumerate(todo, 1):
        print(f"[{i}/{len(todo)}] {cell.name}: {cell.steps} steps on {sorted(cell.data)}",
              flush=True)
        results["cells"][cell.name] = run_cell(plan, cell, args.data_dir, args.runs, args.workers)
        results["plan"] = plan
        save(results, args.out)
        scores = {g: round(s["crafter_score"], 1) for g, s in results["cells"][cell.name]["scores"].items()}
        print(f"    {scores}, fit {results['cells'][cell.name]['fit_s'] / 60:.1f} min", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
