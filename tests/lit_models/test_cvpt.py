"""C-VPT LightningModule: learns, windows are exact, checkpoints rebuild the same model."""

from __future__ import annotations

import math
from pathlib import Path

import lightning as L
import pytest
import torch
from torch.nn import functional as F
from torch.utils.data import DataLoader

from lit_models.cvpt import CVPT
from lit_models.schedules import WarmupCosine
from zoo.weights import load_model
from zoo.weights.checkpoint_io import CheckpointError

SMALL = dict(
    model="tiny", d_model=32, d_ff=64, n_heads=2, n_layers=1, impala_channels=[4, 8, 8],
    encoder_hidden=32, memory_len=4, tbptt_len=4,
)


def _batch(b: int = 2, t: int = 8, seed: int = 0) -> dict[str, torch.Tensor]:
    g = torch.Generator().manual_seed(seed)
    first = torch.zeros(b, t, dtype=torch.bool)
    first[:, 0] = True
    first[0, 5] = True
    actions = torch.randint(0, 17, (b, t), generator=g)
    actions[1, -1] = -1  # an episode's final observation
    frames = torch.randint(0, 256, (b, t, 144, 144, 3), dtype=torch.uint8, generator=g)
    return {"frames": frames, "actions": actions, "first": first}


def _patterned_batch() -> dict[str, torch.Tensor]:
    """One sequence whose frames show the action as a white square at a per-action place."""
    batch = {k: v[:1] for k, v in _batch().items()}
    batch["frames"] = torch.zeros_like(batch["frames"])
    for t, action in enumerate(batch["actions"][0].tolist()):
        row, col = divmod(action, 8)
        batch["frames"][0, t, row * 16 : (row + 1) * 16, col * 16 : (col + 1) * 16] = 255
    return batch


def _repeat(batch: dict[str, torch.Tensor], n: int) -> DataLoader:
    return DataLoader([batch] * n, batch_size=None)


def _trainer(max_steps: int, root: Path) -> L.Trainer:
    return L.Trainer(
        max_steps=max_steps, logger=False, enable_checkpointing=False, enable_progress_bar=False,
        enable_model_summary=False, accelerator="cpu", default_root_dir=root,
    )


ENCODERS = {"impala": {"impala_channels": [2, 4, 4]},
            "tiles": {"encoder": "tiles", "tile_channels": 4}}


@pytest.mark.parametrize("encoder", sorted(ENCODERS))
def test_overfits_a_tiny_batch(tmp_path: Path, encoder: str) -> None:
    torch.manual_seed(0)
    batch = _patterned_batch()
    module = CVPT(
        **{**SMALL, **ENCODERS[encoder]}, lr=1e-2, cosine_steps=1000,
    )
    _trainer(30, tmp_path).fit(module, train_dataloaders=_repeat(batch, 30))
    module.eval()
    with torch.no_grad():
        loss = module._loss(module(batch["frames"], batch["first"]), batch["actions"])
    assert loss < 0.1


def test_loss_ignores_final_observation() -> None:
    module = CVPT(**SMALL)
    logits = torch.randn(2, 3, 17)
    actions = torch.tensor([[1, 2, 3], [4, 5, -1]])
    expected = F.cross_entropy(logits.reshape(-1, 17)[:5], actions.reshape(-1)[:5])
    torch.testing.assert_close(module._loss(logits, actions), expected)


def test_windows_carry_memory_like_one_pass() -> None:
    """Cutting into TBPTT windows changes nothing in the forward pass."""
    torch.manual_seed(0)
    batch = _batch()
    module = CVPT(**SMALL).eval()
    with torch.no_grad():
        windowed = module(batch["frames"], batch["first"])
        one_pass, _ = module.model(batch["frames"], batch["first"], module.model.initial_state(2))
    torch.testing.assert_close(windowed, one_pass, atol=1e-5, rtol=0)


def test_no_decay_for_norms_biases_and_embeddings(tmp_path: Path) -> None:
    module = CVPT(**SMALL, cosine_steps=10)
    optimizer = module.configure_optimizers()["optimizer"]
    decay, no_decay = optimizer.param_groups
    assert decay["weight_decay"] == 1e-4 and no_decay["weight_decay"] == 0.0
    assert all(p.ndim >= 2 for p in decay["params"])
    names = {id(p): n for n, p in module.model.named_parameters()}
    skipped = {names[id(p)] for p in no_decay["params"]}
    assert "trxl.layers.0.attn.relative_bias.weight" in skipped
    assert "trxl.norm.weight" in skipped and "policy_head.bias" in skipped
    assert len(decay["params"]) + len(no_decay["params"]) == len(names)


