"""`zoo pipeline --dry-run`: the paper's plan, at its model sizes and sequence shapes, with each
fit shortened for one CPU. The planned fit commands are read back through LightningCLI; the
first stages run for real at the dry sizes; the whole dry run is a slow test.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from zoo.cli import main
from zoo.data.sequences import episode_split
from zoo.pipeline.config import PipelineConfig, load_pipeline_config
from zoo.pipeline.dry_run import CLIP_INIT, SIZES, VAL_FRACTION, changes, dry_config, dry_plan
from zoo.pipeline.runner import run_stages

REPO = Path(__file__).resolve().parents[1]
PAPER = REPO / "configs/pipeline_paper.yaml"
FITS = ("cvpt", "cclip", "csteve1", "prior")


def _paper() -> PipelineConfig:
    config = load_pipeline_config(PAPER)
    assert isinstance(config, PipelineConfig)
    return config


def _keys(out: Path) -> dict[str, Path]:
    """Stand-ins for the key files the wiring reads (the embedding widths) and the data folders
    the fits name (LightningCLI checks that they exist)."""
    for folder in ("data/crafterplay", "data/craftercaption", "data/embed", "keys"):
        (out / folder).mkdir(parents=True)
    for name in ("embed.json", "pairs.json"):
        (out / "keys" / name).write_text(json.dumps({"embed_dim": 512}))
    (out / "keys/pairs.npz").touch()
    return {name: out / "keys" / file for name, file in (
        ("cvpt", "cvpt.ckpt"), ("cclip", "cclip.ckpt"), ("embed", "embed.json"),
        ("prior-pairs", "pairs.npz"), ("csteve1", "csteve1.ckpt"), ("prior", "prior.ckpt"))}


class _Parsed(Exception):
    """The validated config of a command line, before any class is built."""


def _parsed(argv: list[str]) -> dict:
    """The config LightningCLI makes of ``argv``, validated (``--print_config`` skips that) but
    with nothing built, so no data, checkpoint or CLIP file is read."""
    import lightning as L

    from lit_models.cli import ZooCLI

    class ParseOnly(ZooCLI):
        def before_instantiate_classes(self) -> None:
            raise _Parsed(self.config[self.subcommand].as_dict())

    with pytest.raises(_Parsed) as parsed:
        ParseOnly(L.LightningModule, L.LightningDataModule, subclass_mode_model=True,
                  subclass_mode_data=True, auto_configure_optimizers=False, args=argv)
    return parsed.value.args[0]


def test_dry_config_shrinks_data_and_evaluations_and_records_it(tmp_path):
    paper = _paper()
    dry = dry_config(paper, tmp_path)
    assert all(getattr(dry, name) == value for name, value in SIZES.items())
    assert dry.eval_episodes <= 2 and dry.task_episodes <= 2 and dry.device == "cpu"
    for name in ("cvpt_config", "cclip_config", "csteve1_config", "prior_config", "env",
                 "balance", "per_unit", "prior_split", "task"):
        assert getattr(dry, name) == getattr(paper, name), name
    for fit in FITS:  # the config's own overrides first, the dry run's after them (they win)
        assert getattr(dry, f"{fit}_args").startswith(getattr(paper, f"{fit}_args"))
    recorded = changes(paper, dry)
    assert recorded["episodes"] == {"config": 20000, "dry_run": SIZES["episodes"]}
    assert "cvpt_config" not in recorded and "cvpt_args" in recorded


def test_dry_episodes_split_into_training_and_validation():
    """The sequence fits' split fractions put both sides in the dry run's few episodes."""
    split = [episode_split(e, VAL_FRACTION, 0.0) for e in range(SIZES["episodes"])]
    assert split.count("train") >= 2 and split.count("val") >= 2, split


def test_planned_fits_keep_paper_sizes_on_one_cpu(tmp_path):
    out = tmp_path / "out"
    stages = {s.name: s for s in dry_plan(dry_config(_paper(), out), out)}
    assert list(stages)[-1] == "scale"
    assert stages["scale"].command({}) == ["scale", "--out", str(out / "scale")]
    assert Path("configs/cvpt_large.yaml") in stages["scale"].reads  # it projects every config
    assert stages["cclip"].reads == (out / CLIP_INIT,)
    keys = _keys(out)
    parsed = {name: _parsed(stages[name].command(keys))
              for name in (*FITS, "eval-cclip-retrieval")}
    for name, config in parsed.items():
        trainer = config["trainer"]
        assert (trainer["accelerator"], str(trainer["devices"]), trainer["strategy"]) == (
            "cpu", "1", "auto"), name
        assert trainer["max_steps"] <= 2 and trainer["limit_val_batches"] == 2, name
        assert trainer["logger"]["class_path"].endswith("CSVLogger"), name
        assert config["data"]["init_args"]["batch_size"] <= 8, name
    for name in ("cvpt", "csteve1"):
        data = parsed[name]["data"]["init_args"]
        assert data["seq_len"] == 640 and parsed[name]["model"]["init_args"]["tbptt_len"] == 64
        assert parsed[name]["trainer"]["val_check_interval"] == 1  # after the 2-step batch
        assert parsed[name]["trainer"]["precision"] == "bf16-mixed"
    assert parsed["cvpt"]["model"]["init_args"]["model"] == "base"
    online = parsed["cvpt"]["trainer"]["callbacks"][-1]
    assert online["class_path"].endswith("OnlineEvaluation")
    assert online["init_args"]["every_n_steps"] == 1 and online["init_args"]["episodes"] == 1
    assert parsed["csteve1"]["model"]["init_args"]["lora_rank"] == 16
    assert parsed["csteve1"]["model"]["init_args"]["backbone"] == str(keys["cvpt"])
    for name in ("cclip", "eval-cclip-retrieval"):
        model = parsed[name]["model"]["init_args"]
        assert model["model"] == "vit_b16" and model["pretrained_path"] == str(out / CLIP_INIT)
    assert parsed["prior"]["model"]["init_args"]["hidden"] == 512


def test_dry_run_refuses_a_dagger_config(tmp_path, capsys):
    config = REPO / "configs/pipeline_dagger.yaml"
    argv = ["pipeline", "--config", str(config), "--dry-run", "--out", str(tmp_path / "o")]
    assert main(argv) == 2
    assert "--dry-run takes a suite config" in capsys.readouterr().err


def test_first_dry_stages_run(tmp_path):
    """CrafterPlay and CrafterCaption at the dry sizes, each split with what its fit reads: a
    640-step sequence after the noop filter to train and one to validate C-VPT and C-Steve-1,
    C-CLIP's 8 validation and test clips, the prior's 32 pairs."""
    from datamodules.crafterplay import CrafterPlayDataModule

    out = tmp_path / "out"
    stages = [s for s in dry_plan(dry_config(_paper(), out), out)
              if s.name in ("generate", "caption")]
    doc = run_stages(stages, out, {})
    assert doc["ok"], doc["stages"]
    play = out / "data/crafterplay"
    for split in ("train", "val"):
        data = CrafterPlayDataModule(str(play), seq_len=640, batch_size=1, num_workers=0,
                                     val_fraction=VAL_FRACTION, test_fraction=0.0)
        assert sum(1 for _ in data.dataset(split)) >= 1, split
    splits = json.loads((out / "data/craftercaption/manifest.json").read_text())["splits"]
    assert splits["val"]["samples"] >= 8 and splits["test"]["samples"] >= 32
    assert splits["train"]["samples"] >= 8


@pytest.mark.slow
def test_paper_dry_run_end_to_end(tmp_path):
    out = tmp_path / "dry"
    assert main(["pipeline", "--config", str(PAPER), "--dry-run", "--out", str(out)]) == 0
    doc = json.loads((out / "pipeline.json").read_text())
    assert doc["ok"] and doc["dry_run"]["changes"]["device"]["dry_run"] == "cpu"
    assert (out / "scale/scale.md").is_file()
