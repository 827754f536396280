"""``zoo pipeline --config configs/pipeline_paper.yaml --dry-run --out DIR``: every stage of the
paper's pipeline at the paper's model sizes and sequence shapes, on a few episodes, on the CPU,
so a shape, config or loader error shows in minutes, not after hours of data on a cluster.

The dry run is the same plan with a smaller config (``dry_config``: ``dataclasses.replace``):
the data, evaluation and pair counts shrink, and each fit gets ``zoo fit`` overrides appended
after the config's own ``*_args`` so they win. What they change: the machine (CPU, one device,
no DDP), the length (2 optimizer steps, then one short validation before the run stops, so the
checkpoint the next stage reads is written), the per-device batch, the loggers (CSV: no W&B)
and the data split fractions the few episodes need. What they keep: every model config's
sizes (C-VPT base, ViT-B/16 towers, LoRA, the prior's widths), ``seq_len`` 640 with TBPTT
windows of 64 (one optimizer step each), precision, the callbacks (C-VPT's online evaluation plays once,
1 episode of 16 steps). C-CLIP starts from a random-init open_clip ViT-B-16 state dict written
to ``DIR/clip_init`` (this project never downloads weights), so it goes through the
pretrained-weights loader (224-px position grid resized to 9x9, strict key match). A ``scale``
stage (``zoo scale``: what the paper's scale costs) ends the plan. docs/pipeline.md lists it all.
"""

from __future__ import annotations

import dataclasses
import shlex
from pathlib import Path

import yaml

import zoo.pipeline.checks as checks  # noqa: PLR0402 - `from zoo.pipeline import` is a cycle
from zoo.files import atomic_path
from zoo.pipeline.config import PipelineConfig
from zoo.pipeline.stages import Stage, plan

CLIP_INIT = Path("clip_init") / "ViT-B-16-random.bin"
"""Under DIR: open_clip's ViT-B-16 at random init, read as the paper's OpenAI CLIP would be."""

# 4 scripted-expert episodes of 500 steps (~385 left each after the noop filter). With
# val_fraction 0.3 and no test split, episodes 1 and 2 are validation and 0 and 3 training
# (zoo.data.sequences.episode_split), so each side packs one 640-step sequence; CrafterCaption
# holds out 2 (the prior's pairs need 2 episodes to split) and validates on 1. Every frame goes
# through ViT-B/16 once in `zoo goals embed`, which is slow in fp32 on a CPU: the frame count
# is the dry run's largest cost.
SIZES = {
    "episodes": 4, "max_steps": 500, "episodes_per_shard": 2, "workers": 1,
    "heldout_episodes": 2, "val_episodes": 1,
    "eval_episodes": 2, "eval_max_steps": 100, "task_episodes": 2,
    "prior_max_pairs": 32, "device": "cpu",
}
VAL_FRACTION = 0.3
"""C-VPT's and C-Steve-1's validation share of the episodes, without a test split."""

FIT = ("--trainer.accelerator=cpu", "--trainer.devices=1", "--trainer.strategy=auto",
       "--trainer.max_steps=2", "--trainer.limit_val_batches=2",
       "--trainer.num_sanity_val_steps=0", "--trainer.check_val_every_n_epoch=null",
       "--trainer.logger=lightning.pytorch.loggers.CSVLogger",
       "--trainer.logger.init_args.save_dir=.")  # the run's folder (lit_models/cli.py)
"""Every fit: CPU, one process (the paper configs' ddp/ddp_spawn replaced), 2 optimizer steps,
at most 2 validation batches (C-VPT's and C-Steve-1's validation episodes hold one sequence),
CSV metrics instead of W&B. Not 1 batch: after JAX ran in the process, jsonargparse can read
``limit_val_batches=1`` as 1.0, every batch (typing caches Union[int, float] and
Union[float, int] as one object, and the first one made wins)."""

# C-VPT and C-Steve-1 step once per 64-step window: the first 640-step batch makes both steps,
# so validation runs after every batch (after that one) and one batch is an epoch.
SEQUENCE = ("--trainer.val_check_interval=1", "--data.init_args.batch_size=1",
            "--data.init_args.num_workers=1", "--data.init_args.train_batches_per_epoch=1",
            f"--data.init_args.val_fraction={VAL_FRACTION}", "--data.init_args.test_fraction=0.0")
