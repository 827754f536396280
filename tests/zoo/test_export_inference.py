"""A C-Steve-1 export records the guidance scale and temperature its scores were measured at, and
`CSteve1Policy.load`, `zoo play` and `zoo eval` play at them unless told otherwise (issue 34)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import torch

from zoo.agents import AgentSpec
from zoo.agents.csteve1_agent import CSteve1Policy
from zoo.cli import main
from zoo.envs.constants import NUM_ACTIONS
from zoo.files import sha256_file
from zoo.models.cvpt import CVPTConfig, CVPTModel
from zoo.models.prior import CVAEPrior, PriorConfig
from zoo.models.csteve1 import CSteve1Config, CSteve1Model
from zoo.weights import inference_settings, load_model
from zoo.weights.export import (
    CHECKSUM_FILE,
    CONFIG_FILE,
    INFERENCE,
    WEIGHTS_FILE,
    save_exported,
    verify_export,
)

DEFAULTS = {"cfg_scale": 1.5, "temperature": 1.0}


def _lightning_checkpoint(model: torch.nn.Module, hparams: dict, path: Path) -> Path:
    state = {f"model.{key}": value for key, value in model.state_dict().items()}
    torch.save({"hyper_parameters": hparams, "state_dict": state}, path)
    return path


@pytest.fixture(scope="module")
def steve_ckpt(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A tiny random C-Steve-1, saved as a `zoo fit` run saves it."""
    torch.manual_seed(0)
    backbone = CVPTModel(CVPTConfig.from_name(
        "tiny", NUM_ACTIONS, d_model=32, d_ff=64, n_heads=2, n_layers=1, impala_channels=(2, 4, 4),
        encoder_hidden=32, memory_len=4, input_downsample=4,
    ))
    config = CSteve1Config(goal_dim=16, lora_rank=2)
    hparams = {"_class_path": "lit_models.csteve1.CSteve1", "backbone": "cvpt.ckpt",
               "backbone_config": backbone.config.to_dict(), **config.to_dict()}
    path = tmp_path_factory.mktemp("steve") / "best.ckpt"
    return _lightning_checkpoint(CSteve1Model(backbone, config), hparams, path)


def _export(steve_ckpt: Path, out: Path, *flags: str) -> Path:
    assert main(["export", "--checkpoint", str(steve_ckpt), "--out", str(out), *flags]) == 0
    return out


def _rewrite_config(out: Path, edit) -> None:
    """Change config.json and re-sum it, as an older `zoo export` or a hand edit would leave it."""
    config = json.loads((out / CONFIG_FILE).read_text())
    (out / CONFIG_FILE).write_text(json.dumps(edit(config), indent=2) + "\n")
    (out / CHECKSUM_FILE).write_text(
        "".join(f"{sha256_file(out / name)}  {name}\n" for name in (WEIGHTS_FILE, CONFIG_FILE))
    )


