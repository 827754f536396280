"""The PPO loop shared by the three agents: rollout, GAE, clipped updates, logs, checkpoints.

A run directory holds ``config.yaml``, ``metrics.csv`` (one row per update; its success window
is ``zoo.rl.window.SeedOrderWindow``'s, not "the last 100 that ended"), ``episodes.csv`` (one
row per ended episode: the update it ended in, its seed index, success, sub-tasks, length),
optional W&B files, and ``checkpoints/update_*.pt`` with the trainable parameters, the
optimizer, the update and env-step counts, the episode counter, the sampling generator and the
sha256 of the frozen model under the trained parameters: ``--resume`` continues at the same env
step with the same optimizer state (``total_env_steps`` may grow, to extend a run; every other
setting must match). Episodes in flight at the checkpoint are dropped (not counted), as are
metrics and episode rows logged after it; the resumed run starts fresh episodes with the next
episode seeds and a fresh 100-episode success window.
"""

from __future__ import annotations

import csv
import math
import os
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
import torch
import yaml

from zoo.files import atomic_path
from zoo.models.sampling import sample_actions
from zoo.rl.agents import build_agent
from zoo.rl.config import RLConfig
from zoo.rl.policies import count_parameters
from zoo.rl.ppo import explained_variance, gae, ppo_loss
from zoo.rl.window import SeedOrderWindow
from zoo.weights.checkpoint_io import read_torch_file

COLUMNS = (
    "update", "env_steps", "episodes", "success_rate", "success_rate_100", "subtasks_100",
    "episode_length_100", "policy_loss", "value_loss", "entropy", "kl_ref", "approx_kl",
    "clip_fraction", "explained_variance", "lr", "env_steps_per_s", "env_share", "model_share",
    "update_share", "wall_seconds",
)
EPISODE_COLUMNS = ("update", "episode", "success", "subtasks", "length")
KEEP_CHECKPOINTS = 2


def list_checkpoints(out: Path) -> list[Path]:
    return sorted((out / "checkpoints").glob("update_*.pt"))


class Rollout:
    """Stored steps of one update, (N, T, ...) once stacked."""

    def __init__(self) -> None:
        self.columns: dict[str, list[torch.Tensor]] = {}

    def add(self, **values: torch.Tensor | None) -> None:
        for key, value in values.items():
            if value is not None:
                self.columns.setdefault(key, []).append(value)

    def stack(self) -> dict[str, torch.Tensor]:
        return {k: torch.stack(v, 1) for k, v in self.columns.items()}


def sample(logits: torch.Tensor, generator: torch.Generator) -> tuple[torch.Tensor, torch.Tensor]:
    """Actions (N,) drawn from softmax(logits) and their log-probabilities."""
    logp = torch.log_softmax(logits.float(), -1).cpu()
    actions = torch.from_numpy(sample_actions(logp, generator=generator, log_probs=True))
    return actions, logp.gather(1, actions[:, None])[:, 0]


