"""Trained networks without Lightning: read .ckpt files, write/read export folders.

An export folder holds ``model.safetensors``, ``config.json`` (the network's config plus
``"kind"``: cvpt, cclip, prior or csteve1, the stored ``"dtype"`` and, for a kind that plays with
settings its weights do not hold, ``"inference"``: C-Steve-1's guidance scale and temperature,
the ones its scores were measured at; for C-Steve-1, ``"goal_models"``: the C-CLIP and prior its
text instructions go through, as paths relative to the folder with their sha256) and
``sha256.txt`` (``sha256sum`` format, so
``sha256sum -c sha256.txt`` also checks it). Every model uses this one format and one checksum
routine; a ``ModelKind`` (zoo/weights/kinds.py) only says how a training run's hyper-parameters become a config and a
config a network. A C-VPT export written before kinds existed has no ``"kind"`` and reads as
cvpt; a C-Steve-1 export written before ``"inference"`` plays at the defaults, and one written
before ``"goal_models"`` needs them named (``--cclip``, ``--prior``). Weights may be
stored as float16/bfloat16 to halve the bytes; loading always gives float32 modules.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import shutil
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import torch
from safetensors.torch import load_file, save_file
from torch import nn

from zoo.files import sha256_file
from zoo.weights.checkpoint_io import ZOO_CHECKPOINT, CheckpointError, read_torch_file
from zoo.weights.kinds import KINDS, kind_of_hparams

WEIGHTS_FILE = "model.safetensors"
CONFIG_FILE = "config.json"
CHECKSUM_FILE = "sha256.txt"
STATE_DICT_PREFIX = "model."  # every lit_models module keeps its network in ``self.model``
DTYPES = {"float32": torch.float32, "float16": torch.float16, "bfloat16": torch.bfloat16}
INFERENCE = "inference"
GOAL_MODELS = "goal_models"
RESERVED_KEYS = ("kind", "dtype", INFERENCE, GOAL_MODELS)  # config.json keys, not config fields


def read_lightning_checkpoint(
    path: str | Path, kind: str | None = None, expected: str = ZOO_CHECKPOINT
) -> tuple[str, dict[str, Any], dict[str, torch.Tensor]]:
    """(kind, config, network state dict) of a Lightning .ckpt, read weights-only.

    ``kind`` is what the caller expects; a checkpoint of another model is an error naming both.
    ``expected`` is what an unreadable file is said to be instead of.
    """
    path = Path(path)
    checkpoint = read_torch_file(path, expected)
    missing = [key for key in ("hyper_parameters", "state_dict") if key not in checkpoint]
    if missing:
        raise CheckpointError(f"{path}: not a Lightning checkpoint (lacks {missing})")
    hparams = dict(checkpoint["hyper_parameters"])
    found = kind_of_hparams(hparams)
    if kind is not None and found not in (None, kind):
        raise CheckpointError(
            f"{path} holds a {KINDS[found].title} checkpoint, expected {KINDS[kind].title} ({kind})"
        )
    kind = kind or found
    if kind is None:
        raise CheckpointError(
            f"{path}: cannot tell which model its hyper-parameters {sorted(hparams)} belong to; "
            f"expected one of {sorted(KINDS)}"
        )
    state_dict = {
        key.removeprefix(STATE_DICT_PREFIX): value
        for key, value in checkpoint["state_dict"].items()
        if key.startswith(STATE_DICT_PREFIX)
    }
    return kind, KINDS[kind].config_from_hparams(hparams), state_dict


def _build(kind: str, config: dict[str, Any], state_dict: dict[str, torch.Tensor]) -> nn.Module:
    model = KINDS[kind].build(config)
    model.load_state_dict({k: _as_float32(v) for k, v in state_dict.items()})
    return model.eval()


def _as_float32(tensor: torch.Tensor) -> torch.Tensor:
    return tensor.float() if tensor.is_floating_point() else tensor


def checkpoint_sha256(path: str | Path) -> str:
    """Fingerprint of a model, so data and reports made from it record what made it: a
    file's own sha256, an export folder's sha256.txt's (which pins its weights and config),
    and for any other folder (a PPO or ``zoo rl train`` run) the sha256 of its files' relative
    names and sums."""
    path = Path(path)
    if not path.is_dir():
        return sha256_file(path)
    if (path / CHECKSUM_FILE).is_file():
        return sha256_file(path / CHECKSUM_FILE)
    files = sorted(p for p in path.rglob("*") if p.is_file())
    listing = "".join(f"{sha256_file(p)}  {p.relative_to(path).as_posix()}\n" for p in files)
    return hashlib.sha256(listing.encode()).hexdigest()


def export_checkpoint(
    ckpt_path: str | Path,
    out_dir: str | Path,
    dtype: str = "float32",
    inference: dict[str, float] | None = None,
    goal_models: Mapping[str, str | Path] | None = None,
    copy_goal_models: bool = False,
) -> Path:
    """Write the network of any model's Lightning checkpoint, or of an export folder (to
    change how it is stored or what it records), as an export folder. ``inference``,
    ``goal_models`` and ``copy_goal_models``: as for ``save_exported``; an export folder keeps
    what it records unless they are given."""
    source = Path(ckpt_path)
    if source.is_dir():
        kind = exported_kind(source)
        network = load_model(source, kind)
        inference = {**inference_settings(source, kind), **(inference or {})}
        if goal_models is None and KINDS[kind].goal_models:
            goal_models = recorded_goal_models(source)
    else:
        # building here makes weights and config that disagree fail now, not at load time
        parts = read_lightning_checkpoint(source, expected="a `zoo fit` checkpoint (.ckpt)")
        network = _build(*parts)
    return save_exported(network, out_dir, dtype, inference, goal_models, copy_goal_models)


def _kind_of_model(model: nn.Module) -> str:
    class_name = f"{type(model).__module__}.{type(model).__qualname__}"
    for name, kind in KINDS.items():
        if kind.model_class == class_name:
            return name
    raise TypeError(f"cannot export a {class_name}: expected one of "
                    f"{[kind.model_class for kind in KINDS.values()]}")


def save_exported(
    model: nn.Module,
    out_dir: str | Path,
    dtype: str = "float32",
    inference: dict[str, float] | None = None,
    goal_models: Mapping[str, str | Path] | None = None,
    copy_goal_models: bool = False,
) -> Path:
    """Write a network as safetensors + config + checksums (what ``load_model`` reads).

    ``dtype`` (float32, float16, bfloat16) is how floating-point weights are stored.
    ``inference`` overrides the kind's play settings (C-Steve-1: ``cfg_scale``, ``temperature``)
    with the ones its scores were measured at; config.json records all of them, so the export
    plays the same even if the defaults change. ``goal_models`` (C-Steve-1: ``cclip`` and
    ``prior``, export folders) are recorded by path relative to the folder and sha256, or with
    ``copy_goal_models`` copied into it, so the export reads text instructions on its own.
    """
    if dtype not in DTYPES:
        raise ValueError(f"dtype {dtype!r}: expected one of {sorted(DTYPES)}")
    kind = _kind_of_model(model)
    settings = {**KINDS[kind].inference, **_checked_inference(kind, inference or {})}
    out = Path(out_dir)
    goals = _checked_goal_models(kind, model, goal_models or {})
    out.mkdir(parents=True, exist_ok=True)
    weights = {
        key: (value.to(DTYPES[dtype]) if value.is_floating_point() else value).contiguous()
        for key, value in model.state_dict().items()
    }
    save_file(weights, out / WEIGHTS_FILE)
    config: dict[str, Any] = {"kind": kind, "dtype": dtype}
    if settings:
        config[INFERENCE] = settings
    if goals:
        config[GOAL_MODELS] = _write_goal_models(goals, out, copy_goal_models)
    config.update(KINDS[kind].config_of(model))
    (out / CONFIG_FILE).write_text(json.dumps(config, indent=2) + "\n")
    lines = [f"{sha256_file(out / name)}  {name}\n" for name in (WEIGHTS_FILE, CONFIG_FILE)]
    (out / CHECKSUM_FILE).write_text("".join(lines))
    return out


def verify_export(out_dir: str | Path) -> None:
    """Raise unless the folder has all three files and every sum in sha256.txt matches."""
    out = Path(out_dir)
    for name in (CHECKSUM_FILE, WEIGHTS_FILE, CONFIG_FILE):
        if not (out / name).is_file():
            raise FileNotFoundError(
                f"{out / name} missing: {out} is not a `zoo export` folder "
                f"(expected {WEIGHTS_FILE}, {CONFIG_FILE} and {CHECKSUM_FILE})"
            )
    listed = {}
    for number, line in enumerate((out / CHECKSUM_FILE).read_text().splitlines(), 1):
        if len(line.split()) != 2:
            raise CheckpointError(
                f"{out / CHECKSUM_FILE} line {number}: expected '<sha256>  <file>', got {line!r}"
            )
        expected, name = line.split()
        listed[name] = expected
        actual = sha256_file(out / name)
        if actual != expected:
            raise CheckpointError(
                f"checksum mismatch for {out / name}: sha256.txt says {expected}, file has {actual}"
            )
    unlisted = [name for name in (WEIGHTS_FILE, CONFIG_FILE) if name not in listed]
    if unlisted:
        raise CheckpointError(f"{out / CHECKSUM_FILE} has no sum for {unlisted}")


def read_export_config(out_dir: str | Path) -> dict[str, Any]:
    """An export folder's config.json; a missing or malformed one is an error naming it."""
    path = Path(out_dir) / CONFIG_FILE
    if not path.is_file():
        raise FileNotFoundError(f"{path} missing: {out_dir} is not a `zoo export` folder")
    try:
        config = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise CheckpointError(f"{path}: not valid JSON ({err}); expected the config.json "
                              "`zoo export` writes") from None
    if not isinstance(config, dict):
        raise CheckpointError(f"{path}: holds a JSON {type(config).__name__}, expected an object")
    return config


