"""The paper's training stages as their configs set them, and the paper's reported runs.

A ``Stage`` holds what the projection needs from a config: per-device batch, devices, precision,
steps and the unit a step's work is counted in. Light on purpose (no torch): ``zoo scale
--help`` lists the stage names from here. ``modules.py`` builds and steps a stage's module.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import yaml

# config file stem -> (kind, what one unit of work is)
STAGES: dict[str, tuple[str, str]] = {
    "cvpt_tiny": ("sequence", "frame"),
    "cvpt_base": ("sequence", "frame"),
    "cvpt_large": ("sequence", "frame"),
    "cclip": ("cclip", "clip"),
    "csteve1": ("sequence", "frame"),
    "prior": ("prior", "pair"),
    "expert_ppo": ("ppo", "env step"),
}
QUICK_STAGES = ("prior", "cvpt_tiny")


@dataclass(frozen=True)
class PaperRun:
    """A run the paper reports: wall hours on ``gpus`` x ``gpu`` (a key of project.GPUS)."""

    hours: float
    gpus: int
    gpu: str
    source: str
    units: float | None = None  # work of the paper's run when it differs from the config's


PAPER: dict[str, PaperRun] = {
    "cvpt_tiny": PaperRun(7.0, 4, "rtx4090", "Appendix, C-VPT training details"),
    "cvpt_base": PaperRun(8.5, 4, "rtx4090", "Appendix, C-VPT training details"),
    "cvpt_large": PaperRun(25.0, 8, "a6000", "Appendix, C-VPT training details"),
    "csteve1": PaperRun(
        1.0, 8, "rtx4090", "Appendix, C-Steve-1 training details ('about an hour')"
    ),
    "expert_ppo": PaperRun(
        10.0, 1, "rtx4090", "Appendix, expert policy training; §5 says 10B steps in ~10 GPU-hours",
        units=1e10,
    ),
}


@dataclass(frozen=True)
class Stage:
    """One training stage at the paper's scale, as its config sets it."""

    name: str
    kind: str  # sequence, cclip, prior, ppo
    unit: str
    path: Path
    config: dict
    per_device_batch: int  # samples (sequences, clips, pairs, envs) per device per batch
    units_per_sample: int  # units of one sample in one optimizer step (TBPTT window frames)
    samples_per_batch_len: int  # sequence length / window: optimizer steps per loaded batch
    devices: int
    precision: str
    max_steps: int  # optimizer steps (PPO: updates, each a rollout and its epochs)
    total_units: float  # units of work of the whole run
    grad_clip: float | None
    data: str | None  # the dataset a DataLoader decodes: crafterplay, craftercaption or None

    @property
    def mixed(self) -> bool:
        """bf16/fp16 autocast over fp32 master weights (Lightning's ``*-mixed``)."""
        return self.precision.endswith("-mixed")

    @property
    def paper(self) -> PaperRun | None:
        return PAPER.get(self.name)


def load_stage(name: str, configs: Path) -> Stage:
    """The stage of ``configs/<name>.yaml``."""
    if name not in STAGES:
        raise ValueError(f"unknown stage {name!r}; expected one of {sorted(STAGES)}")
    kind, unit = STAGES[name]
    path = Path(configs) / f"{name}.yaml"
    config = yaml.safe_load(path.read_text())
    if kind == "ppo":
        from zoo.experts.ppo.config import PPOConfig

        ppo = PPOConfig.from_yaml(path)
        return Stage(name, kind, unit, path, config, ppo.num_envs, ppo.num_steps, 1, 1, "32-true",
                     ppo.num_updates, float(ppo.num_updates * ppo.batch_size), ppo.max_grad_norm,
                     None)  # fmt: skip
    trainer, model, data = config["trainer"], config["model"]["init_args"], config["data"]
    window, seq_len = 1, 1
    if kind == "sequence":
        window, seq_len = model["tbptt_len"], data["init_args"]["seq_len"]
    clip = model.get("max_grad_norm") if kind == "sequence" else trainer.get("gradient_clip_val")
    dataset = {"sequence": "crafterplay", "cclip": "craftercaption"}.get(kind)
    devices = trainer.get("devices", 1)
    devices = devices if isinstance(devices, int) else 1
    batch, steps = data["init_args"]["batch_size"], trainer["max_steps"]
    return Stage(
        name, kind, unit, path, config, batch, window, seq_len // window, devices,
        str(trainer.get("precision") or "32-true"), steps,
        float(steps) * batch * devices * window, clip, dataset,
    )  # fmt: skip


__all__ = ["PAPER", "QUICK_STAGES", "STAGES", "PaperRun", "Stage", "load_stage"]