def train_rl(
    config: RLConfig,
    out_dir: str | Path,
    resume: bool = False,
    use_wandb: bool = False,
    progress: bool = True,
) -> dict[str, Any] | None:
    """Train (or resume) one RL agent into ``out_dir``; returns the last update's record."""
    out = Path(out_dir)
    found = list_checkpoints(out)
    if found and not resume:
        raise FileExistsError(
            f"{out} already holds checkpoints ({found[-1].name}); pass --resume to continue "
            "that run or choose another --out"
        )
    saved = (read_torch_file(found[-1], expected="a `zoo rl train` checkpoint (update_*.pt)")
             if resume and found else None)
    if saved is not None:  # a resume may extend the run, nothing else
        diff = sorted(k for k, v in config.to_dict().items()
                      if saved["config"].get(k) != v and k != "total_env_steps")
        if diff:
            raise ValueError(f"{found[-1]} was trained with other settings: {diff} differ")
    start = saved["update"] if saved else 0
    torch.manual_seed(config.seed)
    env, policy = build_agent(
        config, saved["next_episode"] if saved else 0, sampling_seed=config.seed * 1_000_003 + start
    )
    params = [p for p in policy.parameters() if p.requires_grad]
    optimizer = torch.optim.Adam(params, lr=config.lr, eps=1e-5)
    generator = torch.Generator().manual_seed(config.seed)
    env_steps, wall, episodes = 0, 0.0, 0
    base = base_sha256(config)
    if saved:
        load_trainable(policy, saved, found[-1], base)
        _drop_rows_after(out / "metrics.csv", COLUMNS, saved["update"])
        _drop_rows_after(out / "episodes.csv", EPISODE_COLUMNS, saved["update"])
        optimizer.load_state_dict(saved["optimizer"])
        generator.set_state(saved["generator"])
        env_steps, wall, episodes = saved["env_steps"], saved["wall_seconds"], saved["episodes"]
    out.mkdir(parents=True, exist_ok=True)
    (out / "config.yaml").write_text(yaml.safe_dump(config.to_dict(), sort_keys=False))
    trainable, total, reference = count_parameters(policy)
    frozen_copy = f" (plus the frozen KL reference's {reference:,})" if reference else ""
    print(f"zoo rl: {config.agent} on {config.task} ({config.env}), {trainable:,} of the acting "
          f"policy's {total:,} parameters trained ({100 * trainable / total:.1f}%){frozen_copy}, "
          f"updates {start}..{config.num_updates}")
    wandb_run = _start_wandb(config, out, start, trainable) if use_wandb else None

    from tqdm import tqdm

    bar = tqdm(total=config.num_updates, initial=start, unit="update", disable=not progress,
               desc=f"{config.agent} {config.task}")
    recent = SeedOrderWindow(100, start=env.next_episode)
    n = config.num_envs
    t = env.reset()
    x, first = policy.preprocess(t.obs), torch.as_tensor(t.first)
    state = policy.initial_state(n)
    record = None
    with _csv_log(out / "metrics.csv", COLUMNS) as writer, \
            _csv_log(out / "episodes.csv", EPISODE_COLUMNS) as episode_writer:
        for update in range(start, config.num_updates):
            lr = config.lr * (1 - update / config.num_updates) if config.anneal_lr else config.lr
            for group in optimizer.param_groups:
                group["lr"] = lr
            began = time.perf_counter()
            env_time = model_time = 0.0
            finished = []
            rollout, state0 = Rollout(), state
            for _ in range(config.num_steps):
                tick = time.perf_counter()
                with torch.no_grad():
                    step = policy.step(x, first, state)
                actions, logp = sample(step.logits, generator)
                tock = time.perf_counter()
                tr = env.step(actions.numpy())
                env_time += time.perf_counter() - tock - tr.model_seconds
                model_time += tock - tick + tr.model_seconds
                rollout.add(
                    x=x, first=first, action=actions, logp=logp, value=step.value.float().cpu(),
                    reward=torch.as_tensor(tr.reward), done=torch.as_tensor(tr.done),
                    ref_logits=None if step.ref_logits is None else step.ref_logits.cpu(),
                )
                env_steps += tr.env_steps
                finished += tr.finished
                tick = time.perf_counter()
                state = step.state
                x, first = policy.preprocess(tr.obs), torch.as_tensor(tr.first)
                model_time += time.perf_counter() - tick
            with torch.no_grad():
                last_value = policy.step(x, first, state).value.float().cpu()
            data = rollout.stack()
            advantages, returns = gae(
                data["reward"], data["value"], data["done"], last_value,
                config.gamma, config.gae_lambda,
            )
            tick = time.perf_counter()
            losses = _optimize(config, policy, optimizer, params, data, advantages, returns,
                               state0, generator)
            update_time = time.perf_counter() - tick
            seconds = time.perf_counter() - began
            wall += seconds
            recent.add(finished)
            episodes += len(finished)
            record = {
                "update": update + 1,
                "env_steps": env_steps,
                "episodes": episodes,
                "success_rate": _mean([e.success for e in finished]),
                "success_rate_100": _mean([e.success for e in recent.episodes]),
                "subtasks_100": _mean([e.subtasks_done for e in recent.episodes]),
                "episode_length_100": _mean([e.length for e in recent.episodes]),
                **losses,
                "explained_variance": explained_variance(data["value"], returns),
                "lr": lr,
                "env_steps_per_s": config.env_steps_per_update / seconds,
                "env_share": env_time / seconds,
                "model_share": model_time / seconds,
                "update_share": update_time / seconds,
                "wall_seconds": wall,
                "trainable_parameters": trainable,  # not in metrics.csv: the same every row
                "total_parameters": total,  # the acting policy's, without the KL reference
                "reference_parameters": reference,
            }
            episode_writer.writerows(
                {"update": update + 1, "episode": e.episode, "success": int(e.success),
                 "subtasks": e.subtasks_done, "length": e.length} for e in finished
            )
            writer.writerow({k: _csv(record[k]) for k in COLUMNS})
            if wandb_run is not None:
                wandb_run.log({k: v for k, v in record.items() if _finite(v)}, step=env_steps)
            bar.update(1)
            bar.set_postfix(success=_fmt(record["success_rate_100"]),
                            sps=f"{record['env_steps_per_s']:.0f}")
            if (update + 1) % config.checkpoint_every == 0 or update + 1 == config.num_updates:
                counts = {"update": update + 1, "env_steps": env_steps, "episodes": episodes,
                          "next_episode": env.next_episode, "wall_seconds": wall,
                          "base_sha256": base}
                _save(out, config, policy, optimizer, generator, counts)
    bar.close()
    if wandb_run is not None:
        wandb_run.finish()
    return record


