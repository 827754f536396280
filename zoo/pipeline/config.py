"""What one ``zoo pipeline`` run makes: every size and model config in one YAML file.

Two kinds: the suite (no ``kind`` key: ``PipelineConfig``, data to C-Steve-1) and DAgger rounds
for C-VPT (``kind: dagger``: ``DaggerPipelineConfig``). Read strictly (``zoo.strict_config``):
every field once, nothing else, types checked, so the file is the complete record of a run.
Training stages take a model config of ``configs/`` plus extra ``zoo fit`` overrides; the
pipeline adds only the paths that wire the stages together.
"""

from __future__ import annotations

import dataclasses
import re
import shlex
from dataclasses import dataclass, fields
from pathlib import Path
from typing import TypeVar

import yaml

from zoo.captions.balance import BALANCE_MODES
from zoo.envs import ENV_NAMES
from zoo.envs.tasks import TASKS
from zoo.strict_config import coerce, dataclass_from_dict

T = TypeVar("T")
MIXES = ("episode", "step")  # `zoo data dagger --mix`


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
        _check_models(self, ("cvpt_config", "cclip_config", "csteve1_config", "prior_config"),
                      ("cvpt_args", "cclip_args", "csteve1_args", "prior_args"))


@dataclass(frozen=True)
class DaggerPipelineConfig:
    """DAgger rounds for C-VPT (docs/dagger.md): per round, roll out the last round's weights
    with the scripted expert labelling every state, train on the expert data plus every round's
    labels from those weights, score the new weights."""

    expert_data: str
    """CrafterPlay folder of the expert's own play, the first source of every round's training;
    local, since its ``manifest.json`` fingerprints it (new data: every round runs again)."""
    initial_learner: str
    """Round 0's C-VPT, made outside the pipeline (plain BC: ``zoo fit --config
    configs/cvpt_tiny_cpu.yaml``): a ``.ckpt`` or a ``zoo export`` folder. Round 1 rolls it out
    and trains from its weights; when its bytes change, every round runs again."""
    fit_config: str
    """Model config of every round's ``zoo fit`` (``configs/cvpt_tiny_cpu_dagger.yaml``: a fresh
    optimizer and a short cosine from the last round's weights). It must save ``last.ckpt``:
    a round's weights are its last ones, at the end of the cosine."""
    fit_args: str
    """Extra ``zoo fit`` arguments of every round, shell-quoted (e.g. ``--trainer.max_steps=500
    --model.init_args.cosine_steps=500``)."""
    rounds: tuple[float, ...]
    """One entry per round, in order: its beta, the probability that the expert acts instead of
    the learner (``zoo data dagger --beta``)."""
    mix: str
    """What one beta draw decides: ``step`` (Ross et al.'s mixture policy) or ``episode``."""
    env: str
    """Game of the rollouts: ``craftax`` or ``crafter``."""
    episodes: int
    """Rollout episodes per round."""
    seed: int
    """Round r's rollouts are seeded ``seed + r``."""
    max_steps: int
    """Step limit of a rollout episode."""
    episodes_per_shard: int
    """Rollout episodes per CrafterPlay shard."""
    num_envs: int
    """Rollout episodes played at once (speed, not bytes)."""
    workers: int
    """Processes that write rollout shards."""
    expert_weight: float
    """Training share of the expert data: its weight over the sum of all sources' weights."""
    round_weight: float
    """Weight of each round's rollouts in every later round's training."""
    eval_episodes: int
    """Episodes of each round's Crafter Score evaluation (seed 0, ``zoo eval``'s default)."""
    eval_num_envs: int
    """Evaluation episodes played at once."""
    eval_games: tuple[str, ...]
    """Games each round's weights are scored in (``craftax``, ``crafter``; empty: none)."""

    def __post_init__(self) -> None:
        if not self.rounds:
            raise ValueError("rounds must list at least one beta")
        for beta in self.rounds:
            if not 0.0 <= beta <= 1.0:
                raise ValueError(f"rounds: every beta must be in [0, 1], got {beta}")
        if self.mix not in MIXES:
            raise ValueError(f"mix must be one of {MIXES}, got {self.mix!r}")
        for game in (self.env, *self.eval_games):
            if game not in ENV_NAMES:
                raise ValueError(f"env and eval_games must be in {ENV_NAMES}, got {game!r}")
        if len(set(self.eval_games)) < len(self.eval_games):
            raise ValueError(f"eval_games lists a game twice: {list(self.eval_games)}")
        _check_models(self, ("fit_config",), ("fit_args",))


KINDS = {None: PipelineConfig, "dagger": DaggerPipelineConfig}  # the YAML's `kind` -> its config


def _check_models(config: object, paths: tuple[str, ...], args: tuple[str, ...]) -> None:
    """Model configs are files and ``zoo fit`` overrides split as a shell would."""
    for name in paths:
        if not Path(getattr(config, name)).is_file():
            raise ValueError(f"{name}: {getattr(config, name)} is not a file")
    for name in args:
        try:
            shlex.split(getattr(config, name))
        except ValueError as err:
            raise ValueError(f"{name}: {err} in {getattr(config, name)!r}") from None


def load_pipeline_config(path: str | Path) -> PipelineConfig | DaggerPipelineConfig:
    """The config at ``path``, of the class its ``kind`` names; ValueError/FileNotFoundError
    name the file and the key."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"pipeline config file not found: {path}")
    try:
        values = yaml.safe_load(path.read_text())
        if not isinstance(values, dict):
            raise ValueError(  # noqa: TRY004 - one error type for every bad config
                f"expected a mapping of config keys, got {type(values).__name__}")
        kind = values.pop("kind", None)
        if kind not in KINDS:
            raise ValueError(f"kind must be one of {sorted(k for k in KINDS if k)} or absent "
                             f"(the suite), got {kind!r}")
        return _from_dict(KINDS[kind], values, str(path))
    except (ValueError, yaml.YAMLError) as err:
        text = " ".join(str(err).split())
        raise ValueError(text if text.startswith(str(path)) else f"{path}: {text}") from None


def _from_dict(cls: type[T], values: dict, source: str) -> T:
    """``zoo.strict_config``'s reading of ``cls``, plus ``tuple[X, ...]`` fields as YAML lists
    of X (that reader knows scalars only): it checks the keys and scalars of a twin of ``cls``
    whose lists are left out (None), then each list item is coerced as an X."""
    lists = {f.name: m.group(1) for f in fields(cls)
             if (m := re.fullmatch(r"tuple\[(\w+), \.\.\.\]", str(f.type)))}
    twin = dataclasses.make_dataclass(
        cls.__name__, [(f.name, f"{f.type} | None" if f.name in lists else f.type)
                       for f in fields(cls)])
    scalars = dataclass_from_dict(twin, {**values, **dict.fromkeys(lists.keys() & values)},
                                  source)
    items = {}
    for name, kind in lists.items():
        if not isinstance(values[name], list):
            raise ValueError(  # noqa: TRY004 - one error type for every bad config
                f"{source}: {name} must be a list of {kind}, got {values[name]!r}")
        items[name] = tuple(coerce(v, kind, f"{name}[{i}]", source)
                            for i, v in enumerate(values[name]))
    return cls(**{**vars(scalars), **items})
