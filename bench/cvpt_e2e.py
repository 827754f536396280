"""The CPU recipe's real `zoo fit` loop, timed: the ``end_to_end`` key of bench/results/cvpt.json.

``run_fit`` derives a config from the recipe (configs/cvpt_tiny_cpu.yaml) with a few overrides:
one data folder, a short ``max_steps``, epochs of ``epoch_steps`` batches (the recipe validates
and checkpoints at every epoch end, so this keeps its validation and checkpoints at a shorter
cadence), the CSV logger alone (W&B's offline writer left out), Lightning's SimpleProfiler and
``StepTimer``. It runs `zoo fit` on that config in a subprocess, as a user does. ``summarize``
turns the timestamps into steady-state seconds per step (warm-up and epoch boundaries left
out), splits a step into the data-loader wait, Lightning's training batch and the loop between
batches, and adds the measured cost of an epoch boundary (validation, checkpoints, the loader's
next epoch) at the recipe's cadence. At the recipe's seq_len == tbptt_len a batch is one
optimizer step.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from statistics import mean, median
from typing import Any

import yaml
from lightning.pytorch import Callback, LightningModule, Trainer

BENCH = Path(__file__).resolve().parent
FETCH = "[_TrainingEpochLoop].train_dataloader_next"  # SimpleProfiler's action names
BATCH = "run_training_batch"
CHECKPOINT = "[Callback]ModelCheckpoint"


class StepTimer(Callback):
    """Timestamps every training batch and validation; writes them as JSON when fit ends.

    Each batch also takes the profiler's newest data-loader fetch (Lightning fetches the next
    batch just before this one starts) and its ``run_training_batch`` duration."""

    def __init__(self, out: str) -> None:
        self.out = out
        self.steps: list[dict[str, float]] = []
        self.validations: list[dict[str, float]] = []
        self._seen: dict[str, int] = {}
        self._start = 0.0
        self._validation: dict[str, float] = {}

    def _newest(self, trainer: Trainer, action: str) -> float:
        """The duration of ``action`` recorded since the last call (0 if none was)."""
        durations = getattr(trainer.profiler, "recorded_durations", {}).get(action, [])
        new = len(durations) > self._seen.get(action, 0)
        self._seen[action] = len(durations)
        return durations[-1] if new else 0.0

    def on_train_batch_start(self, trainer: Trainer, pl_module: LightningModule, batch: Any,
                             batch_idx: int) -> None:
        self._start = time.perf_counter()

    def on_train_batch_end(self, trainer: Trainer, pl_module: LightningModule, outputs: Any,
                           batch: Any, batch_idx: int) -> None:
        self.steps.append({
            "step": trainer.global_step, "batch_idx": batch_idx, "start": self._start,
            "end": time.perf_counter(), "fetch_s": self._newest(trainer, FETCH),
            "batch_s": self._newest(trainer, BATCH),
        })

    def on_validation_start(self, trainer: Trainer, pl_module: LightningModule) -> None:
        if not trainer.sanity_checking:
            self._validation = {"after_step": trainer.global_step, "start": time.perf_counter(),
                                "batches": 0}

    def on_validation_batch_end(self, trainer: Trainer, pl_module: LightningModule, outputs: Any,
                                batch: Any, batch_idx: int, dataloader_idx: int = 0) -> None:
        if not trainer.sanity_checking:
            self._validation["batches"] += 1

    def on_validation_end(self, trainer: Trainer, pl_module: LightningModule) -> None:
        if not trainer.sanity_checking:
            self.validations.append({**self._validation, "end": time.perf_counter()})

    def on_train_end(self, trainer: Trainer, pl_module: LightningModule) -> None:
        durations = getattr(trainer.profiler, "recorded_durations", {})
        totals = {action: [len(d), sum(d)] for action, d in durations.items()}
        Path(self.out).write_text(json.dumps(
            {"steps": self.steps, "validations": self.validations, "profiler_totals": totals}))


def set_dotted(config: dict, assignment: str) -> None:
    """Apply ``a.b.c=VALUE`` (VALUE read as YAML) to a nested config dict."""
    key, sep, value = assignment.partition("=")
    if not sep or not key:
        raise ValueError(f"--e2e-set {assignment!r}: expected KEY.PATH=VALUE")
    *parents, leaf = key.split(".")
    node = config
    for name in parents:
        node = node.setdefault(name, {})
    node[leaf] = yaml.safe_load(value)


def epoch_batches(train_batches_per_epoch: int, workers: int) -> int:
    """Batches in one epoch: CrafterPlayDataModule gives each worker an equal share."""
    return max(1, train_batches_per_epoch // max(1, workers)) * max(1, workers)


def derived_config(recipe: dict, data: str, max_steps: int, epoch_steps: int, root_dir: str,
                   timer_out: str, overrides: list[str]) -> dict:
    """The recipe with this benchmark's overrides (see the module docstring)."""
    config = json.loads(json.dumps(recipe))  # a deep copy
    trainer = config["trainer"]
    loggers = trainer.get("logger") or []
    csv = [lg for lg in (loggers if isinstance(loggers, list) else [loggers])
           if isinstance(lg, dict) and lg.get("class_path", "").endswith("CSVLogger")]
    workers = config["data"]["init_args"].get("num_workers", 0)
    trainer.update(
        default_root_dir=root_dir, max_steps=max_steps, logger=csv or False,
        profiler="simple",
        callbacks=[*(trainer.get("callbacks") or []),
                   {"class_path": "cvpt_e2e.StepTimer", "init_args": {"out": timer_out}}],
    )
    config["data"]["init_args"].update(
        root=data, sources=None, train_batches_per_epoch=epoch_steps * max(1, workers))
    for assignment in overrides:
        set_dotted(config, assignment)
    return config