# C-CLIP and the prior step once per batch: validate after the second. Retrieval groups of 8
# (paper: 64): 2 batches of 4 held-out clips score R@1, in validation (which picks the
# checkpoint) and in the retrieval test.
CCLIP = ("--trainer.val_check_interval=2", "--trainer.limit_test_batches=2",
         "--data.init_args.batch_size=4", "--data.init_args.eval_batch_size=4",
         "--data.init_args.num_workers=1", "--data.init_args.train_batches_per_epoch=2",
         "--model.init_args.retrieval_group_size=8")
PRIOR = ("--trainer.val_check_interval=2", "--data.init_args.batch_size=8")

ONLINE_EVAL = "OnlineEvaluation"
ONLINE_EVAL_ARGS = ("every_n_steps=1", "episodes=1", "num_envs=1", "max_steps=16")
"""jsonargparse's ``--trainer.callbacks.init_args.X`` sets X of the config's LAST callback."""


def dry_config(config: PipelineConfig, out: Path) -> PipelineConfig:
    """``config`` at the dry run's sizes, its fits shortened for one CPU (see the module)."""

    def extra(field: str, path: str, *args: str) -> str:
        return " ".join(filter(None, (getattr(config, field), shlex.join(
            (*FIT, *args, *_online_eval_args(path))))))

    init = out / CLIP_INIT
    return dataclasses.replace(
        config, **SIZES,
        cvpt_args=extra("cvpt_args", config.cvpt_config, *SEQUENCE),
        cclip_args=extra("cclip_args", config.cclip_config, *CCLIP,
                         f"--model.init_args.pretrained_path={init}"),
        csteve1_args=extra("csteve1_args", config.csteve1_config, *SEQUENCE),
        prior_args=extra("prior_args", config.prior_config, *PRIOR),
    )


def changes(paper: PipelineConfig, dry: PipelineConfig) -> dict[str, dict]:
    """Each setting the dry run changed: {name: {"config": value, "dry_run": value}}."""
    return {f.name: {"config": getattr(paper, f.name), "dry_run": getattr(dry, f.name)}
            for f in dataclasses.fields(paper) if getattr(paper, f.name) != getattr(dry, f.name)}


def dry_plan(config: PipelineConfig, out: Path) -> list[Stage]:
    """The suite's stages for the dry config (C-CLIP also reads the CLIP init file, so a new
    one retrains it), then ``zoo scale``, which reruns when a config it projects changes."""
    from lit_models.scale.stages import STAGES

    init = out / CLIP_INIT
    stages = [dataclasses.replace(s, reads=(*s.reads, init)) if s.name == "cclip" else s
              for s in plan(config, out)]
    scale = out / "scale"
    projected = tuple(Path("configs") / f"{name}.yaml" for name in STAGES)
    return [*stages, Stage("scale", (), scale, lambda keys: ["scale", "--out", str(scale)],
                           checks.scale, reads=projected)]


def write_clip_init(out: Path) -> Path:
    """``DIR/clip_init/ViT-B-16-random.bin``: ``open_clip.create_model("ViT-B-16")`` at a seeded
    random init, its state dict saved as open_clip's loader (``load_clip_state_dict``) reads a
    downloaded one. Kept when it exists: its bytes fingerprint the C-CLIP stage."""
    path = out / CLIP_INIT
    if path.is_file():
        return path
    import open_clip
    import torch

    torch.manual_seed(0)
    model = open_clip.create_model("ViT-B-16", pretrained=None)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        torch.save(model.state_dict(), tmp)
    return path


def _online_eval_args(config_path: str) -> tuple[str, ...]:
    """Overrides that make the config's online evaluation play once, briefly; none without one.
    jsonargparse reaches only the last callback of a config's list, so an online evaluation
    elsewhere in it is an error rather than hours of play in a dry run."""
    callbacks = (yaml.safe_load(Path(config_path).read_text()).get("trainer") or {}).get(
        "callbacks") or []
    found = [i for i, c in enumerate(callbacks) if c["class_path"].endswith(ONLINE_EVAL)]
    if not found:
        return ()
    if found != [len(callbacks) - 1]:
        raise ValueError(f"{config_path}: the dry run shortens an {ONLINE_EVAL} callback only "
                         "when it is the last of trainer.callbacks (move it there)")
    return tuple(f"--trainer.callbacks.init_args.{arg}" for arg in ONLINE_EVAL_ARGS)