def exported_kind(out_dir: str | Path) -> str:
    """The kind an export folder's config.json names (no "kind": a C-VPT export)."""
    kind = read_export_config(out_dir).get("kind", "cvpt")
    if kind not in KINDS:
        path = Path(out_dir) / CONFIG_FILE
        raise CheckpointError(f"{path}: unknown kind {kind!r}, expected one of {sorted(KINDS)}")
    return kind


def _checked_inference(kind: str, settings: dict[str, Any]) -> dict[str, float]:
    """``settings`` if ``kind`` plays with each of them and each is a number >= 0 (a guidance
    scale, 0: the conditional logits alone; a temperature, 0: the most likely action); else a
    ValueError."""
    allowed = KINDS[kind].inference
    unknown = sorted(set(settings) - set(allowed))
    if unknown:
        raise ValueError(f"a {KINDS[kind].title} export records no {unknown}: "
                         f"its inference settings are {sorted(allowed) or 'none'}")
    bad = {name: value for name, value in settings.items()
           if isinstance(value, bool) or not isinstance(value, int | float)
           or not (math.isfinite(value) and value >= 0)}
    if bad:
        raise ValueError(f"inference settings must be finite numbers >= 0, got {bad}")
    return settings


def inference_settings(path: str | Path, kind: str) -> dict[str, float]:
    """The settings the ``kind`` model at ``path`` plays with: what a ``zoo export`` folder's
    config.json records, else the kind's defaults (a ``.ckpt``, an older export)."""
    path = Path(path)
    recorded = read_export_config(path).get(INFERENCE, {}) if path.is_dir() else {}
    if not isinstance(recorded, dict):
        raise CheckpointError(f"{path / CONFIG_FILE}: {INFERENCE!r} holds a JSON "
                              f"{type(recorded).__name__}, expected an object")
    try:
        checked = _checked_inference(kind, recorded)
    except ValueError as err:
        raise CheckpointError(f"{path / CONFIG_FILE}: {err}") from None
    return {**KINDS[kind].inference, **checked}


