"""Trained C-VPT weights without Lightning: read .ckpt files, write/read export folders.

An export folder holds ``model.safetensors``, ``config.json`` (a ``CVPTConfig``) and
``sha256.txt`` (``sha256sum`` format, so ``sha256sum -c sha256.txt`` also checks it).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from pathlib import Path
from typing import Any

import torch
from safetensors.torch import load_file, save_file

from zoo.models.cvpt import CVPTConfig, CVPTModel

WEIGHTS_FILE = "model.safetensors"
CONFIG_FILE = "config.json"
CHECKSUM_FILE = "sha256.txt"
STATE_DICT_PREFIX = "model."  # lit_models.cvpt.CVPT keeps the network in ``self.model``


def config_from_hparams(hparams: dict[str, Any]) -> CVPTConfig:
    """The CVPTConfig of a ``lit_models.cvpt.CVPT`` run: preset ``model`` + non-None size overrides."""
    if "model" not in hparams:
        raise ValueError(f"checkpoint hyper_parameters have no 'model' preset: {sorted(hparams)}")
    fields = {f.name for f in dataclasses.fields(CVPTConfig)} - {"name"}
    overrides = {k: v for k, v in hparams.items() if k in fields and v is not None}
    if "impala_channels" in overrides:
        overrides["impala_channels"] = tuple(overrides["impala_channels"])
    return CVPTConfig.from_name(hparams["model"], **overrides)


def _read_lightning_checkpoint(ckpt_path: str | Path) -> tuple[CVPTConfig, dict[str, torch.Tensor]]:
    checkpoint = torch.load(ckpt_path, map_location="cpu", weights_only=True)
    if "state_dict" not in checkpoint or "hyper_parameters" not in checkpoint:
        raise ValueError(f"{ckpt_path}: not a Lightning checkpoint (no state_dict/hyper_parameters)")
    config = config_from_hparams(checkpoint["hyper_parameters"])
    state_dict = {
        key.removeprefix(STATE_DICT_PREFIX): value
        for key, value in checkpoint["state_dict"].items()
        if key.startswith(STATE_DICT_PREFIX)
    }
    return config, state_dict


def _build(config: CVPTConfig, state_dict: dict[str, torch.Tensor]) -> CVPTModel:
    model = CVPTModel(config)
    model.load_state_dict(state_dict)
    return model.eval()


def load_checkpoint_model(ckpt_path: str | Path) -> CVPTModel:
    """Rebuild the network from a Lightning .ckpt (``weights_only`` torch.load, no Lightning)."""
    return _build(*_read_lightning_checkpoint(ckpt_path))


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with path.open("rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def export_checkpoint(ckpt_path: str | Path, out_dir: str | Path) -> Path:
    """Write the network of a Lightning checkpoint as safetensors + config + checksums."""
    config, state_dict = _read_lightning_checkpoint(ckpt_path)
    # _build fails here, not at load time, if weights and config disagree
    return save_exported(_build(config, state_dict), out_dir)


def save_exported(model: CVPTModel, out_dir: str | Path) -> Path:
    """Write a C-VPT network as safetensors + config + checksums (what ``load_exported`` reads)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    state_dict = model.state_dict()
    save_file({k: v.contiguous() for k, v in state_dict.items()}, out / WEIGHTS_FILE)
    (out / CONFIG_FILE).write_text(json.dumps(model.config.to_dict(), indent=2) + "\n")
    lines = [f"{_sha256(out / name)}  {name}\n" for name in (WEIGHTS_FILE, CONFIG_FILE)]
    (out / CHECKSUM_FILE).write_text("".join(lines))
    return out


def load_exported(out_dir: str | Path) -> CVPTModel:
    """Rebuild the network from an export folder after checking its sha256 sums."""
    out = Path(out_dir)
    checksum_path = out / CHECKSUM_FILE
    if not checksum_path.is_file():
        raise FileNotFoundError(f"{checksum_path} missing: {out} is not a `zoo export` folder")
    for line in checksum_path.read_text().splitlines():
        expected, name = line.split()
        actual = _sha256(out / name)
        if actual != expected:
            raise ValueError(
                f"checksum mismatch for {out / name}: sha256.txt says {expected}, file has {actual}"
            )
    config = CVPTConfig.from_dict(json.loads((out / CONFIG_FILE).read_text()))
    return _build(config, load_file(out / WEIGHTS_FILE))


def load_policy_model(path: str | Path) -> CVPTModel:
    """A folder is an export, a file a Lightning checkpoint."""
    return load_exported(path) if Path(path).is_dir() else load_checkpoint_model(path)
