"""A stage's LightningModule, a synthetic batch and its training loss: what gets measured.

``build_module``, ``make_batch`` and ``loss`` give the module its config builds, a batch of the
real shapes and dtypes, and the module's own training loss on it, so FLOPs, memory and time are
measured on the code that trains, not on a re-implementation (bench/bench_gpu.py steps the
same). The PPO expert (JAX) is measured in ``ppo.py``.
"""

from __future__ import annotations

import importlib

import torch
import yaml

from lit_models.scale.stages import Stage


def _instantiate(class_path: str, init_args: dict) -> torch.nn.Module:
    module, _, name = class_path.rpartition(".")
    return getattr(importlib.import_module(module), name)(**init_args)


def build_module(stage: Stage) -> torch.nn.Module:
    """The stage's LightningModule from its config, built with no file: C-CLIP from random init
    (same shapes as the pretrained towers), C-Steve-1 on a C-VPT base built in memory from
    cvpt_base.yaml's sizes (its ``backbone`` is a checkpoint path)."""
    model = stage.config["model"]
    init_args = dict(model["init_args"])
    if stage.kind == "cclip":
        init_args["pretrained_path"] = None
    if stage.name == "csteve1":
        base = yaml.safe_load((stage.path.parent / "cvpt_base.yaml").read_text())["model"]
        backbone = _instantiate(base["class_path"], base["init_args"]).config.to_dict()
        init_args.update(backbone=None, backbone_config=backbone)
    module = _instantiate(model["class_path"], init_args)
    module.configure_model()
    return module.train()


def _cvpt_config(module: torch.nn.Module):
    return getattr(module.model, "cvpt_config", None) or module.model.config


def make_batch(stage: Stage, module: torch.nn.Module, batch: int, device: str) -> dict:
    """A synthetic batch of the real shapes and dtypes: for sequence models one TBPTT window
    (one optimizer step), for C-CLIP clips with caption ids, for the prior embedding pairs."""
    gen = torch.Generator().manual_seed(0)
    if stage.kind == "sequence":
        config, t = _cvpt_config(module), stage.units_per_sample
        size = config.frame_size
        out = {
            "frames": torch.randint(0, 256, (batch, t, size, size, 3), generator=gen,
                                    dtype=torch.uint8),
            "first": torch.zeros(batch, t, dtype=torch.bool),
            "actions": torch.randint(0, config.num_actions, (batch, t), generator=gen),
        }  # fmt: skip
        out["first"][:, 0] = True
        if "goal" in module.condition_keys:
            out["goal"] = torch.randn(batch, t, module.hparams.goal_dim, generator=gen)
    elif stage.kind == "cclip":
        cfg = module.config
        shape = (batch, cfg.num_frames, cfg.image_size, cfg.image_size, 3)
        out = {
            "frames": torch.randint(0, 256, shape, generator=gen, dtype=torch.uint8),
            "caption_id": torch.randint(0, len(module.variant_offsets), (batch,), generator=gen),
        }
    else:
        dim = module.config.embed_dim
        out = {"video": torch.randn(batch, dim, generator=gen),
               "text": torch.randn(batch, dim, generator=gen)}  # fmt: skip
    return {k: v.to(device) for k, v in out.items()}


def loss(stage: Stage, module: torch.nn.Module, batch: dict) -> torch.Tensor:
    """The training loss of one optimizer step, through the module's own pieces (its
    ``training_step`` also logs and steps, which needs a Trainer)."""
    if stage.kind == "sequence":
        conditions = [batch[k] for k in module.condition_keys]
        state = module.model.initial_state(batch["frames"].shape[0], batch["frames"].device)
        logits, _ = module.model(batch["frames"], batch["first"], *conditions, state)
        return module._loss(logits, batch["actions"])
    if stage.kind == "cclip":
        from zoo.models.contrastive import multi_positive_infonce

        ids = batch["caption_id"]
        video, text = module(batch["frames"], module.caption_tokens(ids, paraphrase=True))
        return multi_positive_infonce(video, text, ids, module.model.logit_scale)
    recon, mu, logvar = module.model(batch["video"], batch["text"])
    return module.model.loss(batch["video"], recon, mu, logvar)["loss"]


def input_bytes_per_sample(stage: Stage, batch: dict) -> int:
    """Device bytes of one sample of a loaded batch: a sequence model holds the whole sequence
    (``samples_per_batch_len`` windows) on the device while it steps window by window."""
    size = batch[next(iter(batch))].shape[0]
    window = sum(t.numel() * t.element_size() for t in batch.values()) // size
    return window * stage.samples_per_batch_len


__all__ = ["build_module", "input_bytes_per_sample", "loss", "make_batch"]