def _optimize(config, policy, optimizer, params, data, advantages, returns, state0, generator):
    n = config.num_envs
    size = n // config.num_minibatches
    sums: dict[str, float] = {}
    count = 0
    for _ in range(config.update_epochs):
        order = torch.randperm(n, generator=generator)
        for k in range(config.num_minibatches):
            idx = order[k * size:(k + 1) * size]
            logits, values = policy.evaluate(
                data["x"][idx], data["first"][idx], policy.select_state(state0, idx)
            )
            loss = ppo_loss(
                logits, values.float(), data["action"][idx], data["logp"][idx],
                data["value"][idx], advantages[idx], returns[idx], config.clip_eps,
                config.vf_coef, config.ent_coef,
                data["ref_logits"][idx] if "ref_logits" in data else None, config.kl_coef,
            )
            optimizer.zero_grad()
            loss.total.backward()
            torch.nn.utils.clip_grad_norm_(params, config.max_grad_norm)
            optimizer.step()
            for name in ("policy", "value", "entropy", "kl_ref", "approx_kl", "clip_fraction"):
                sums[name] = sums.get(name, 0.0) + float(getattr(loss, name).detach())
            count += 1
    return {
        "policy_loss": sums["policy"] / count, "value_loss": sums["value"] / count,
        "entropy": sums["entropy"] / count, "kl_ref": sums["kl_ref"] / count,
        "approx_kl": sums["approx_kl"] / count, "clip_fraction": sums["clip_fraction"] / count,
    }


@contextmanager
def _csv_log(path: Path, columns: tuple[str, ...]):
    """An appending CSV writer (header on a new file), line-buffered so a killed run keeps
    every row it logged."""
    new_file = not path.exists()
    with path.open("a", newline="", buffering=1) as f:
        writer = csv.DictWriter(f, columns)
        if new_file:
            writer.writeheader()
        yield writer


def _drop_rows_after(path: Path, columns: tuple[str, ...], update: int) -> None:
    """Forget the rows a killed run logged after its last checkpoint: the resume redoes them."""
    if not path.exists():  # a run from before episodes.csv existed
        return
    with path.open(newline="") as f:
        rows = [r for r in csv.DictReader(f) if int(r["update"]) <= update]
    with path.open("w", newline="") as f:
        writer = csv.DictWriter(f, columns)
        writer.writeheader()
        writer.writerows(rows)


def _save(out, config, policy, optimizer, generator, counts: dict[str, Any]) -> None:
    folder = out / "checkpoints"
    update = counts["update"]
    folder.mkdir(parents=True, exist_ok=True)
    trainable = {k: v for k, v in policy.state_dict().items()
                 if k in {n for n, p in policy.named_parameters() if p.requires_grad}}
    payload = {
        "config": config.to_dict(), **counts, "trainable": trainable,
        "optimizer": optimizer.state_dict(), "generator": generator.get_state(),
    }
    with atomic_path(folder / f"update_{update:06d}.pt") as tmp:
        torch.save(payload, tmp)
    for old in list_checkpoints(out)[:-KEEP_CHECKPOINTS]:
        old.unlink()


def load_trainable(policy: torch.nn.Module, saved: dict, path: Path, base: str | None) -> None:
    """Put a checkpoint's trained parameters into ``policy`` (built from the same config), after
    checking that they fit it and that its frozen base model (sha256 ``base``) is the one they
    were trained on."""
    if saved.get("base_sha256") not in (None, base):
        raise ValueError(
            f"{path} was trained on other weights than its checkpoint path holds now (sha256 "
            f"{saved['base_sha256'][:12]}..., now {str(base)[:12]}...): restore those weights"
        )
    unexpected = policy.load_state_dict(saved["trainable"], strict=False).unexpected_keys
    absent = sorted({n for n, p in policy.named_parameters() if p.requires_grad}
                    - set(saved["trainable"]))
    if unexpected or absent:
        raise ValueError(f"{path} does not fit this agent: unexpected parameters "
                         f"{unexpected[:5]}, trained parameters it lacks {absent[:5]}")


def base_sha256(config: RLConfig) -> str | None:
    """Fingerprint of the frozen model a run's trainable parameters sit on (C-VPT, C-Steve-1),
    so loading them onto other weights that share the path is refused."""
    if config.checkpoint is None:
        return None
    from zoo.weights.export import checkpoint_sha256

    return checkpoint_sha256(config.checkpoint)


def _mean(values: list) -> float:
    return float(np.mean(values)) if values else math.nan


def _finite(value: Any) -> bool:
    return value is not None and not (isinstance(value, float) and not math.isfinite(value))


def _csv(value: Any) -> Any:
    return "" if not _finite(value) else value


def _fmt(value: float) -> str:
    return "-" if math.isnan(value) else f"{value:.2f}"


def _start_wandb(config: RLConfig, out: Path, start: int, trainable: int):
    import wandb

    return wandb.init(
        project=os.environ.get("WANDB_PROJECT", "crafter-zoo"),
        name=out.name,
        dir=str(out),
        config=config.to_dict() | {"resumed_from_update": start, "trainable_parameters": trainable},
        mode=os.environ.get("WANDB_MODE", "offline"),
        group=f"rl/{config.agent}_{config.task}",
    )
