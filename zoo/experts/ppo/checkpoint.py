"""PPO checkpoints without pickle: flax msgpack for arrays, JSON for the config and counters.

A run directory holds ``checkpoints/update_0000100/`` folders, each with ``params.msgpack``,
``opt_state.msgpack``, ``rollout.msgpack`` and ``meta.json``. The rollout state (env states and
their pool of fresh worlds, the observation, the GRU state, the episode counters, the PRNG key)
makes a resumed run the run it interrupted, update for update; it is the big file (~48 KB per
env: ~195 MB at 4,096 envs), so ``keep`` bounds the disk it takes.
A folder is written under a temporary name and renamed when complete, so a killed run never
leaves a half-written checkpoint behind.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

from flax import serialization

from zoo.experts.ppo.config import PPOConfig

FORMAT = "crafter-zoo-ppo-rnn/1"
META = "meta.json"
PARAMS = "params.msgpack"
OPT_STATE = "opt_state.msgpack"
ROLLOUT = "rollout.msgpack"


def checkpoint_dir(run_dir: str | Path, update: int) -> Path:
    return Path(run_dir) / "checkpoints" / f"update_{update:07d}"


def save_checkpoint(run_dir: str | Path, config: PPOConfig, update: int, params: Any,
                    opt_state: Any, keep: int, rollout: Any = None) -> Path:
    """Write the checkpoint of ``update`` and delete all but the newest ``keep``."""
    final = checkpoint_dir(run_dir, update)
    tmp = final.with_name(final.name + ".tmp")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    (tmp / PARAMS).write_bytes(serialization.to_bytes(params))
    (tmp / OPT_STATE).write_bytes(serialization.to_bytes(opt_state))
    if rollout is not None:
        (tmp / ROLLOUT).write_bytes(serialization.to_bytes(rollout))
    meta = {
        "format": FORMAT,
        "update": update,
        "env_steps": update * config.batch_size,
        "config": config.to_dict(),
    }
    (tmp / META).write_text(json.dumps(meta, indent=2) + "\n")
    shutil.rmtree(final, ignore_errors=True)
    tmp.rename(final)
    for old in list_checkpoints(run_dir)[:-keep]:
        shutil.rmtree(old)
    return final


def list_checkpoints(run_dir: str | Path) -> list[Path]:
    """Complete checkpoints of a run, oldest first."""
    root = Path(run_dir) / "checkpoints"
    if not root.is_dir():
        return []
    found = [p for p in root.glob("update_*") if p.suffix != ".tmp" and (p / META).is_file()]
    return sorted(found, key=lambda p: p.name)


def resolve_checkpoint(path: str | Path) -> Path:
    """A checkpoint folder itself, or the newest checkpoint of a run directory."""
    path = Path(path)
    if (path / META).is_file():
        return path
    found = list_checkpoints(path)
    if not found:
        raise FileNotFoundError(
            f"no PPO checkpoint at {path}: expected a folder with {META} or a run directory "
            f"with checkpoints/update_*/ (made by `zoo expert train`)"
        )
    return found[-1]


def read_meta(path: str | Path) -> tuple[dict, PPOConfig]:
    """The checkpoint's metadata and its run's config."""
    path = resolve_checkpoint(path)
    meta = json.loads((path / META).read_text())
    if meta.get("format") != FORMAT:
        raise ValueError(f"{path / META}: format {meta.get('format')!r}, expected {FORMAT!r}")
    return meta, PPOConfig.from_dict(meta["config"], source=str(path / META))


def load_params(path: str | Path, target: Any) -> Any:
    """Network parameters shaped like ``target`` (a freshly initialised tree)."""
    path = resolve_checkpoint(path)
    return serialization.from_bytes(target, (path / PARAMS).read_bytes())


def load_opt_state(path: str | Path, target: Any) -> Any:
    path = resolve_checkpoint(path)
    return serialization.from_bytes(target, (path / OPT_STATE).read_bytes())


def load_rollout(path: str | Path, target: Any) -> Any | None:
    """The rollout state saved with a checkpoint, shaped like ``target``; None when it has none
    (checkpoints written before it was saved)."""
    file = resolve_checkpoint(path) / ROLLOUT
    return serialization.from_bytes(target, file.read_bytes()) if file.is_file() else None
