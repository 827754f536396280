"""The paper's update schedule: one optimizer step per TBPTT window (STEVE-1's loop), per-batch
stepping as a named option, no gradient across a window edge."""

from __future__ import annotations

from pathlib import Path

import lightning as L
import pytest
import torch
from torch.utils.data import DataLoader

from lit_models.cvpt import CVPT

TINY = dict(
    model="tiny", d_model=16, d_ff=32, n_heads=2, n_layers=1, impala_channels=[2, 4, 4],
    encoder_hidden=16, memory_len=8, input_downsample=4, activation_checkpointing=False,
)


def _batch(t: int, seed: int = 0) -> dict[str, torch.Tensor]:
    g = torch.Generator().manual_seed(seed)
    first = torch.zeros(1, t, dtype=torch.bool)
    first[:, 0] = True
    return {
        "frames": torch.randint(0, 256, (1, t, 144, 144, 3), dtype=torch.uint8, generator=g),
        "actions": torch.randint(0, 17, (1, t), generator=g),
        "first": first,
    }


def _fit(module: CVPT, batches: list[dict], root: Path, max_steps: int = -1) -> L.Trainer:
    trainer = L.Trainer(
        max_steps=max_steps, max_epochs=1, logger=False, enable_checkpointing=False,
        enable_progress_bar=False, enable_model_summary=False, accelerator="cpu",
        default_root_dir=root,
    )
    trainer.fit(module, train_dataloaders=DataLoader(batches, batch_size=None))
    return trainer


def _module(update_every: str, tbptt_len: int, weights: dict | None = None) -> CVPT:
    torch.manual_seed(0)
    module = CVPT(**TINY, tbptt_len=tbptt_len, update_every=update_every, lr=1e-3,
                  cosine_steps=100, max_grad_norm=5.0)
    if weights is not None:
        module.load_state_dict(weights)
    return module


def test_a_640_step_batch_with_windows_of_64_makes_10_optimizer_steps(tmp_path: Path) -> None:
    module = _module("window", 64)
    trainer = _fit(module, [_batch(640)], tmp_path)
    assert trainer.global_step == 10
    assert module.lr_schedulers().last_epoch == 10  # the schedule advanced once per step


def test_per_batch_stepping_makes_one_step_per_batch(tmp_path: Path) -> None:
    trainer = _fit(_module("batch", 64), [_batch(640)], tmp_path)
    assert trainer.global_step == 1


def test_max_steps_ends_a_batch_between_windows(tmp_path: Path) -> None:
    trainer = _fit(_module("window", 64), [_batch(640)], tmp_path, max_steps=3)
    assert trainer.global_step == 3


def test_no_gradient_crosses_a_window_edge() -> None:
    """The memory handed to the next window is detached: window 2's loss has no gradient
    w.r.t. window 1's inputs, only w.r.t. its own."""
    module = _module("window", 8).train()
    batch = _batch(16)
    encoded = module.model.encode_frames(batch["frames"]).detach().requires_grad_(True)
    first = batch["first"]
    state = module.model.initial_state(1)
    _, state = module.model.trxl(encoded[:, :8], first[:, :8], state)
    hidden, _ = module.model.trxl(encoded[:, 8:], first[:, 8:], state)
    hidden.sum().backward()
    assert encoded.grad[:, :8].abs().max() == 0
    assert encoded.grad[:, 8:].abs().max() > 0


def test_per_window_and_per_batch_differ_as_expected(tmp_path: Path) -> None:
    """On a 2-window batch: per-window stepping's first step is a per-batch step on window 1
    alone; then it steps again on window 2 with memory from window 1. Per-batch stepping makes
    one step. With a single window the two modes are the same."""
    weights = _module("window", 8).state_dict()
    batch = _batch(16)
    first_window = {k: v[:, :8] for k, v in batch.items()}

    windowed = _module("window", 8, weights)
    _fit(windowed, [batch], tmp_path / "w", max_steps=1)  # stop after window 1's step
    one_window = _module("batch", 8, weights)
    _fit(one_window, [first_window], tmp_path / "b1")
    for a, b in zip(windowed.parameters(), one_window.parameters()):
        torch.testing.assert_close(a, b)

    both = _module("window", 8, weights)
    trainer = _fit(both, [batch], tmp_path / "w2")
    per_batch = _module("batch", 8, weights)
    batch_trainer = _fit(per_batch, [batch], tmp_path / "b2")
    assert (trainer.global_step, batch_trainer.global_step) == (2, 1)
    moved = [
        (a - w).abs().max().item() for a, w in zip(both.parameters(), per_batch.parameters())
    ]
    assert max(moved) > 1e-5  # two steps are not one step

    same = _module("window", 16, weights)
    _fit(same, [batch], tmp_path / "w3")
    also = _module("batch", 16, weights)
    _fit(also, [batch], tmp_path / "b3")
    for a, b in zip(same.parameters(), also.parameters()):
        torch.testing.assert_close(a, b)


def test_unknown_update_every_is_refused() -> None:
    with pytest.raises(ValueError, match="update_every='epoch'"):
        CVPT(**TINY, update_every="epoch")
