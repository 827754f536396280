"""`zoo rl plot`: success rate against env steps, mean ± std over seeds, one panel per task
(the paper's long-horizon figure), with fixed agents (``zoo eval --task`` reports) as lines."""

from __future__ import annotations

import csv
import json
from collections import defaultdict
from pathlib import Path

import numpy as np
import yaml

LABELS = {"ppo_rnn": "PPO-RNN", "cvpt_rl": "C-VPT-RL", "ppo_steve": "PPO-Steve"}


def read_run(run_dir: str | Path) -> tuple[dict, np.ndarray, np.ndarray]:
    """(config, env steps, success rate of the logged window) of one ``zoo rl`` run (the
    window is the last 100 episodes in seed order, ``SeedOrderWindow``, not the last 100 to end,
    which would favour short episodes)."""
    run_dir = Path(run_dir)
    config_path, metrics_path = run_dir / "config.yaml", run_dir / "metrics.csv"
    if not config_path.is_file() or not metrics_path.is_file():
        raise FileNotFoundError(
            f"{run_dir} is not a `zoo rl train` run: it needs config.yaml and metrics.csv"
        )
    config = yaml.safe_load(config_path.read_text())
    with metrics_path.open(newline="") as f:
        rows = [r for r in csv.DictReader(f) if r["success_rate_100"] != ""]
    steps = np.array([int(r["env_steps"]) for r in rows])
    success = np.array([float(r["success_rate_100"]) for r in rows])
    return config, steps, success


def mean_curve(curves: list[tuple[np.ndarray, np.ndarray]], points: int = 50):
    """Seeds on a shared grid up to the shortest run: (grid, mean, std)."""
    end = min(s[-1] for s, _ in curves)
    start = max(s[0] for s, _ in curves)
    grid = np.linspace(start, end, points) if end > start else np.array([end])
    ys = np.stack([np.interp(grid, s, y) for s, y in curves])
    return grid, ys.mean(0), ys.std(0)


def plot_runs(
    run_dirs: list[str | Path], out: str | Path, baselines: list[tuple[str, Path]]
) -> dict:
    """Draw every run (grouped by task and agent) and the baselines; returns the final
    success rates per task and agent (mean and std over seeds, and the seed count)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    groups: dict[str, dict[str, list]] = defaultdict(lambda: defaultdict(list))
    for run in run_dirs:
        config, steps, success = read_run(run)
        if len(steps):
            groups[config["task"]][config["agent"]].append((steps, success))
    lines: dict[str, list[tuple[str, float]]] = defaultdict(list)
    for label, path in baselines:  # a label may repeat: one line per task it reports
        report = json.loads(Path(path).read_text())
        lines[report["task"]].append((label, report["success_percent"] / 100))
    tasks = sorted(set(groups) | set(lines))
    if not tasks:
        raise ValueError("no run has a finished episode yet and no baseline was given")
    fig = Figure(figsize=(4.2 * len(tasks), 3.6), dpi=100)
    FigureCanvasAgg(fig)
    table: dict[str, dict] = {}
    for i, task in enumerate(tasks):
        ax = fig.add_subplot(1, len(tasks), i + 1)
        for agent, curves in sorted(groups[task].items()):
            grid, mean, std = mean_curve(curves)
            ax.plot(grid, mean, label=f"{LABELS.get(agent, agent)} ({len(curves)} seeds)")
            ax.fill_between(grid, mean - std, mean + std, alpha=0.2)
            finals = [y[-1] for _, y in curves]
            table.setdefault(task, {})[agent] = {
                "success_rate": float(np.mean(finals)), "std": float(np.std(finals)),
                "seeds": len(curves), "env_steps": int(min(s[-1] for s, _ in curves)),
            }
        for label, rate in lines[task]:
            ax.axhline(rate, ls="--", lw=1, color="gray")
            ax.annotate(label, (0.02, rate), xycoords=("axes fraction", "data"), fontsize=7)
            table.setdefault(task, {})[label] = {"success_rate": rate, "fixed": True}
        ax.set_title(task)
        ax.set_xlabel("env steps")
        ax.set_ylabel("success rate (100 episodes, seed order)")
        ax.set_ylim(-0.02, 1.02)
        if groups[task]:  # below the axes: never over a curve or a baseline's label
            ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.18))
    fig.tight_layout()
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, bbox_inches="tight")
    return table