def _load_exported(out_dir: str | Path, kind: str | None) -> nn.Module:
    """The network of an export folder, float32 and in eval mode, after checking its sums."""
    out = Path(out_dir)
    verify_export(out)
    found = exported_kind(out)
    kind = kind or found
    if found != kind:
        raise CheckpointError(
            f"{out / CONFIG_FILE} says kind {found!r} ({KINDS[found].title}), "
            f"expected {kind!r} ({KINDS[kind].title})"
        )
    config = {k: v for k, v in read_export_config(out).items() if k not in RESERVED_KEYS}
    return _build(kind, config, load_file(out / WEIGHTS_FILE))


def load_model(
    path: str | Path, kind: str | None = None, map_location: str | torch.device = "cpu"
) -> nn.Module:
    """The network at ``path``, float32, in eval mode, without Lightning: the one loader.

    A folder is a ``zoo export`` (checked against its ``sha256.txt`` first), a file the ``.ckpt``
    of a ``zoo fit`` run. ``kind`` ("cvpt", "cclip", "prior", "csteve1") is checked when given
    (another model's file is an error naming both) and read from the file when not.
    """
    if Path(path).is_dir():
        model = _load_exported(path, kind)
    else:
        model = _build(*read_lightning_checkpoint(path, kind))
    return model.to(map_location)


