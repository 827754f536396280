"""Starting a run from a finished one's network (``model.init_args.init_weights``).

A DAgger round fine-tunes the last round's weights with a fresh optimizer and schedule, which a
``--ckpt_path`` resume (the same run, continued) does not give. The file must hold the same
architecture: a mismatch is refused with the fields that differ, not loaded half-way.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import torch
from torch import nn

from zoo.weights import load_model
from zoo.weights.checkpoint_io import CheckpointError


def _configs(model: nn.Module) -> dict[str, object]:
    """The dataclass configs that fix an architecture: the model's and, for C-Steve-1, its
    backbone's."""
    configs = {"": model.config}
    if hasattr(model, "backbone"):
        configs["backbone."] = model.backbone.config
    return configs


def starting_weights(path: str, kind: str, model: nn.Module, title: str) -> dict[str, torch.Tensor]:
    """State dict of the ``kind`` network at ``path`` (a ``.ckpt`` or ``zoo export`` folder),
    refused unless its architecture is ``model``'s (``title`` names the model in errors)."""
    if not Path(path).exists():
        raise FileNotFoundError(
            f"model.init_weights={path}: no such checkpoint or export folder (resuming or testing"
            " a run that started from it? Its weights are in --ckpt_path: add"
            " --model.init_args.init_weights=null)"
        )
    try:
        source = load_model(path, kind)
    except CheckpointError as err:
        raise CheckpointError(f"model.init_weights: {err}") from None
    theirs, ours = _configs(source), _configs(model)
    diff = {}
    for prefix, config in ours.items():
        a, b = dataclasses.asdict(theirs[prefix]), dataclasses.asdict(config)
        diff |= {prefix + k: (a.get(k), b[k]) for k in b if a.get(k) != b[k]}
    if diff:
        raise CheckpointError(
            f"model.init_weights={path} holds a different {title}: (its value, this model's) {diff}"
        )
    return source.state_dict()


__all__ = ["starting_weights"]
