"""The four models' kinds: how a training run's hyper-parameters become a network's config,
and a config a network (C-VPT, C-CLIP, the CVAE prior, C-Steve-1). ``zoo.weights.export``
reads and writes every kind the same way; a kind says only what differs."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

from torch import nn

from zoo.envs.constants import NUM_ACTIONS
from zoo.models.cvpt import CVPTConfig, CVPTModel
from zoo.weights.guidance import PAPER_CFG_SCALE


def config_from_hparams(hparams: dict[str, Any]) -> CVPTConfig:
    """The CVPTConfig of a ``lit_models.cvpt.CVPT`` run: preset ``model`` + non-None size overrides.

    The run's hyper-parameters hold no action count (CVPT trains on the game's actions), so
    the game's is used unless they name one.
    """
    if "model" not in hparams:
        raise ValueError(f"checkpoint hyper_parameters have no 'model' preset: {sorted(hparams)}")
    fields = {f.name for f in dataclasses.fields(CVPTConfig)} - {"name"}
    overrides = {k: v for k, v in hparams.items() if k in fields and v is not None}
    if "impala_channels" in overrides:
        overrides["impala_channels"] = tuple(overrides["impala_channels"])
    return CVPTConfig.from_name(hparams["model"], **{"num_actions": NUM_ACTIONS, **overrides})


# Per-kind builders import their model lazily: open_clip and peft are slow to import and a
# C-VPT agent needs neither.
def _cclip_config(hparams: dict[str, Any]) -> dict[str, Any]:
    from zoo.models.cclip import CCLIPConfig

    return dataclasses.asdict(CCLIPConfig.from_hparams(hparams))


def _cclip_build(config: dict[str, Any]) -> nn.Module:
    from zoo.models.cclip import CCLIPConfig, CCLIPModel

    return CCLIPModel(CCLIPConfig(**config))


def _prior_config(hparams: dict[str, Any]) -> dict[str, Any]:
    from zoo.models.prior import PriorConfig

    return dataclasses.asdict(PriorConfig.from_hparams(hparams))


def _prior_build(config: dict[str, Any]) -> nn.Module:
    from zoo.models.prior import CVAEPrior, PriorConfig

    return CVAEPrior(PriorConfig(**config))


def _steve_config(hparams: dict[str, Any]) -> dict[str, Any]:
    """C-Steve-1's hyper-parameter layout: the backbone's CVPTConfig dict + CSteve1Config fields."""
    from zoo.models.csteve1 import CSteve1Config

    backbone = CVPTConfig.from_dict(hparams["backbone_config"]).to_dict()
    return {"backbone_config": backbone, **CSteve1Config.from_hparams(hparams).to_dict()}


def _steve_build(config: dict[str, Any]) -> nn.Module:
    from zoo.models.csteve1 import CSteve1Config, CSteve1Model

    unknown = set(config) - {"backbone_config"} - {f.name for f in dataclasses.fields(CSteve1Config)}
    if unknown:
        raise ValueError(f"unknown C-Steve-1 config fields {sorted(unknown)}")
    backbone = CVPTModel(CVPTConfig.from_dict(config["backbone_config"]))
    return CSteve1Model(backbone, CSteve1Config.from_hparams(config))


def _steve_config_of(model: nn.Module) -> dict[str, Any]:
    return {"backbone_config": model.cvpt_config.to_dict(), **model.config.to_dict()}


@dataclasses.dataclass(frozen=True)
class ModelKind:
    """How one model's checkpoints become a plain network and its config.json."""

    title: str
    """Name in messages."""
    lit_class: str
    """The LightningModule whose checkpoints hold it (``_class_path`` of LightningCLI runs)."""
    model_class: str
    """The plain network's class, ``module.QualName``."""
    marker: str
    """A hyper-parameter only this model's runs have (checkpoints without ``_class_path``)."""
    config_from_hparams: Callable[[dict[str, Any]], dict[str, Any]]
    build: Callable[[dict[str, Any]], nn.Module]
    config_of: Callable[[nn.Module], dict[str, Any]]
    inference: dict[str, float] = dataclasses.field(default_factory=dict)
    """Settings it plays with that its weights do not hold, with the values used where an
    export records none (a ``.ckpt``, an export from before they were recorded)."""
    goal_models: tuple[str, ...] = ()
    """The kinds of the models it reads its goals through (C-Steve-1: C-CLIP, the prior)."""


KINDS: dict[str, ModelKind] = {
    "cvpt": ModelKind(
        "C-VPT", "lit_models.cvpt.CVPT", "zoo.models.cvpt.CVPTModel", "tbptt_len",
        lambda hparams: config_from_hparams(hparams).to_dict(),
        lambda config: CVPTModel(CVPTConfig.from_dict(config)),
        lambda model: model.config.to_dict(),
    ),
    "cclip": ModelKind(
        "C-CLIP", "lit_models.cclip.CCLIP", "zoo.models.cclip.CCLIPModel", "text_layers",
        _cclip_config, _cclip_build, lambda model: dataclasses.asdict(model.config),
    ),
    "prior": ModelKind(
        "CVAE prior", "lit_models.prior.CVAEPriorModule", "zoo.models.prior.CVAEPrior",
        "latent_dim", _prior_config, _prior_build, lambda model: dataclasses.asdict(model.config),
    ),
    "csteve1": ModelKind(
        "C-Steve-1", "lit_models.csteve1.CSteve1", "zoo.models.csteve1.CSteve1Model",
        "backbone_config", _steve_config, _steve_build, _steve_config_of,
        {"cfg_scale": PAPER_CFG_SCALE, "temperature": 1.0}, ("cclip", "prior"),
    ),
}


def kind_of_hparams(hparams: dict[str, Any]) -> str | None:
    """The kind a run's hyper-parameters belong to (None: cannot tell).

    LightningCLI runs name their class; hand-made checkpoints are told apart by a field only
    one model has, C-Steve-1 first since it also carries C-VPT's.
    """
    class_path = hparams.get("_class_path")
    for name, kind in KINDS.items():
        if class_path == kind.lit_class:
            return name
    for name in ("csteve1", "prior", "cclip", "cvpt"):
        if KINDS[name].marker in hparams:
            return name
    return "cvpt" if class_path is None and "model" in hparams else None