def summarize(record: dict, warmup: int, frames_per_step: int, recipe_epoch_steps: int) -> dict:
    """Steady-state step time and its parts from a ``StepTimer`` record, skipping the first
    ``warmup`` steps; each epoch's first step carries that epoch boundary, whose extra time
    (over a steady step) is reported apart and spread over ``recipe_epoch_steps``."""
    steps = record["steps"]
    if len(steps) < warmup + 3:
        raise ValueError(f"{len(steps)} steps timed: need at least warmup + 3 = {warmup + 3}")
    intervals = [(cur, cur["end"] - prev["end"]) for prev, cur in zip(steps, steps[1:])][warmup:]
    steady = [(s, dt) for s, dt in intervals if s["batch_idx"] != 0]
    if not steady:
        raise ValueError("every timed step starts an epoch: raise the epoch length")
    step_s = mean(dt for _, dt in steady)
    fetch_s = mean(s["fetch_s"] for s, _ in steady)
    batch_s = mean(s["batch_s"] for s, _ in steady)
    boundary_extra = [dt - step_s for s, dt in intervals if s["batch_idx"] == 0]
    validations = record["validations"]
    checkpoint_total = sum(total for action, (_, total) in record["profiler_totals"].items()
                           if action.startswith(CHECKPOINT))
    epochs = max(1, len(validations))
    boundary_s = mean(boundary_extra) if boundary_extra else None
    recipe_step_s = step_s + (boundary_s or 0.0) / recipe_epoch_steps
    window_s = steps[-1]["end"] - steps[warmup]["end"]
    window_steps = len(steps) - 1 - warmup
    return {
        "steps_timed": len(steady), "warmup_steps": warmup, "frames_per_step": frames_per_step,
        "s_per_step": step_s, "s_per_step_median": median(dt for _, dt in steady),
        "frames_per_s": frames_per_step / step_s,
        "data_wait_s_per_step": fetch_s, "training_batch_s_per_step": batch_s,
        "loop_between_batches_s_per_step": step_s - fetch_s - batch_s,
        "epoch_boundaries_timed": len(boundary_extra), "epoch_boundary_extra_s": boundary_s,
        "validation_s": mean(v["end"] - v["start"] for v in validations) if validations else None,
        "validation_batches": [v["batches"] for v in validations],
        "checkpoint_s_per_epoch": checkpoint_total / epochs,
        "window": {"steps": window_steps, "seconds": window_s,
                   "frames_per_s": window_steps * frames_per_step / window_s},
        "recipe_epoch_steps": recipe_epoch_steps, "recipe_s_per_step": recipe_step_s,
        "recipe_frames_per_s": frames_per_step / recipe_step_s,
    }


