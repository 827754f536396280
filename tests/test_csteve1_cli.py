"""C-Steve-1 end to end through the commands a user runs: `zoo fit` with configs/csteve1_cpu.yaml
on embedded CrafterPlay, then `zoo play` with a text instruction (C-CLIP -> prior -> goal)."""

from __future__ import annotations

import json
from pathlib import Path

import torch

from lit_models.cli import run_lightning_cli
from zoo.cli import main
from zoo.envs.constants import NUM_ACTIONS
from zoo.models.cvpt import CVPTConfig, CVPTModel
from zoo.models.prior import CVAEPrior, PriorConfig
from zoo.weights.export import save_exported

CONFIG = Path(__file__).resolve().parents[1] / "configs" / "csteve1_cpu.yaml"


def _tiny_backbone(root: Path) -> Path:
    torch.manual_seed(0)
    config = CVPTConfig.from_name(
        "tiny", NUM_ACTIONS, d_model=32, d_ff=64, n_heads=2, n_layers=1, impala_channels=(2, 4, 4),
        encoder_hidden=32, memory_len=4, input_downsample=4,
    )
    return save_exported(CVPTModel(config), root / "cvpt")


def _tiny_prior(path: Path) -> Path:
    """A random CVAE prior saved as Lightning saves lit_models.prior.CVAEPriorModule."""
    torch.manual_seed(0)
    config = {"embed_dim": 64, "hidden": 16, "latent_dim": 4}
    prior = CVAEPrior(PriorConfig(**config))
    state = {f"model.{k}": v for k, v in prior.state_dict().items()}
    torch.save({"hyper_parameters": config, "state_dict": state}, path)
    return path


def test_fit_then_play_an_instruction(
    steve_play: Path, steve_embeddings: Path, steve_cclip: Path, tmp_path: Path
) -> None:
    cli = run_lightning_cli([
        "fit", f"--config={CONFIG}", f"--trainer.default_root_dir={tmp_path / 'runs'}",
        "--trainer.max_steps=2", "--trainer.limit_val_batches=1", "--trainer.logger=false",
        "--trainer.enable_progress_bar=false", "--trainer.precision=32",
        f"--model.init_args.backbone={_tiny_backbone(tmp_path)}", "--model.init_args.tbptt_len=4",
        f"--data.init_args.root={steve_play}", f"--data.init_args.embeddings={steve_embeddings}",
        "--data.init_args.seq_len=8", "--data.init_args.batch_size=2",
        "--data.init_args.num_workers=0", "--data.init_args.val_fraction=0.3",
        "--data.init_args.test_fraction=0.0", "--data.init_args.train_batches_per_epoch=2",
    ])
    assert cli.trainer.global_step == 2
    (checkpoint,) = Path(cli.trainer.default_root_dir).glob("checkpoints/last.ckpt")

    out = tmp_path / "play"
    argv = ["play", "--checkpoint", str(checkpoint), "--instruction", "obtain wood",
            "--cclip", str(steve_cclip), "--prior", str(_tiny_prior(tmp_path / "prior.ckpt")),
            "--env", "crafter", "--max-steps", "12", "--out", str(out)]
    assert main(argv) == 0
    log = json.loads((out / "play.json").read_text())
    assert log["instruction"] == "obtain wood" and log["steps"] == 12 and log["cfg_scale"] == 1.5
    assert len(log["actions"]) == 12 and isinstance(log["unlocked"], dict)
    assert (out / "play.gif").stat().st_size > 0

    both = tmp_path / "side_by_side"
    argv[argv.index("--out") + 1] = str(both)
    argv[3:5] = ["--instruction", "obtain wood", "--instruction", "obtain drink"]
    assert main(argv) == 0
    episodes = json.loads((both / "play.json").read_text())["episodes"]
    assert [e["instruction"] for e in episodes] == ["obtain wood", "obtain drink"]
    import imageio.v3 as iio

    one, two = iio.imread(out / "play.gif"), iio.imread(both / "play.gif")
    assert two.shape[2] == 2 * one.shape[2] + 4  # two tiles and the gap between them

    task_out = tmp_path / "task"
    argv = ["eval", "--task", "make_wood_pickaxe", "--checkpoint", str(checkpoint),
            "--instruction", "craft wood pickaxe", "--cclip", str(steve_cclip), "--prior",
            str(tmp_path / "prior.ckpt"), "--env", "crafter", "--episodes", "2",
            "--max-steps", "8", "--no-gif", "--out", str(task_out)]
    assert main(argv) == 0
    report = json.loads((task_out / "report.json").read_text())
    assert report["episodes"] == 2 and 0 <= report["success_percent"] <= 100
    no_text = ["eval", "--task", "collect_drink", "--checkpoint", str(checkpoint), "--env",
               "crafter", "--episodes", "1", "--no-gif", "--out", str(tmp_path / "no_text")]
    assert main(no_text) == 2  # a task's instructions need --cclip and --prior


def test_goal_width_mismatch_is_named_before_training(
    steve_play: Path, steve_embeddings: Path, tmp_path: Path
) -> None:
    import pytest

    with pytest.raises(ValueError, match="goal_dim=512 but the data's goal embeddings"):
        run_lightning_cli([
            "fit", f"--config={CONFIG}", f"--trainer.default_root_dir={tmp_path / 'runs'}",
            "--trainer.max_steps=1", "--trainer.logger=false", "--trainer.precision=32",
            "--trainer.enable_progress_bar=false", "--model.init_args.goal_dim=512",
            f"--model.init_args.backbone={_tiny_backbone(tmp_path)}",
            f"--data.init_args.root={steve_play}", f"--data.init_args.embeddings={steve_embeddings}",
            "--data.init_args.num_workers=0",
        ])
