"""`zoo compare DIR...`: several evaluation reports side by side, as a paper table and a plot.

Reads the ``report.json`` that ``zoo eval`` wrote in each folder and prints one Markdown table
(Crafter Score and Return as mean ± std over chunks, then every achievement's success rate), so
agents and games can be set next to each other, or next to published numbers, without retyping.
``--plot`` draws the paper's per-achievement comparison figure (grouped bars).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from zoo.envs.constants import ACHIEVEMENT_NAMES

REQUIRED = ("crafter_score", "normalized_return", "success_rates", "episodes")


def load_report(path: str | Path) -> dict:
    """The report in ``path`` (a ``zoo eval`` folder or its report.json), checked for the keys
    the comparison reads."""
    path = Path(path)
    file = path / "report.json" if path.is_dir() else path
    if not file.is_file():
        raise FileNotFoundError(f"{file}: no report.json (expected a `zoo eval --out` folder)")
    try:
        report = json.loads(file.read_text())
    except json.JSONDecodeError as err:
        raise ValueError(f"{file}: not valid JSON ({err})") from None
    missing = [k for k in REQUIRED if k not in report]
    if missing:
        raise ValueError(f"{file}: missing {missing}; expected a report written by `zoo eval`")
    absent = [a for a in ACHIEVEMENT_NAMES if a not in report["success_rates"]]
    if absent:
        raise ValueError(f"{file}: success_rates lacks {absent}")
    return report


def default_label(path: str | Path, report: dict) -> str:
    """``agent (env)`` from the report, falling back to the folder name."""
    agent, env = report.get("agent"), report.get("env")
    return f"{agent} ({env})" if agent and env else Path(path).name


def markdown_table(labels: list[str], reports: list[dict]) -> str:
    """One column per report: score and return (mean ± std over chunks), episodes, success %."""

    def pm(metric: dict) -> str:
        return f"{metric['mean']:.1f} ± {metric['std']:.1f}"

    rows = [
        ["Crafter Score (%)", *(pm(r["crafter_score"]) for r in reports)],
        ["Return (%)", *(pm(r["normalized_return"]) for r in reports)],
        ["episodes", *(f"{r['episodes']} ({r.get('chunks', '?')} chunks)" for r in reports)],
        *(
            [name.replace("_", " "), *(f"{r['success_rates'][name]:.1f}" for r in reports)]
            for name in ACHIEVEMENT_NAMES
        ),
    ]
    header = ["", *labels]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(lines)


def plot_comparison(labels: list[str], reports: list[dict], path: str | Path) -> Path:
    """Grouped horizontal bars: per achievement, one bar per report (paper's comparison figure)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    n = len(reports)
    fig = Figure(figsize=(8, 0.22 * n * len(ACHIEVEMENT_NAMES) + 1.6), dpi=100)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    y = np.arange(len(ACHIEVEMENT_NAMES))
    height = 0.8 / n
    for i, (label, report) in enumerate(zip(labels, reports)):
        rates = [report["success_rates"][name] for name in ACHIEVEMENT_NAMES]
        score = report["crafter_score"]["mean"]
        ax.barh(y + (i - (n - 1) / 2) * height, rates, height, label=f"{label}: score {score:.1f}")
    ax.set_yticks(y, [name.replace("_", " ") for name in ACHIEVEMENT_NAMES], fontsize=8)
    ax.invert_yaxis()
    ax.set_xlim(0, 100)
    ax.set_xlabel("success rate (%)")
    ax.grid(axis="x", alpha=0.3)
    ax.legend(fontsize=8, loc="lower right")
    fig.tight_layout()
    fig.savefig(path)
    return Path(path)


def register(subparsers) -> None:
    """Add ``zoo compare`` to the ``zoo`` command."""
    p = subparsers.add_parser(
        "compare",
        help="several `zoo eval` reports side by side (Markdown table, comparison plot)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("reports", nargs="+", type=Path, help="`zoo eval --out` folders")
    p.add_argument(
        "--labels", nargs="+", help="column names, one per report (default: agent (env))"
    )
    p.add_argument("--plot", type=Path, help="also write the grouped bar plot to this PNG")
    p.set_defaults(handler=run_compare)


def run_compare(args: argparse.Namespace) -> int:
    if args.labels is not None and len(args.labels) != len(args.reports):
        print(
            f"zoo compare: error: {len(args.labels)} --labels for {len(args.reports)} reports",
            file=sys.stderr,
        )
        return 2
    try:
        reports = [load_report(path) for path in args.reports]
    except (FileNotFoundError, ValueError) as err:
        print(f"zoo compare: error: {err}", file=sys.stderr)
        return 2
    labels = args.labels or [default_label(p, r) for p, r in zip(args.reports, reports)]
    print(markdown_table(labels, reports))
    if args.plot is not None:
        print(f"wrote {plot_comparison(labels, reports, args.plot)}")
    return 0
