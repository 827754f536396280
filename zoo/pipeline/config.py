"""What one ``zoo pipeline`` run makes: every size and model config of the suite in one YAML file.

Read strictly (``zoo.strict_config``): every field once, nothing else, types checked, so the
file is the complete record of a run. Training stages take a model config of ``configs/`` plus
extra ``zoo fit`` overrides; the pipeline adds only the paths that wire the stages together.
"""

from __future__ import annotations

import shlex
from dataclasses import dataclass
from pathlib import Path

from zoo.captions.balance import BALANCE_MODES
from zoo.envs import ENV_NAMES
from zoo.envs.tasks import TASKS
from zoo.strict_config import dataclass_from_yaml


@dataclass(frozen=True)
class PipelineConfig:
    env: str
    """Game the scripted expert's CrafterPlay is played in: ``craftax`` or ``crafter``."""
    seed: int
    """Seed of the data, the caption split and every evaluation."""
    episodes: int
    """CrafterPlay episodes (paper: 20,000)."""
    max_steps: int
    """Step limit of a CrafterPlay episode (paper: 10,000)."""
    episodes_per_shard: int
    """Episodes per CrafterPlay shard."""
    chunk_length: int
    """Steps per CrafterPlay sample."""
    workers: int
    """Processes that generate shards."""
    heldout_episodes: int
    """CrafterCaption test episodes: C-CLIP retrieval and the prior's pairs (paper: 1,000)."""
    val_episodes: int
    """CrafterCaption validation episodes, which pick C-CLIP's checkpoint (paper: 500)."""
    balance: str
    """CrafterCaption balancing: ``uniform`` (the paper's) or ``none`` (keep every clip)."""
    per_unit: int | None
    """Clips per rule category when balancing (paper: 575,000); null: the rarest category's."""
    per_shard: int
    """Clips per CrafterCaption shard."""
    cvpt_config: str
    """C-VPT model config (``zoo fit --config``)."""
    cvpt_args: str
    """Extra ``zoo fit`` arguments for C-VPT, shell-quoted (e.g. ``--trainer.max_steps=10``)."""
    cclip_config: str
    """C-CLIP model config."""
    cclip_args: str
    """Extra ``zoo fit`` arguments for C-CLIP; its retrieval test gets them too."""
    eval_episodes: int
    """Episodes of every Crafter Score evaluation (paper: 100)."""
    eval_max_steps: int
    """Episode step limit of the Crafter Score evaluations (paper: 10,000)."""
    retrieval: bool
    """Score C-CLIP's video -> text retrieval on the held-out episodes (``zoo test``)."""
    steve: bool
    """Run the C-Steve-1 stages: goal embeddings, C-Steve-1, prior pairs, prior, task eval."""
    csteve1_config: str
    """C-Steve-1 model config; its backbone is this run's C-VPT, its goals this run's C-CLIP."""
    csteve1_args: str
    """Extra ``zoo fit`` arguments for C-Steve-1."""
    prior_split: str
    """CrafterCaption split the prior's (video, text) pairs come from (paper: test)."""
    prior_max_pairs: int | None
    """Seeded subset of the prior's pairs (paper: 120,000); null: every clip of the split."""
    prior_config: str
    """CVAE prior model config."""
    prior_args: str
    """Extra ``zoo fit`` arguments for the prior."""
    task: str
    """Single-step task C-Steve-1 is scored on (``zoo eval --task``)."""
    instruction: str
    """The text instruction C-Steve-1 gets in that task."""
    task_episodes: int
    """Episodes of the task evaluation (paper: 20 per task)."""
    device: str
    """Torch device of ``zoo goals embed`` and ``prior-pairs`` (``cpu``, ``cuda``)."""

    def __post_init__(self) -> None:
        if self.env not in ENV_NAMES:
            raise ValueError(f"env must be one of {ENV_NAMES}, got {self.env!r}")
        if self.task not in TASKS:
            raise ValueError(f"task must be one of {sorted(TASKS)}, got {self.task!r}")
        if self.balance not in BALANCE_MODES:
            raise ValueError(f"balance must be one of {BALANCE_MODES}, got {self.balance!r}")
        for name in ("cvpt_config", "cclip_config", "csteve1_config", "prior_config"):
            if not Path(getattr(self, name)).is_file():
                raise ValueError(f"{name}: {getattr(self, name)} is not a file")
        for name in ("cvpt_args", "cclip_args", "csteve1_args", "prior_args"):
            try:
                shlex.split(getattr(self, name))
            except ValueError as err:
                raise ValueError(f"{name}: {err} in {getattr(self, name)!r}") from None


def load_pipeline_config(path: str | Path) -> PipelineConfig:
    """The config at ``path``; ValueError/FileNotFoundError name the file and the key."""
    try:
        return dataclass_from_yaml(PipelineConfig, path)
    except ValueError as err:
        text = str(err)
        raise ValueError(text if text.startswith(str(path)) else f"{path}: {text}") from None