def run_fit(recipe_path: Path, data: str, warmup: int, steps: int, epoch_steps: int,
            overrides: list[str], code_root: Path | None = None) -> dict:
    """`zoo fit` on the derived recipe in a subprocess; ``summarize`` of its timestamps.
    ``code_root``: a checkout whose package code the run imports instead of this one (an
    older commit: the baseline of a change)."""
    recipe = yaml.safe_load(recipe_path.read_text())
    data_args, model_args = recipe["data"]["init_args"], recipe["model"]["init_args"]
    frames = data_args["batch_size"] * data_args["seq_len"]
    recipe_epoch = epoch_batches(data_args["train_batches_per_epoch"], data_args["num_workers"])
    runs = Path(recipe["trainer"].get("default_root_dir") or "runs/x").parent.resolve()
    if code_root:  # `python -m` imports from its working directory first: run in code_root
        data = str(Path(data).resolve())
    runs.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="bench_cvpt_e2e_", dir=runs) as tmp:
        timer_out = Path(tmp) / "steps.json"
        config = derived_config(recipe, data, warmup + steps, epoch_steps, tmp, str(timer_out),
                                overrides)
        config_path = Path(tmp) / "config.yaml"
        config_path.write_text(yaml.safe_dump(config, sort_keys=False))
        env = {k: v for k, v in os.environ.items() if k != "ZOO_RUN_DIR"}
        paths = (str(code_root) if code_root else None, str(BENCH), env.get("PYTHONPATH"))
        env["PYTHONPATH"] = os.pathsep.join(p for p in paths if p)
        command = [sys.executable, "-m", "zoo.cli", "fit", "--config", str(config_path)]
        start = time.perf_counter()
        done = subprocess.run(command, env=env, capture_output=True, text=True, cwd=code_root)
        wall = time.perf_counter() - start
        if done.returncode or not timer_out.exists():
            raise RuntimeError(f"zoo fit exited {done.returncode}:\n{done.stderr[-4000:]}")
        record = json.loads(timer_out.read_text())
    summary = summarize(record, warmup, frames, recipe_epoch)
    return {
        "command": f"zoo fit --config {recipe_path} (derived: see overrides)",
        "code_root": str(code_root) if code_root else None,
        "overrides": {"data": data, "max_steps": warmup + steps, "epoch_steps": epoch_steps,
                      "logger": "CSVLogger only", "profiler": "SimpleProfiler",
                      "set": list(overrides)},
        "precision": recipe["trainer"].get("precision"),
        "num_workers": data_args["num_workers"],
        "limit_val_batches": recipe["trainer"].get("limit_val_batches"),
        "tbptt_len": model_args.get("tbptt_len"), "subprocess_wall_s": wall, **summary,
    }


def compare_recipes(old: Path, new: Path, data: str, warmup: int, steps: int, epoch_steps: int,
                    overrides: list[str], rounds: int = 2, old_code: Path | None = None) -> dict:
    """``run_fit`` of two recipes taking turns (old, new, old, new, ...) on the same data, so
    load drifts hit both alike; the speedup is the ratio of their mean steady frames/s (at
    each recipe's own validation cadence, and without it). ``old_code``: the old recipe runs
    on that checkout's package code (the speedup is then the whole change's)."""
    runs: dict[str, list[dict]] = {"old": [], "new": []}
    for _ in range(rounds):
        for name, path, code in (("old", old, old_code), ("new", new, None)):
            runs[name].append(run_fit(path, data, warmup, steps, epoch_steps, overrides, code))

    def rate(name: str, key: str) -> float:
        return mean(run[key] for run in runs[name])

    return {
        "old": {"config": str(old), "runs": runs["old"]},
        "new": {"config": str(new), "runs": runs["new"]},
        "rounds": rounds, "data": data, "old_code": str(old_code) if old_code else None,
        "frames_per_s": {name: rate(name, "frames_per_s") for name in runs},
        "recipe_frames_per_s": {name: rate(name, "recipe_frames_per_s") for name in runs},
        "speedup": rate("new", "frames_per_s") / rate("old", "frames_per_s"),
        "recipe_speedup": rate("new", "recipe_frames_per_s") / rate("old", "recipe_frames_per_s"),
    }


__all__ = ["StepTimer", "compare_recipes", "derived_config", "epoch_batches", "run_fit",
           "set_dotted", "summarize"]
