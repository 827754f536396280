"""C-Steve-1 LightningModule: learns to follow goals with LoRA + conditioning alone, reloads."""

from __future__ import annotations

import shutil
from pathlib import Path

import lightning as L
import pytest
import torch
from torch.utils.data import DataLoader

from lit_models.csteve1 import CSteve1
from zoo.envs.constants import NUM_ACTIONS
from zoo.models.cvpt import CVPTConfig, CVPTModel
from zoo.weights.export import save_exported

GOAL_DIM = 17  # one-hot goals naming the action to take


def _backbone_export(root: Path) -> Path:
    torch.manual_seed(0)
    config = CVPTConfig.from_name(
        "tiny", NUM_ACTIONS, d_model=32, d_ff=64, n_heads=2, n_layers=1, impala_channels=(2, 4, 4),
        encoder_hidden=32, memory_len=4, input_downsample=4,
    )
    return save_exported(CVPTModel(config), root / "cvpt_export")


def _goal_batch(seed: int = 0, b: int = 2, t: int = 8) -> dict[str, torch.Tensor]:
    """Identical frames everywhere; the action is whatever the one-hot goal names."""
    g = torch.Generator().manual_seed(seed)
    actions = torch.randint(0, 17, (b, t), generator=g)
    first = torch.zeros(b, t, dtype=torch.bool)
    first[:, 0] = True
    frames = torch.full((b, t, 144, 144, 3), 90, dtype=torch.uint8)
    goal = torch.nn.functional.one_hot(actions, GOAL_DIM).to(torch.float16)
    goal_mask = torch.ones(b, t, dtype=torch.bool)
    return {"frames": frames, "actions": actions, "first": first, "goal": goal, "goal_mask": goal_mask}


def _trainer(max_steps: int, root: Path, **kwargs) -> L.Trainer:
    return L.Trainer(
        max_steps=max_steps, logger=False, enable_progress_bar=False, enable_model_summary=False,
        accelerator="cpu", default_root_dir=root, **{"enable_checkpointing": False, **kwargs},
    )


def _loss(module: CSteve1, batch: dict[str, torch.Tensor], goal: torch.Tensor) -> float:
    with torch.no_grad():
        return float(module._loss(module(batch["frames"], batch["first"], goal), batch["actions"]))


def test_learns_to_follow_the_goal_with_only_lora_and_conditioning(tmp_path: Path) -> None:
    backbone = _backbone_export(tmp_path)
    module = CSteve1(
        backbone=str(backbone), goal_dim=GOAL_DIM, lora_rank=4, lr=3e-2, tbptt_len=4,
        cosine_steps=1000,
    )
    module.configure_model()
    base = {n: p.detach().clone() for n, p in module.model.named_parameters() if not p.requires_grad}
    batch = _goal_batch()
    shuffled = batch["goal"][:, torch.randperm(batch["goal"].shape[1])]
    untrained = _loss(module, batch, batch["goal"])
    _trainer(80, tmp_path).fit(module, train_dataloaders=DataLoader([batch] * 80, batch_size=None))
    module.eval()
    followed, misled = _loss(module, batch, batch["goal"]), _loss(module, batch, shuffled)
    # frames are identical, so only the goal can tell the actions apart
    assert followed < 0.25 < untrained and misled > 2 * followed
    for name, param in module.model.named_parameters():
        if name in base:
            assert torch.equal(param, base[name]), f"frozen {name} changed in training"


def test_validation_reports_what_the_goal_is_worth(tmp_path: Path) -> None:
    module = CSteve1(
        backbone=str(_backbone_export(tmp_path)), goal_dim=GOAL_DIM, lora_rank=2, lr=3e-2,
        tbptt_len=4, cosine_steps=1000,
    )
    batch = _goal_batch()
    trainer = _trainer(40, tmp_path)

    def validate() -> dict[str, float]:
        (metrics,) = trainer.validate(module, DataLoader([batch], batch_size=None), verbose=False)
        return metrics

    untrained = validate()
    assert untrained["val/loss_goal"] == pytest.approx(untrained["val/loss_nogoal"], abs=1e-6)
    trainer.fit(module, train_dataloaders=DataLoader([batch] * 40, batch_size=None))
    trained = validate()
    assert trained["val/loss_goal"] < 0.5 * trained["val/loss_nogoal"]


