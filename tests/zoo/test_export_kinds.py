"""`zoo export` for every model: one format, kind detection, half precision, clear errors.

Tiny models are built here and saved as Lightning lays out a checkpoint (``model.`` weights
plus hyper-parameters), so no Lightning and no shipped weights are needed.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from functools import partial
from pathlib import Path

import numpy as np
import pytest
import torch
from torch import nn

from zoo.agents import checkpoint_kind
from zoo.cli import main as zoo_main
from zoo.envs.constants import NUM_ACTIONS
from zoo.files import sha256_file
from zoo.models.cclip import build_cclip
from zoo.models.cvpt import CVPTConfig, CVPTModel
from zoo.models.prior import CVAEPrior, PriorConfig
from zoo.models.csteve1 import CSteve1Config, CSteve1Model
from zoo.weights import load_model
from zoo.weights.cli import DTYPE_CHOICES
from zoo.weights.export import (
    CONFIG_FILE,
    DTYPES,
    WEIGHTS_FILE,
    export_checkpoint,
    exported_kind,
    kind_of_hparams,
    save_exported,
)

CVPT_SIZES = {
    "d_model": 32,
    "d_ff": 64,
    "n_heads": 2,
    "n_layers": 1,
    "impala_channels": (4, 8, 8),
    "encoder_hidden": 32,
    "memory_len": 3,
    "input_downsample": 4,
}
# Half-precision weights (10 mantissa bits) move these tiny random models' outputs by ~1e-3;
# 2e-2 absolute leaves room and still catches a wrong or garbled tensor (outputs are O(1)).
HALF_ATOL = 2e-2


def _cvpt() -> tuple[nn.Module, dict]:
    """With VPT's hidden head layer (the default linear head's reload: test_cvpt.py)."""
    hparams = {
        "_class_path": "lit_models.cvpt.CVPT",
        "model": "tiny",
        "tbptt_len": 4,
        **CVPT_SIZES,
        "impala_channels": list(CVPT_SIZES["impala_channels"]),
        "head_hidden": 8,
    }
    config = CVPTConfig.from_name("tiny", NUM_ACTIONS, **CVPT_SIZES, head_hidden=8)
    return CVPTModel(config), hparams


def _cclip() -> tuple[nn.Module, dict]:
    sizes = {"vision_layers": 1, "text_layers": 1, "temporal_layers": 1, "adapter_layers": 1}
    hparams = {
        "_class_path": "lit_models.cclip.CCLIP",
        "model": "smoke",
        "embed_dim": None,
        **sizes,
    }
    return build_cclip("smoke", **sizes), hparams


def _prior() -> tuple[nn.Module, dict]:
    sizes = {"embed_dim": 16, "hidden": 32, "latent_dim": 4, "kl_weight": 1.0}
    hparams = {"_class_path": "lit_models.prior.CVAEPriorModule", **sizes, "lr": 1e-3}
    return CVAEPrior(PriorConfig(**sizes)), hparams


def _steve() -> tuple[nn.Module, dict]:
    backbone = CVPTModel(CVPTConfig.from_name("tiny", NUM_ACTIONS, **CVPT_SIZES))
    config = CSteve1Config(goal_dim=16, lora_rank=2, lora_targets=["query", "ff.0"], head_hidden=8)
    hparams = {
        "_class_path": "lit_models.csteve1.CSteve1",
        "backbone": "cvpt.ckpt",
        "backbone_config": backbone.config.to_dict(),
        **config.to_dict(),
        "lr": 1e-3,
    }
    return CSteve1Model(backbone, config), hparams


def _frames(shape: tuple[int, ...], seed: int = 0) -> torch.Tensor:
    return torch.from_numpy(
        np.random.default_rng(seed).integers(0, 256, (*shape, 144, 144, 3), dtype=np.uint8)
    )


@torch.no_grad()
def _cvpt_outputs(model: nn.Module) -> list[torch.Tensor]:
    first = torch.tensor([[True, False, False]])
    return [model(_frames((1, 3)), first, model.initial_state(1))[0]]


@torch.no_grad()
def _cclip_outputs(model: nn.Module) -> list[torch.Tensor]:
    return [model.encode_video(_frames((2, 6))), model.encode_text(["go to sleep", "stay"])]


@torch.no_grad()
def _prior_outputs(model: nn.Module) -> list[torch.Tensor]:
    z = torch.nn.functional.normalize(
        torch.randn(3, 16, generator=torch.Generator().manual_seed(0)), dim=-1
    )
    return [model.sample(z, mean=True), *model.encode(z, z)]


@torch.no_grad()
def _steve_outputs(model: nn.Module) -> list[torch.Tensor]:
    goal = torch.randn(1, 3, 16, generator=torch.Generator().manual_seed(0))
    first = torch.tensor([[True, False, False]])
    return [model(_frames((1, 3)), first, goal, model.initial_state(1))[0]]


KINDS: dict[str, tuple[Callable, Callable, Callable]] = {
    # kind: (model + hyper-parameters, outputs on fixed inputs, the one loader for this kind)
    "cvpt": (_cvpt, _cvpt_outputs, partial(load_model, kind="cvpt")),
    "cclip": (_cclip, _cclip_outputs, partial(load_model, kind="cclip")),
    "prior": (_prior, _prior_outputs, partial(load_model, kind="prior")),
    "csteve1": (_steve, _steve_outputs, partial(load_model, kind="csteve1")),
}


@pytest.fixture(scope="module", params=list(KINDS))
def checkpoint(request, tmp_path_factory) -> tuple[str, Path, nn.Module]:
    """(kind, a Lightning-shaped .ckpt, the model in it); weights perturbed so that LoRA and
    the zero-initialised goal projection matter."""
    kind = request.param
    torch.manual_seed(0)
    model, hparams = KINDS[kind][0]()
    with torch.no_grad():
        for param in model.parameters():
            param.add_(0.05 * torch.randn_like(param))
    model.eval()
    path = tmp_path_factory.mktemp(kind) / "best.ckpt"
    state = {f"model.{key}": value for key, value in model.state_dict().items()}
    torch.save({"hyper_parameters": hparams, "state_dict": state, "global_step": 7}, path)
    return kind, path, model


def test_export_round_trip_gives_identical_outputs(checkpoint, tmp_path: Path) -> None:
    kind, path, model = checkpoint
    _, outputs, loader = KINDS[kind]
    out = export_checkpoint(path, tmp_path / "export")
    assert sorted(p.name for p in out.iterdir()) == [
        "config.json",
        "model.safetensors",
        "sha256.txt",
    ]
    assert (
        exported_kind(out) == kind
        and json.loads((out / CONFIG_FILE).read_text())["dtype"] == "float32"
    )
    for source in (path, out):  # the model's loader takes the .ckpt and the folder alike
        loaded = loader(source)
        assert type(loaded) is type(model) and not loaded.training
        assert loaded.state_dict().keys() == model.state_dict().keys()
        for got, want in zip(outputs(loaded), outputs(model), strict=True):
            assert torch.equal(got, want)


@pytest.mark.parametrize("dtype", ["float16", "bfloat16"])
def test_half_precision_loads_as_float32_within_tolerance(
    checkpoint, dtype, tmp_path: Path
) -> None:
    kind, path, model = checkpoint
    _, outputs, loader = KINDS[kind]
    full = export_checkpoint(path, tmp_path / "float32")
    half = export_checkpoint(path, tmp_path / dtype, dtype)
    # stored at half the bytes (integer buffers, if any, and the header aside)
    assert (half / WEIGHTS_FILE).stat().st_size < 0.55 * (full / WEIGHTS_FILE).stat().st_size
    loaded = loader(half)
    assert {p.dtype for p in loaded.state_dict().values() if p.is_floating_point()} == {
        torch.float32
    }
    atol = HALF_ATOL if dtype == "float16" else 8 * HALF_ATOL  # bfloat16 keeps 7 mantissa bits
    for got, want in zip(outputs(loaded), outputs(model), strict=True):
        torch.testing.assert_close(got, want, atol=atol, rtol=0)


def test_kind_comes_from_class_path_or_a_field_only_that_model_has(checkpoint) -> None:
    kind, path, _ = checkpoint
    hparams = torch.load(path, weights_only=True)["hyper_parameters"]
    assert kind_of_hparams(hparams) == kind
    assert kind_of_hparams({k: v for k, v in hparams.items() if k != "_class_path"}) == kind
    assert kind_of_hparams({"lr": 1e-3}) is None


def test_agents_tell_exports_apart(checkpoint, tmp_path: Path) -> None:
    kind, path, _ = checkpoint
    out = export_checkpoint(path, tmp_path / "export")
    if kind in ("cvpt", "csteve1"):
        assert checkpoint_kind(out) == kind
    else:
        with pytest.raises(ValueError, match="export, not an agent"):
            checkpoint_kind(out)


def test_wrong_kind_names_the_file_and_the_expected_kind(checkpoint, tmp_path: Path) -> None:
    kind, path, _ = checkpoint
    out = export_checkpoint(path, tmp_path / "export")
    other = "prior" if kind != "prior" else "cclip"
    other_loader = KINDS[other][2]
    with pytest.raises(ValueError, match=rf"config.json says kind '{kind}'.*expected '{other}'"):
        other_loader(out)
    with pytest.raises(
        ValueError, match=rf"best.ckpt holds a .* checkpoint, expected .*\({other}\)"
    ):
        other_loader(path)


def test_tampered_or_incomplete_folder_is_named(tmp_path: Path) -> None:
    model, _ = _prior()
    out = save_exported(model, tmp_path / "export")
    config = out / CONFIG_FILE
    config.write_text(config.read_text().replace('"hidden": 32', '"hidden": 33'))
    with pytest.raises(ValueError, match=r"checksum mismatch for .*config.json"):
        load_model(out, "prior")
    (out / WEIGHTS_FILE).unlink()
    with pytest.raises(FileNotFoundError, match=r"model.safetensors missing"):
        load_model(out, "prior")
    with pytest.raises(ValueError, match="dtype 'int8'"):
        save_exported(model, tmp_path / "bad", "int8")


def test_cvpt_export_without_kind_still_loads(tmp_path: Path) -> None:
    """Exports written before kinds existed: config.json is the bare CVPTConfig."""
    model, _ = _cvpt()
    out = save_exported(model, tmp_path / "old")
    config = json.loads((out / CONFIG_FILE).read_text())
    (out / CONFIG_FILE).write_text(
        json.dumps({k: v for k, v in config.items() if k not in ("kind", "dtype")})
    )
    (out / "sha256.txt").write_text(
        "".join(f"{sha256_file(out / name)}  {name}\n" for name in (WEIGHTS_FILE, CONFIG_FILE))
    )
    assert exported_kind(out) == "cvpt" and checkpoint_kind(out) == "cvpt"
    assert load_model(out).config == model.config


def test_cli_flags_positional_form_and_errors(tmp_path: Path, capsys) -> None:
    assert set(DTYPE_CHOICES) == set(DTYPES)  # the CLI's copy (no torch import for --help)
    model, hparams = _prior()
    path = tmp_path / "prior.ckpt"
    torch.save(
        {
            "hyper_parameters": hparams,
            "state_dict": {f"model.{k}": v for k, v in model.state_dict().items()},
        },
        path,
    )
    assert (
        zoo_main(
            [
                "export",
                "--checkpoint",
                str(path),
                "--out",
                str(tmp_path / "a"),
                "--dtype",
                "float16",
            ]
        )
        == 0
    )
    assert "exported prior" in capsys.readouterr().out
    assert json.loads((tmp_path / "a" / CONFIG_FILE).read_text())["dtype"] == "float16"
    assert zoo_main(["export", str(path), str(tmp_path / "b")]) == 0
    assert load_model(tmp_path / "b", "prior").config == model.config
    assert zoo_main(["export", str(path), "--out", str(tmp_path / "c")]) == 2
    assert (
        zoo_main(
            ["export", "--checkpoint", str(tmp_path / "none.ckpt"), "--out", str(tmp_path / "d")]
        )
        == 2
    )
    assert "none.ckpt does not exist" in capsys.readouterr().err
