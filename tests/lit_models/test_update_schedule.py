"""The paper's update schedule: one optimizer step per TBPTT window (STEVE-1's loop), no
gradient across a window edge; and the per-window loop step by
step against one written out by hand: each window's gradient is its own (zeroed between
windows), clipped to ``max_grad_norm`` (also under ``16-mixed``, where Lightning unscales late)
and computed from the memory the previous window left; the curves sit on the optimizer-step
axis; what a mid-batch ``max_steps`` checkpoint resumes from."""

from __future__ import annotations

import csv
from pathlib import Path

import lightning as L
import pytest
import torch
from lightning.pytorch.callbacks import Callback, ModelCheckpoint
from lightning.pytorch.loggers import CSVLogger
from lightning.pytorch.plugins import MixedPrecision
from torch.utils.data import DataLoader

from lit_models.cvpt import CVPT

TINY = dict(
    model="tiny", d_model=16, d_ff=32, n_heads=2, n_layers=1, impala_channels=[2, 4, 4],
    encoder_hidden=16, memory_len=8, input_downsample=4,
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


def _module(tbptt_len: int, weights: dict | None = None) -> CVPT:
    torch.manual_seed(0)
    module = CVPT(**TINY, tbptt_len=tbptt_len, lr=1e-3, cosine_steps=100, max_grad_norm=5.0)
    if weights is not None:
        module.load_state_dict(weights)
    return module


def test_a_640_step_batch_with_windows_of_64_makes_10_optimizer_steps(tmp_path: Path) -> None:
    module = _module(64)
    trainer = _fit(module, [_batch(640)], tmp_path)
    assert trainer.global_step == 10
    assert module.lr_schedulers().last_epoch == 10  # the schedule advanced once per step


def test_max_steps_ends_a_batch_between_windows(tmp_path: Path) -> None:
    trainer = _fit(_module(64), [_batch(640)], tmp_path, max_steps=3)
    assert trainer.global_step == 3


def test_no_gradient_crosses_a_window_edge() -> None:
    """The memory handed to the next window is detached: window 2's loss has no gradient
    w.r.t. window 1's inputs, only w.r.t. its own."""
    module = _module(8).train()
    batch = _batch(16)
    encoded = module.model.encode_frames(batch["frames"]).detach().requires_grad_(True)
    first = batch["first"]
    state = module.model.initial_state(1)
    _, state = module.model.trxl(encoded[:, :8], first[:, :8], state)
    hidden, _ = module.model.trxl(encoded[:, 8:], first[:, 8:], state)
    hidden.sum().backward()
    assert encoded.grad[:, :8].abs().max() == 0
    assert encoded.grad[:, 8:].abs().max() > 0


def test_the_first_step_of_a_batch_is_a_step_on_its_first_window_alone(tmp_path: Path) -> None:
    """Stopped after one step, a 2-window batch has trained on window 1 only: the same weights
    as a run on that window alone. Run on, it makes a second step, on window 2."""
    weights = _module(8).state_dict()
    batch = _batch(16)
    first_window = {k: v[:, :8] for k, v in batch.items()}

    windowed = _module(8, weights)
    _fit(windowed, [batch], tmp_path / "w", max_steps=1)
    one_window = _module(8, weights)
    _fit(one_window, [first_window], tmp_path / "w1")
    for a, b in zip(windowed.parameters(), one_window.parameters()):
        torch.testing.assert_close(a, b)

    both = _module(8, weights)
    assert _fit(both, [batch], tmp_path / "w2").global_step == 2
    moved = [(a - w).abs().max().item() for a, w in zip(both.parameters(), windowed.parameters())]
    assert max(moved) > 1e-5  # the second step moved the weights


WINDOW, WINDOWS = 8, 3


class GradientsAtEachStep(Callback):
    """The gradients each optimizer step applies, recorded after the module's
    ``on_before_optimizer_step`` (where it clips, after Lightning's unscaling): the last point
    before the update. (An optimizer step pre-hook would run too early: Lightning calls the
    backward closure, and so that hook, inside ``optimizer.step``.)"""

    def __init__(self) -> None:
        self.grads: list[list[torch.Tensor]] = []

    def on_train_start(self, trainer: L.Trainer, module: L.LightningModule) -> None:
        clip = module.on_before_optimizer_step

        def clip_then_record(optimizer: torch.optim.Optimizer) -> None:
            clip(optimizer)
            params = [p for g in optimizer.param_groups for p in g["params"]]
            self.grads.append([p.grad.detach().clone() for p in params])

        module.on_before_optimizer_step = clip_then_record


def _clipped_module(weights: dict | None, max_grad_norm: float | None) -> CVPT:
    torch.manual_seed(0)
    module = CVPT(**TINY, tbptt_len=WINDOW, lr=1e-2, cosine_steps=100,
                  max_grad_norm=max_grad_norm)
    if weights is not None:
        module.load_state_dict(weights)
    return module


def _trainer(root: Path, **kwargs) -> L.Trainer:
    options = dict(max_epochs=1, logger=False, enable_checkpointing=False,
                   enable_progress_bar=False, enable_model_summary=False, accelerator="cpu",
                   default_root_dir=root)
    return L.Trainer(**{**options, **kwargs})


def _by_hand(module: CVPT, batch: dict, max_grad_norm: float | None):
    """The paper's loop written out: per window, zeroed gradients, backward of that window's
    loss from the memory the last window left (made by the weights before its step), clip,
    AdamW step, schedule step. Returns the gradients each step applied."""
    config = module.configure_optimizers()
    optimizer, schedule = config["optimizer"], config["lr_scheduler"]["scheduler"]
    state = module.model.initial_state(1)
    applied = []
    for start in range(0, WINDOWS * WINDOW, WINDOW):
        w = slice(start, start + WINDOW)
        logits, state = module.model(batch["frames"][:, w], batch["first"][:, w], state)
        optimizer.zero_grad(set_to_none=True)
        module._loss(logits, batch["actions"][:, w]).backward()
        params = [p for g in optimizer.param_groups for p in g["params"]]
        if max_grad_norm is not None:
            torch.nn.utils.clip_grad_norm_(params, max_grad_norm)
        applied.append([p.grad.detach().clone() for p in params])
        optimizer.step()
        schedule.step()
    return applied


def _norm(grads: list[torch.Tensor]) -> float:
    return float(torch.linalg.vector_norm(torch.stack([torch.linalg.vector_norm(g) for g in grads])))


@pytest.mark.parametrize("max_grad_norm", [0.05, None], ids=["clipped", "unclipped"])
def test_each_window_steps_on_its_own_clipped_gradient_from_carried_memory(
    tmp_path: Path, max_grad_norm: float | None
) -> None:
    """Three windows of one sequence make three steps. The gradient each step applies equals
    a fresh backward of that window alone, from the same weights and the carried memory (so
    gradients are zeroed between windows and the memory is not reset), clipped to the norm
    (raw norms here are ~1-3, above 0.05) or left alone when ``max_grad_norm`` is None; and
    the weights end where the hand-written loop ends."""
    weights = _clipped_module(None, max_grad_norm).state_dict()
    batch = _batch(WINDOWS * WINDOW, seed=1)
    module, seen = _clipped_module(weights, max_grad_norm), GradientsAtEachStep()
    _trainer(tmp_path, callbacks=[seen]).fit(module, DataLoader([batch], batch_size=None))

    reference = _clipped_module(weights, max_grad_norm)
    applied = _by_hand(reference, batch, max_grad_norm)
    assert len(seen.grads) == len(applied) == WINDOWS
    for step, (got, want) in enumerate(zip(seen.grads, applied)):
        for g, w in zip(got, want):
            torch.testing.assert_close(g, w, msg=f"step {step}")
        if max_grad_norm is not None:
            assert _norm(got) == pytest.approx(max_grad_norm, rel=1e-4)
    for a, b in zip(module.parameters(), reference.parameters()):
        torch.testing.assert_close(a, b)


def test_a_step_without_clipping_really_exceeds_the_clip(tmp_path: Path) -> None:
    """The clipped case above is a test of clipping only if the raw gradients exceed it."""
    seen = GradientsAtEachStep()
    _trainer(tmp_path, callbacks=[seen]).fit(
        _clipped_module(None, None), DataLoader([_batch(WINDOWS * WINDOW, seed=1)], batch_size=None)
    )
    assert min(_norm(g) for g in seen.grads) > 10 * 0.05


def test_clipping_under_16_mixed_sees_unscaled_gradients(tmp_path: Path) -> None:
    """With a real GradScaler (scale 65,536) the clip must act on the true gradient: the step
    applies a gradient of norm ``max_grad_norm``, not 1/65,536 of it. (``precision="16-mixed"``
    on CPU falls back to bf16, so the plugin is built as a GPU run would build it.)"""
    seen = GradientsAtEachStep()
    fp16 = MixedPrecision("16-mixed", "cpu", torch.amp.GradScaler("cpu"))
    trainer = _trainer(tmp_path, callbacks=[seen], plugins=[fp16])
    trainer.fit(_clipped_module(None, 0.05), DataLoader([_batch(WINDOWS * WINDOW, seed=1)],
                                                 batch_size=None))
    assert trainer.precision_plugin.scaler is not None
    finite = [g for g in seen.grads if all(torch.isfinite(x).all() for x in g)]
    assert finite
    for grads in finite:
        assert _norm(grads) == pytest.approx(0.05, rel=1e-3)


def test_windows_with_carried_memory_equal_one_pass_and_differ_from_reset() -> None:
    """``forward`` runs window by window; with the memory carried, window 2's logits equal one
    pass over windows 1-2 (trxl.py's segment-invariance, memory_len 8 = one window), and
    differ from window 2 run from empty memory."""
    module = _clipped_module(None, 5.0).eval()
    batch = _batch(2 * WINDOW, seed=2)
    with torch.no_grad():
        windowed = module(batch["frames"], batch["first"])
        one_pass = module.model(batch["frames"], batch["first"],
                                module.model.initial_state(1))[0]
        reset = module.model(batch["frames"][:, WINDOW:], batch["first"][:, WINDOW:],
                             module.model.initial_state(1))[0]
    torch.testing.assert_close(windowed, one_pass)
    assert (windowed[:, WINDOW:] - reset).abs().max() > 1e-4


def test_curves_are_logged_on_the_optimizer_step_axis(tmp_path: Path) -> None:
    """Two batches of three windows: ``train/*`` rows at steps 3 and 6 (optimizer steps, the
    axis of ``online/*``), not at batches 0 and 1; the validation row after the epoch at 6."""
    batches = [_batch(WINDOWS * WINDOW, seed=s) for s in (3, 4)]
    trainer = _trainer(tmp_path, logger=CSVLogger(tmp_path), log_every_n_steps=1,
                       num_sanity_val_steps=0)
    trainer.fit(_clipped_module(None, 5.0), DataLoader(batches, batch_size=None),
                DataLoader(batches[:1], batch_size=None))
    with open(Path(trainer.logger.log_dir) / "metrics.csv") as f:
        rows = list(csv.DictReader(f))
    assert [int(r["step"]) for r in rows if r.get("train/loss")] == [3, 6]
    assert [int(r["step"]) for r in rows if r.get("val/loss")] == [6]


def test_a_mid_batch_checkpoint_resumes_at_the_next_batch(tmp_path: Path) -> None:
    """A checkpoint written after window 2 of a 3-window batch (``every_n_train_steps``)
    resumes at the next batch, as docs/models.md says:
    resumed for the rest of the epoch, it makes the second batch's three steps, 2 + 3 = 5, and
    never replays window 3 of the first (Lightning counts that batch done)."""
    batches = [_batch(WINDOWS * WINDOW, seed=s) for s in (5, 6)]
    saving = ModelCheckpoint(tmp_path / "ckpt", save_last=True, every_n_train_steps=1)
    first = _trainer(tmp_path, max_steps=2, enable_checkpointing=True, callbacks=[saving])
    first.fit(_clipped_module(None, 5.0), DataLoader(batches, batch_size=None))
    last = tmp_path / "ckpt" / "last.ckpt"
    assert torch.load(last, weights_only=False)["global_step"] == 2

    seen = GradientsAtEachStep()
    resumed = _trainer(tmp_path, callbacks=[seen])
    resumed.fit(_clipped_module(None, 5.0), DataLoader(batches, batch_size=None), ckpt_path=last)
    assert resumed.global_step == 5 and len(seen.grads) == 3
