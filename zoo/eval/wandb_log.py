"""`zoo eval --wandb`: the report, its plot and GIF as a W&B run (offline unless WANDB_MODE
says otherwise), so evaluations sit next to the training runs in one dashboard."""

from __future__ import annotations

import os
from pathlib import Path

SCALARS = {  # report key path -> W&B name
    ("crafter_score", "mean"): "eval/crafter_score",
    ("crafter_score", "std"): "eval/crafter_score_std",
    ("crafter_score", "pooled"): "eval/crafter_score_pooled",
    ("normalized_return", "mean"): "eval/return_percent",
    ("episode_length", "mean"): "eval/episode_length",
    ("success_percent",): "eval/task_success",
}


def report_scalars(report: dict) -> dict[str, float]:
    """The headline numbers of a ``zoo eval`` report (either kind) and each success rate."""
    scalars = {}
    for path, name in SCALARS.items():
        value = report
        for key in path:
            value = value.get(key) if isinstance(value, dict) else None
        if isinstance(value, (int, float)):
            scalars[name] = float(value)
    for achievement, rate in report.get("success_rates", {}).items():
        scalars[f"eval/success/{achievement}"] = float(rate)
    for k, sub in enumerate(report.get("subtasks", [])):
        scalars[f"eval/subtask/{k + 1}_{sub['instruction']}"] = float(sub["completed_percent"])
    return scalars


def log_report(report: dict, out_dir: Path) -> Path:
    """One W&B run named after ``out_dir`` holding the report's numbers, its success-rate
    table, ``achievements.png`` and ``episode.gif``; returns the run's local folder."""
    import wandb

    run = wandb.init(
        project=os.environ.get("WANDB_PROJECT", "crafter-zoo"),
        name=out_dir.name,
        dir=str(out_dir),
        mode=os.environ.get("WANDB_MODE", "offline"),
        job_type="eval",
        config={k: v for k, v in report.items() if isinstance(v, (str, int, float, bool))},
    )
    media = {}
    rates = report.get("success_rates")
    if rates:
        media["eval/success_rates"] = wandb.Table(
            columns=["achievement", "success %"], data=[[k, v] for k, v in rates.items()]
        )
    if (out_dir / "achievements.png").is_file():
        media["eval/achievements"] = wandb.Image(str(out_dir / "achievements.png"))
    if (out_dir / "episode.gif").is_file():
        media["eval/episode"] = wandb.Video(str(out_dir / "episode.gif"), format="gif")
    scalars = report_scalars(report)
    run.log(scalars | media)
    run.summary.update(scalars)
    folder = Path(run.dir).parent
    run.finish()
    return folder