def test_warmup_cosine_schedule() -> None:
    schedule = WarmupCosine(warmup_steps=10, total_steps=110, min_ratio=0.1)
    assert schedule(0) == pytest.approx(0.1)
    assert schedule(9) == pytest.approx(1.0)
    assert schedule(60) == pytest.approx(0.1 + 0.9 * 0.5 * (1 + math.cos(math.pi * 0.5)))
    assert schedule(110) == pytest.approx(0.1) and schedule(500) == pytest.approx(0.1)


def _trained_checkpoint(
    batch: dict[str, torch.Tensor], root: Path, **overrides: object
) -> tuple[CVPT, Path]:
    """A small CVPT after two steps on ``batch``, and its checkpoint ``root/model.ckpt``."""
    torch.manual_seed(0)
    module = CVPT(**{**SMALL, **overrides}, cosine_steps=100)
    trainer = _trainer(2, root)
    trainer.fit(module, train_dataloaders=_repeat(batch, 2))
    path = root / "model.ckpt"
    trainer.save_checkpoint(path)
    return module, path


@pytest.mark.parametrize("encoder", sorted(ENCODERS))
def test_checkpoint_reload_gives_identical_logits(tmp_path: Path, encoder: str) -> None:
    batch = _batch()
    module, path = _trained_checkpoint(batch, tmp_path, **ENCODERS[encoder])
    module.eval()
    with torch.no_grad():
        expected = module(batch["frames"], batch["first"])
        reloaded = CVPT.load_from_checkpoint(path).eval()
        assert torch.equal(reloaded(batch["frames"], batch["first"]), expected)
        # the same file, read with weights_only torch.load and no Lightning
        plain = load_model(path, "cvpt")
        logits, _ = plain(batch["frames"], batch["first"], plain.initial_state(2))
    torch.testing.assert_close(logits, expected, atol=1e-5, rtol=0)


def test_init_weights_starts_a_new_run_from_a_finished_one(tmp_path: Path) -> None:
    batch = _batch()
    trained, path = _trained_checkpoint(batch, tmp_path)

    follow_up = CVPT(**SMALL, cosine_steps=50, lr=1e-4, init_weights=str(path))
    assert not torch.equal(follow_up.model.policy_head.weight, trained.model.policy_head.weight)
    follow_up.setup("fit")  # where Lightning loads them: construction alone reads no file
    theirs = trained.model.state_dict()
    for name, ours in follow_up.model.state_dict().items():
        assert torch.equal(ours, theirs[name]), name
    # a run that started from init_weights reloads without the file
    _trainer(1, tmp_path).fit(follow_up, train_dataloaders=_repeat(batch, 1))
    path.rename(tmp_path / "gone.ckpt")
    again = tmp_path / "follow_up.ckpt"
    follow_up.trainer.save_checkpoint(again)
    reloaded = CVPT.load_from_checkpoint(again).eval()
    follow_up.eval()
    # the follow-up's own trained weights, not those it started from
    assert not torch.equal(reloaded.model.policy_head.weight, trained.model.policy_head.weight)
    ours, theirs = reloaded.state_dict(), follow_up.state_dict()
    assert ours.keys() == theirs.keys()
    for name in ours:
        assert torch.equal(ours[name], theirs[name]), name
    with torch.no_grad():
        expected = follow_up(batch["frames"], batch["first"])
        assert torch.equal(reloaded(batch["frames"], batch["first"]), expected)

    with pytest.raises(FileNotFoundError, match="model.init_weights=.*gone-too"):
        CVPT(**SMALL, init_weights=str(tmp_path / "gone-too.ckpt")).setup("fit")
    wider = CVPT(**{**SMALL, "d_model": 64}, init_weights=str(tmp_path / "gone.ckpt"))
    with pytest.raises(ValueError, match=r"different C-VPT.*'d_model': \(32, 64\)"):
        wider.setup("fit")


def test_unreadable_init_weights_name_the_option_and_the_file(tmp_path: Path) -> None:
    """`zoo fit --model.init_args.init_weights EMPTY` must not show torch's weights_only advice."""
    empty = tmp_path / "empty.ckpt"
    empty.write_bytes(b"")
    with pytest.raises(CheckpointError) as err:
        CVPT(**SMALL, init_weights=str(empty)).setup("fit")
    assert str(err.value) == (
        f"model.init_weights: {empty}: not a readable checkpoint (empty file); "
        "expected a `zoo fit` checkpoint (.ckpt) or a `zoo export` folder"
    )