def _checked_goal_models(
    kind: str, model: nn.Module, goal_models: Mapping[str, str | Path]
) -> dict[str, Path]:
    """``goal_models`` as export folders of the kinds ``kind`` reads goals through, all of them
    or none, the C-CLIP embedding the width the model's goals have; else a ValueError."""
    wanted = KINDS[kind].goal_models
    if not goal_models:
        return {}
    if not wanted:
        raise ValueError(f"a {KINDS[kind].title} export records no goal models")
    if sorted(goal_models) != sorted(wanted):
        raise ValueError(f"a {KINDS[kind].title} export records its goal models "
                         f"{list(wanted)} together, got {sorted(goal_models)}")
    checked = {}
    for name, path in goal_models.items():
        path = Path(path)
        if not path.is_dir():
            raise ValueError(f"goal model {name} {path}: expected a `zoo export` folder")
        verify_export(path)
        if (found := exported_kind(path)) != name:
            raise ValueError(f"goal model {name} {path} is a {KINDS[found].title} export")
        checked[name] = path
    width = read_export_config(checked["cclip"]).get("embed_dim")
    if width != model.config.goal_dim:
        raise ValueError(f"the C-CLIP {checked['cclip']} embeds {width} dimensions but this "
                         f"C-Steve-1 expects goal_dim={model.config.goal_dim}: record the "
                         "C-CLIP it was trained with")
    return checked


def _write_goal_models(goals: dict[str, Path], out: Path, copy: bool) -> dict[str, dict]:
    """config.json's record of the goal models: path relative to ``out`` and sha256, after
    copying them into ``out`` with ``copy``."""
    record = {}
    for name, path in goals.items():
        if copy and path.resolve() != (out / name).resolve():
            shutil.rmtree(out / name, ignore_errors=True)
            shutil.copytree(path, out / name)
            path = out / name
        record[name] = {"path": os.path.relpath(path.resolve(), out.resolve()),
                        "sha256": checkpoint_sha256(path)}
    return record


def recorded_goal_models(path: str | Path) -> dict[str, Path] | None:
    """The goal models a C-Steve-1 export records, checked: each exists and has the sha256
    the export was written with; None for a ``.ckpt`` or an export that records none."""
    path = Path(path)
    if not path.is_dir():
        return None
    recorded = read_export_config(path).get(GOAL_MODELS)
    if recorded is None:
        return None
    config = path / CONFIG_FILE
    if not isinstance(recorded, dict) or not all(
        isinstance(v, dict) and {"path", "sha256"} <= v.keys() for v in recorded.values()
    ):
        raise CheckpointError(f"{config}: {GOAL_MODELS!r} must map each model to "
                              '{"path": ..., "sha256": ...}')
    found = {}
    for name, entry in recorded.items():
        where = (path / entry["path"]).resolve()
        if not where.exists():
            raise CheckpointError(
                f"{config} records its {name} at {entry['path']} ({where}), which does not "
                "exist: keep the export beside it, pass --cclip and --prior, or re-export with "
                "`zoo export --copy-goal-models`")
        if (actual := checkpoint_sha256(where)) != entry["sha256"]:
            raise CheckpointError(
                f"{config} records its {name} {where} with sha256 {entry['sha256']}, but it now "
                f"has {actual}: other weights than the ones this C-Steve-1 was exported with")
        found[name] = where
    return found
