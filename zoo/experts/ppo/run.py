"""``train_ppo``: the host side of a run — blocks of jitted updates, logs, checkpoints, resume.

Each block's metrics are printed, appended to ``<out>/metrics.jsonl`` and, when asked, sent to
W&B (offline unless ``WANDB_MODE`` says otherwise); the first block's ``sps`` includes
compilation. A resumed run restores parameters, optimizer state and the rollout state (envs,
GRU state, episode counters, PRNG key) from the newest checkpoint, so it continues exactly as
the interrupted run would have, then runs on to the config's total number of updates. A
checkpoint without a rollout state (an older format) resumes on fresh episodes.
"""

from __future__ import annotations

import json
import math
import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jax
import numpy as np
import yaml

from zoo.envs.craftax_env import enable_compilation_cache
from zoo.experts.ppo.checkpoint import (
    list_checkpoints,
    load_opt_state,
    load_params,
    load_rollout,
    read_meta,
    save_checkpoint,
)
from zoo.experts.ppo.config import PPOConfig
from zoo.experts.ppo.train import EpisodeTally, Runner, TrainState, build_trainer, learning_rate
from zoo.metrics import crafter_score

LOSS_KEYS = ("loss", "policy_loss", "value_loss", "entropy", "approx_kl", "clip_frac")


def block_record(config: PPOConfig, update: int, seconds: float, num_updates: int,
                 stats: dict[str, np.ndarray], tally: EpisodeTally) -> dict[str, Any]:
    """One metrics.jsonl line: episode means over the episodes that ended in the block."""
    episodes = float(tally.episodes)

    def per_episode(total) -> float | None:
        return float(total) / episodes if episodes else None

    success = 100.0 * np.asarray(tally.unlocked) / max(episodes, 1.0)
    record: dict[str, Any] = {
        "update": update,
        "env_steps": update * config.batch_size,
        "sps": num_updates * config.batch_size / seconds,
        "episodes": int(episodes),
        "episode_return": per_episode(tally.return_sum),
        "achievements": per_episode(np.sum(tally.unlocked)),
        "episode_length": per_episode(tally.length_sum),
        "death_rate": per_episode(tally.deaths),
        "crafter_score": crafter_score(success) if episodes else None,
        "lr": float(learning_rate(config, update - 1)),
    }
    record.update({k: float(np.mean(stats[k])) for k in LOSS_KEYS})
    return record


def _format(record: dict[str, Any], total_updates: int) -> str:
    def num(key: str, fmt: str) -> str:
        value = record[key]
        return "-" if value is None else format(value, fmt)

    return (
        f"update {record['update']}/{total_updates} steps {record['env_steps']:,} "
        f"sps {record['sps']:,.0f} | episodes {record['episodes']} "
        f"return {num('episode_return', '.2f')} achievements {num('achievements', '.2f')} "
        f"length {num('episode_length', '.0f')} deaths {num('death_rate', '.2f')} "
        f"score {num('crafter_score', '.2f')} | loss {record['loss']:.4f} "
        f"value {record['value_loss']:.4f} entropy {record['entropy']:.3f} "
        f"kl {record['approx_kl']:.4f}"
    )


def _config_diff(saved: PPOConfig, given: PPOConfig) -> list[str]:
    a, b = saved.to_dict(), given.to_dict()
    return [f"{k}: checkpoint {a[k]!r} vs given {b[k]!r}" for k in a if a[k] != b[k]]


def train_ppo(config: PPOConfig, out_dir: str | Path, resume: bool = False,
              use_wandb: bool = False, log: Callable[[str], None] = print) -> dict[str, Any] | None:
    """Train (or resume) a PPO-RNN expert into ``out_dir``; returns the last block's record."""
    enable_compilation_cache()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    found = list_checkpoints(out)
    if found and not resume:
        raise FileExistsError(
            f"{out} already holds checkpoints ({found[-1].name}); pass --resume to continue "
            f"that run or choose another --out"
        )
    trainer = build_trainer(config)
    key = jax.random.PRNGKey(config.seed)
    start = 0
    if found:
        meta, saved = read_meta(found[-1])
        diff = _config_diff(saved, config)
        if diff:
            raise ValueError(
                f"cannot resume {found[-1]} with a different config: {'; '.join(diff)}"
            )
        start = int(meta["update"])
        runner = trainer.init(jax.random.fold_in(key, start))
        params = load_params(found[-1], runner.train.params)
        opt_state = load_opt_state(found[-1], runner.train.opt_state)
        rollout = load_rollout(found[-1], tuple(runner[1:]))
        if rollout is not None:
            runner = Runner(TrainState(params, opt_state), *rollout)
        else:
            runner = runner._replace(train=TrainState(params, opt_state))
            log(f"{found[-1]} holds no rollout state: resuming on fresh episodes")
        log(f"resuming from {found[-1]} (update {start}, {start * config.batch_size:,} env steps)")
    else:
        (out / "config.yaml").write_text(yaml.safe_dump(config.to_dict(), sort_keys=False))
        runner = trainer.init(key)

    wandb_run = _start_wandb(config, out, start) if use_wandb else None
    record = None
    update = start
    with (out / "metrics.jsonl").open("a") as metrics:
        while update < config.num_updates:
            block = min(config.updates_per_block, config.num_updates - update)
            began = time.perf_counter()
            runner, stats = trainer.update_block(runner, block)
            stats, tally = jax.device_get((stats, runner.tally))
            seconds = time.perf_counter() - began
            update += block
            record = block_record(config, update, seconds, block, stats, tally)
            log(_format(record, config.num_updates))
            metrics.write(json.dumps(_finite(record)) + "\n")
            metrics.flush()
            if wandb_run is not None:
                logged = {k: v for k, v in record.items() if v is not None}
                wandb_run.log(logged, step=record["env_steps"])
            if update % config.checkpoint_every_updates == 0 or update == config.num_updates:
                path = save_checkpoint(out, config, update, runner.train.params,
                                       runner.train.opt_state, config.keep_checkpoints,
                                       rollout=tuple(runner[1:]))
                log(f"saved {path}")
    if wandb_run is not None:
        wandb_run.finish()
    return record


def _finite(record: dict[str, Any]) -> dict[str, Any]:
    """JSON has no NaN: write a non-finite float as null."""
    def clean(v: Any) -> Any:
        return None if isinstance(v, float) and not math.isfinite(v) else v

    return {k: clean(v) for k, v in record.items()}


def _start_wandb(config: PPOConfig, out: Path, start: int):
    import wandb

    return wandb.init(
        project=os.environ.get("WANDB_PROJECT", "crafter-zoo"),
        name=out.name,
        dir=str(out),
        config=config.to_dict() | {"resumed_from_update": start},
        mode=os.environ.get("WANDB_MODE", "offline"),
    )
