"""The online-evaluation callback: a training run logs what the policy scores in the game."""

from __future__ import annotations

import csv
from pathlib import Path

import pytest

from lit_models.cli import run_lightning_cli
from lit_models.online_eval import OnlineEvaluation
from zoo.agents import dataset_agent
from zoo.data.generate import GenerationConfig, generate
from zoo.weights import load_model

ROOT = Path(__file__).resolve().parents[2]
CONFIG = ROOT / "configs" / "cvpt_smoke.yaml"


@pytest.fixture(scope="module")
def crafterplay(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("crafterplay")
    generate(GenerationConfig(expert="random", episodes=6, seed=1, env="crafter",
                              episodes_per_shard=2, chunk_length=32, max_steps=80),
             out, progress=False, build_agent=dataset_agent)
    return out


def test_a_fit_logs_the_crafter_score_at_every_evaluation(crafterplay: Path, tmp_path: Path):
    run_lightning_cli([
        "fit", f"--config={CONFIG}", f"--trainer.default_root_dir={tmp_path}",
        "--trainer.max_steps=4", "--trainer.limit_val_batches=1", "--trainer.log_every_n_steps=1",
        "--trainer.enable_progress_bar=false", f"--data.init_args.root={crafterplay}",
        "--data.init_args.seq_len=8", "--data.init_args.batch_size=2",
        "--data.init_args.num_workers=0", "--data.init_args.val_fraction=0.3",
        "--data.init_args.train_batches_per_epoch=2", "--model.init_args.tbptt_len=4",
        "--model.init_args.memory_len=4",
        "--trainer.logger=lightning.pytorch.loggers.CSVLogger",
        f"--trainer.logger.save_dir={tmp_path}",
        "--trainer.callbacks+=lit_models.online_eval.OnlineEvaluation",
        "--trainer.callbacks.every_n_steps=2", "--trainer.callbacks.episodes=2",
        "--trainer.callbacks.num_envs=2", "--trainer.callbacks.env=crafter",
        "--trainer.callbacks.max_steps=12", "--trainer.callbacks.video=false",
    ])
    (metrics,) = tmp_path.glob("**/metrics.csv")
    with metrics.open() as f:
        rows = [r for r in csv.DictReader(f) if r.get("online/crafter_score")]
    assert [int(r["step"]) for r in rows] == [2, 4]
    for row in rows:
        assert 0 <= float(row["online/crafter_score"]) <= 100
        assert 1 <= float(row["online/episode_length"]) <= 12
        assert "online/success/collect_wood" in row


def test_c_steve_1_is_scored_on_its_task_with_its_instruction():
    weights = {k: ROOT / "weights" / k for k in ("csteve1_cpu", "cclip_cpu", "prior_cpu")}
    callback = OnlineEvaluation(
        episodes=2, num_envs=2, env="crafter", max_steps=10, task="collect_sapling",
        instruction="obtain sapling", cclip=str(weights["cclip_cpu"]),
        prior=str(weights["prior_cpu"]), video=True,
    )
    metrics, rates, frames = callback.evaluate(load_model(weights["csteve1_cpu"], "csteve1"))
    assert 0 <= metrics["online/task_success"] <= 100
    assert set(rates) >= {"collect_sapling", "collect_wood"}
    assert frames is not None and frames.shape[1:] == (144, 144, 3) and len(frames) >= 2


def test_a_half_configured_c_steve_1_evaluation_is_refused():
    with pytest.raises(ValueError, match="task, instruction, cclip and prior"):
        OnlineEvaluation(task="collect_sapling")


def test_wandb_gets_the_bar_chart_and_the_rollout_video(tmp_path, monkeypatch):
    import numpy as np
    from lightning.pytorch.loggers import WandbLogger

    monkeypatch.setenv("WANDB_SILENT", "true")
    logger = WandbLogger(project="crafter-zoo", save_dir=str(tmp_path), offline=True)
    logged = []
    monkeypatch.setattr(type(logger.experiment), "log", lambda self, data, **kw: logged.append(data))
    frames = np.zeros((5, 144, 144, 3), np.uint8)
    OnlineEvaluation()._log_media(logger, {"collect_wood": 50.0}, frames, step=7)
    (media,) = logged
    assert {"online/achievements", "online/rollout"} <= set(media)
    assert media["trainer/global_step"] == 7
    logger.experiment.finish()
