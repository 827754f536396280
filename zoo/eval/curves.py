"""`zoo curves RUN_DIR`: training curves of a `zoo fit` run as a PNG, without W&B.

Runs whose config has a CSVLogger write ``csv/version_*/metrics.csv`` (one row per logged step,
a column per metric, blanks where a metric was not logged at that step); this draws each
``*/loss`` and ``*/acc`` column against the optimizer step.
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

import numpy as np


def read_metrics(path: str | Path) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """``{metric: (steps, values)}`` from a Lightning CSVLogger file, blanks skipped."""
    path = Path(path)
    with path.open(newline="") as f:
        rows = list(csv.DictReader(f))
    if not rows or "step" not in rows[0]:
        raise ValueError(f"{path}: expected a CSVLogger metrics.csv with a 'step' column")
    series: dict[str, tuple[list[int], list[float]]] = {}
    for row in rows:
        for name, value in row.items():
            if name in ("epoch", "step") or value in ("", None):
                continue
            steps, values = series.setdefault(name, ([], []))
            steps.append(int(row["step"]))
            values.append(float(value))
    return {name: (np.array(s), np.array(v)) for name, (s, v) in series.items()}


def find_metrics(run_dir: str | Path) -> Path:
    """The newest ``metrics.csv`` under a run folder."""
    found = sorted(Path(run_dir).glob("**/metrics.csv"), key=lambda p: p.stat().st_mtime)
    if not found:
        raise FileNotFoundError(
            f"no metrics.csv under {run_dir}: add a lightning CSVLogger to the config's "
            "trainer.logger (configs/cvpt_tiny_cpu.yaml has one)"
        )
    return found[-1]


def plot_curves(metrics: dict[str, tuple[np.ndarray, np.ndarray]], title: str, path: str | Path) -> Path:
    """One panel for losses, one for accuracies; train and val/test share the axes."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    panels = [("loss", "cross-entropy"), ("acc", "accuracy")]
    fig = Figure(figsize=(10, 3.6), dpi=100)
    FigureCanvasAgg(fig)
    for i, (suffix, label) in enumerate(panels):
        ax = fig.add_subplot(1, len(panels), i + 1)
        for name, (steps, values) in sorted(metrics.items()):
            if name.endswith("/" + suffix):
                ax.plot(steps, values, marker="o" if len(steps) < 30 else None, ms=3, label=name)
        ax.set_xlabel("optimizer step")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=8)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path)
    return Path(path)


def run_curves(args: argparse.Namespace) -> int:
    try:
        source = find_metrics(args.run_dir)
        metrics = read_metrics(source)
    except (FileNotFoundError, ValueError) as err:
        print(f"zoo curves: error: {err}")
        return 2
    out = args.out or Path(args.run_dir) / "curves.png"
    plot_curves(metrics, str(args.run_dir), out)
    for name, (steps, values) in sorted(metrics.items()):
        print(f"{name:<16} step {steps[-1]:>6}  last {values[-1]:.4f}  "
              f"range [{values.min():.4f}, {values.max():.4f}]")
    print(f"wrote {out}")
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "curves", help="plot a training run's loss/accuracy curves (CSVLogger metrics)",
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("run_dir", type=Path, help="a run folder from `zoo fit`")
    p.add_argument("--out", type=Path, help="PNG to write (default RUN_DIR/curves.png)")
    p.set_defaults(handler=run_curves)