def test_checkpoint_reloads_without_the_backbone_file(tmp_path: Path) -> None:
    backbone = _backbone_export(tmp_path)
    module = CSteve1(backbone=str(backbone), goal_dim=GOAL_DIM, lora_rank=2, lr=1e-2, tbptt_len=4,
                     cosine_steps=100)
    batch = _goal_batch()
    trainer = _trainer(3, tmp_path)
    trainer.fit(module, train_dataloaders=DataLoader([batch] * 3, batch_size=None))
    path = tmp_path / "csteve1.ckpt"
    trainer.save_checkpoint(path)
    shutil.rmtree(backbone)
    reloaded = CSteve1.load_from_checkpoint(path).eval()
    module.eval()
    with torch.no_grad():
        expected = module(batch["frames"], batch["first"], batch["goal"])
        torch.testing.assert_close(reloaded(batch["frames"], batch["first"], batch["goal"]), expected)
    assert reloaded.hparams.backbone_config["d_model"] == 32


def test_optimizer_holds_only_trainable_parameters(tmp_path: Path) -> None:
    module = CSteve1(backbone=str(_backbone_export(tmp_path)), goal_dim=GOAL_DIM, cosine_steps=10)
    module.configure_model()
    optimizer = module.configure_optimizers()["optimizer"]
    in_optimizer = {id(p) for group in optimizer.param_groups for p in group["params"]}
    trainable = {id(p) for p in module.model.trainable_parameters().values()}
    assert in_optimizer == trainable


def test_missing_backbone_is_a_clear_error(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="model.init_args.backbone is required"):
        CSteve1()
    module = CSteve1(backbone=str(tmp_path / "nowhere.ckpt"))  # a config check reads no file
    with pytest.raises(FileNotFoundError, match="nowhere.ckpt"):
        module.configure_model()


def test_init_weights_starts_a_new_run_from_a_finished_one(tmp_path: Path) -> None:
    """A DAgger round: the last round's network, a fresh optimizer; the new run reloads
    without the file it started from, and another architecture is refused by name."""
    backbone = _backbone_export(tmp_path)
    settings = dict(backbone=str(backbone), goal_dim=GOAL_DIM, lora_rank=2, tbptt_len=4)
    first = CSteve1(**settings, lr=3e-2, cosine_steps=100)
    batch = _goal_batch()
    trainer = _trainer(20, tmp_path)
    trainer.fit(first, train_dataloaders=DataLoader([batch] * 20, batch_size=None))
    path = tmp_path / "round0.ckpt"
    trainer.save_checkpoint(path)

    follow_up = CSteve1(**settings, lr=1e-9, cosine_steps=100, init_weights=str(path))
    follow_up.configure_model()
    assert _loss(follow_up, batch, batch["goal"]) > _loss(first.eval(), batch, batch["goal"]) + 0.1
    again = _trainer(1, tmp_path)
    again.fit(follow_up, train_dataloaders=DataLoader([batch], batch_size=None))
    follow_up.eval()
    # one step at lr 1e-9: the network is round 0's
    assert _loss(follow_up, batch, batch["goal"]) == pytest.approx(
        _loss(first, batch, batch["goal"]), abs=1e-4)
    path.rename(tmp_path / "gone.ckpt")
    saved = tmp_path / "round1.ckpt"
    again.save_checkpoint(saved)
    reloaded = CSteve1.load_from_checkpoint(saved).eval()
    with torch.no_grad():
        torch.testing.assert_close(reloaded(batch["frames"], batch["first"], batch["goal"]),
                                   follow_up(batch["frames"], batch["first"], batch["goal"]))

    wider = CSteve1(**{**settings, "lora_rank": 4}, cosine_steps=10,
                    init_weights=str(tmp_path / "gone.ckpt"))
    with pytest.raises(Exception, match="holds a different C-Steve-1.*lora_rank"):
        _trainer(1, tmp_path).fit(wider, train_dataloaders=DataLoader([batch], batch_size=None))
