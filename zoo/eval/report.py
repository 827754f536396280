"""Turn episode results into the files an evaluation leaves behind.

``out_dir/report.json`` (metrics + run metadata), ``stats.jsonl`` (crafter's format, so
crafter's own analysis scripts agree with us), ``achievements.png`` and ``episode.gif``.
"""

from __future__ import annotations

import json
from datetime import datetime, timezone
from importlib import metadata
from pathlib import Path

import numpy as np

from zoo.envs.constants import ACHIEVEMENT_NAMES
from zoo.eval.death import death_shares
from zoo.eval.plots import plot_success_rates, write_gif
from zoo.eval.rollout import EpisodeResult
from zoo.metrics import chunked, crafter_score, normalized_return, success_rates
from zoo.eval.stats import write_stats

PAPER_CHUNKS = 5  # the paper: 100 episodes in 5 chunks of 20, mean ± std over chunks


def _spread(values: np.ndarray) -> dict:
    values = np.asarray(values, np.float64)
    return {
        "mean": float(values.mean()),
        "std": float(values.std()),
        "min": float(values.min()),
        "max": float(values.max()),
    }


def summarize(results: list[EpisodeResult], chunks: int = PAPER_CHUNKS) -> dict:
    """Metrics of a set of episodes; with fewer episodes than ``chunks``, one chunk per episode."""
    if not results:
        raise ValueError("no episode results to summarize")
    unlocks = np.stack([r.unlocked for r in results]).astype(bool)
    returns = np.array([r.episode_return for r in results], np.float64)
    lengths = np.array([r.length for r in results], np.int64)
    unlock_steps = np.stack([r.unlock_step for r in results])
    chunks = min(chunks, len(results))
    score = chunked(lambda u: crafter_score(success_rates(u)), unlocks, chunks)
    norm_return = chunked(lambda r: float(normalized_return(r).mean()), returns, chunks)
    rates = success_rates(unlocks)
    median_unlock = {}
    for i, name in enumerate(ACHIEVEMENT_NAMES):
        steps = unlock_steps[:, i][unlock_steps[:, i] >= 0]
        median_unlock[name] = float(np.median(steps)) if len(steps) else None
    return {
        "episodes": len(results),
        "chunks": chunks,
        "crafter_score": score.to_dict(),
        "normalized_return": norm_return.to_dict(),
        "return": _spread(returns),
        "episode_length": _spread(lengths),
        "success_rates": dict(zip(ACHIEVEMENT_NAMES, rates.tolist())),
        "median_unlock_step": median_unlock,
        "episode_end_percent": death_shares([r.death for r in results]),
    }


def _zoo_version() -> str:
    try:
        return metadata.version("crafter-zoo")
    except metadata.PackageNotFoundError:
        return "unknown"


def write_report(
    results: list[EpisodeResult], out_dir: str | Path, meta: dict, gif_scale: int = 2
) -> dict:
    """Write report.json, stats.jsonl, achievements.png and (if frames were kept) episode.gif.

    ``meta`` (env, agent, seed, timestamps, ...) is stored at the top level of report.json
    beside the metrics; a key that clashes with a metric is an error. Returns the report.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    results = sorted(results, key=lambda r: r.index)
    report = summarize(results)
    clashes = sorted(set(meta) & (set(report) | {"zoo_version", "written_at", "files"}))
    if clashes:
        raise ValueError(f"meta keys {clashes} clash with report fields; rename them")
    report.update(meta)
    report["zoo_version"] = _zoo_version()
    report["written_at"] = datetime.now(timezone.utc).isoformat(timespec="seconds")

    files = ["report.json", "stats.jsonl", "achievements.png"]
    write_stats(
        out_dir / "stats.jsonl",
        np.stack([r.unlocked for r in results]),
        np.array([r.episode_return for r in results]),
        np.array([r.length for r in results]),
    )
    score = report["crafter_score"]
    title = (
        f"{meta.get('agent', 'agent')} in {meta.get('env', 'env')}: Crafter Score "
        f"{score['mean']:.1f} ± {score['std']:.1f} ({report['episodes']} episodes)"
    )
    plot_success_rates(report["success_rates"], title, out_dir / "achievements.png")
    gif_episode = next((r for r in results if r.frames is not None), None)
    if gif_episode is not None:
        write_gif(gif_episode.frames, out_dir / "episode.gif", scale=gif_scale)
        report["gif_episode"] = gif_episode.index
        files.append("episode.gif")
    report["files"] = files
    (out_dir / "report.json").write_text(json.dumps(report, indent=2) + "\n")
    return report


def format_table(report: dict) -> str:
    """A compact plain-text summary of a report for the terminal."""
    score, ret = report["crafter_score"], report["normalized_return"]
    length = report["episode_length"]
    sizes = sorted(set(score["chunk_sizes"]))
    size_text = "/".join(str(s) for s in sizes)
    lines = [
        f"Crafter Score  {score['mean']:6.2f} ± {score['std']:5.2f}"
        f"   (pooled {score['pooled']:.2f})",
        f"Return         {ret['mean']:6.2f} ± {ret['std']:5.2f} % (pooled {ret['pooled']:.2f} %,"
        f" raw {report['return']['mean']:.2f})",
        f"episodes {report['episodes']} in {report['chunks']} chunks of {size_text};"
        f" length mean {length['mean']:.0f} (min {length['min']:.0f}, max {length['max']:.0f})",
        "episodes ended by: " + ", ".join(
            f"{cause} {share:.0f}%" for cause, share in report["episode_end_percent"].items() if share
        ),
        "",
        f"{'achievement':<20} {'success %':>9}",
    ]
    lines += [f"{name:<20} {rate:9.1f}" for name, rate in report["success_rates"].items()]
    return "\n".join(lines)