def test_export_records_the_scale_and_loading_plays_at_it(
    steve_ckpt: Path, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    out = _export(steve_ckpt, tmp_path / "export", "--cfg-scale", "0.7")
    assert "(float32, cfg_scale 0.7, temperature 1)" in capsys.readouterr().out
    verify_export(out)  # sha256.txt sums the config.json that holds the block
    recorded = {"cfg_scale": 0.7, "temperature": 1.0}
    assert json.loads((out / CONFIG_FILE).read_text())[INFERENCE] == recorded
    assert inference_settings(out, "csteve1") == recorded
    assert isinstance(load_model(out, "csteve1"), CSteve1Model)  # the block is not a model field
    policy = CSteve1Policy.load(out)
    assert (policy.cfg_scale, policy.temperature, policy.greedy) == (0.7, 1.0, False)
    told = CSteve1Policy.load(out, cfg_scale=2.0, temperature=0.5)
    assert (told.cfg_scale, told.temperature) == (2.0, 0.5)
    assert AgentSpec("csteve1", out).build(1).inference == recorded
    assert AgentSpec("csteve1", out, temperature=0, cfg_scale=0).build(1).inference == {
        "cfg_scale": 0.0, "temperature": 0.0
    }


def test_a_recorded_temperature_of_zero_plays_the_most_likely_action(
    steve_ckpt: Path, tmp_path: Path
) -> None:
    out = _export(steve_ckpt, tmp_path / "export", "--temperature", "0")
    policy = CSteve1Policy.load(out)
    assert (policy.cfg_scale, policy.greedy) == (1.5, True)
    assert AgentSpec("csteve1", out).build(1).inference == {"cfg_scale": 1.5, "temperature": 0.0}


def test_checkpoints_and_older_exports_play_at_the_defaults(
    steve_ckpt: Path, tmp_path: Path
) -> None:
    out = _export(steve_ckpt, tmp_path / "export")
    assert json.loads((out / CONFIG_FILE).read_text())[INFERENCE] == DEFAULTS  # pinned anyway
    _rewrite_config(out, lambda config: {k: v for k, v in config.items() if k != INFERENCE})
    for source in (steve_ckpt, out):
        assert inference_settings(source, "csteve1") == DEFAULTS
        policy = CSteve1Policy.load(source)
        assert (policy.cfg_scale, policy.temperature) == (1.5, 1.0)
    _rewrite_config(out, lambda config: {**config, INFERENCE: {"cfg_scale": 0.25}})
    assert inference_settings(out, "csteve1") == {"cfg_scale": 0.25, "temperature": 1.0}


@pytest.mark.parametrize(
    ("block", "message"),
    [
        ({"cfg_scale": -1}, "must be finite numbers >= 0"),
        ({"cfg_scale": "high"}, "must be finite numbers >= 0"),
        ({"top_k": 3}, r"records no \['top_k'\]"),
        ([0.5], "holds a JSON list, expected an object"),
    ],
)
def test_a_bad_recorded_block_names_the_file(
    steve_ckpt: Path, tmp_path: Path, block: object, message: str
) -> None:
    out = _export(steve_ckpt, tmp_path / "export")
    _rewrite_config(out, lambda config: {**config, INFERENCE: block})
    with pytest.raises(ValueError, match=rf"config.json: .*{message}"):
        CSteve1Policy.load(out)


def test_export_refuses_settings_a_model_does_not_play_with(
    steve_ckpt: Path, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    sizes = {"embed_dim": 16, "hidden": 32, "latent_dim": 4}
    prior = _lightning_checkpoint(CVAEPrior(PriorConfig(**sizes)), sizes, tmp_path / "prior.ckpt")
    assert main(["export", str(prior), str(tmp_path / "prior"), "--cfg-scale", "0.5"]) == 2
    err = capsys.readouterr().err
    assert "a CVAE prior export records no ['cfg_scale']" in err
    assert not (tmp_path / "prior").exists()
    assert main(["export", str(steve_ckpt), str(tmp_path / "bad"), "--cfg-scale", "-1"]) == 2
    assert "must be finite numbers >= 0" in capsys.readouterr().err
    with pytest.raises(ValueError, match=r"C-VPT export records no \['temperature'\]"):
        save_exported(load_model(steve_ckpt, "csteve1").backbone, tmp_path / "cvpt",
                      inference={"temperature": 0.5})


def test_eval_report_and_play_log_record_the_scale_they_played_at(
    steve_ckpt: Path, tmp_path: Path
) -> None:
    out = _export(steve_ckpt, tmp_path / "export", "--cfg-scale", "0.7")
    run = ["eval", "--checkpoint", str(out), "--env", "crafter", "--episodes", "1",
           "--max-steps", "3", "--no-gif"]
    assert main([*run, "--out", str(tmp_path / "recorded")]) == 0
    report = json.loads((tmp_path / "recorded" / "report.json").read_text())
    assert (report["cfg_scale"], report["temperature"]) == (0.7, 1.0)
    assert main([*run, "--cfg-scale", "0", "--out", str(tmp_path / "told")]) == 0
    assert json.loads((tmp_path / "told" / "report.json").read_text())["cfg_scale"] == 0.0
    assert main(["play", "--checkpoint", str(out), "--env", "crafter", "--max-steps", "3",
                 "--out", str(tmp_path / "play")]) == 0
    log = json.loads((tmp_path / "play" / "play.json").read_text())
    assert (log["cfg_scale"], log["temperature"]) == (0.7, 1.0)


def test_cfg_scale_is_for_c_steve_1_only(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    argv = ["eval", "--agent", "random", "--env", "crafter", "--out", str(tmp_path)]
    assert main([*argv, "--cfg-scale", "1.5"]) == 2
    assert "--cfg-scale apply to C-Steve-1 only, not 'random'" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("command", "default"),
    [
        (["eval"], "the scale its export records, else the paper's 1.5"),
        (["tables", "task-table"], "the scale its export records, else the paper's 1.5"),
        (["play"], "the scale its export records, else the paper's 1.5"),
        (["export"], "recorded in config.json as what it plays at (default: the paper's 1.5)"),
    ],
    ids=["tables", "task-table", "play", "export"],
)
def test_help_says_where_the_default_scale_comes_from(
    command: list[str], default: str, capsys: pytest.CaptureFixture
) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main([*command, "--help"])
    assert exit_info.value.code == 0
    assert default in " ".join(capsys.readouterr().out.split())  # argparse wraps help text
