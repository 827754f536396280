"""bench/cvpt_e2e.py and bench/cvpt_profile.py arithmetic on hand-made timestamps; the levers of
bench/cvpt_levers.py compute what they claim to."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[1] / "bench"


def _load(name: str):
    spec = importlib.util.spec_from_file_location(name, BENCH / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


cvpt_e2e = _load("cvpt_e2e")
cvpt_profile = _load("cvpt_profile")
cvpt_levers = _load("cvpt_levers")


def _record() -> dict:
    """8 steps, epochs of 4: steps end at 0, 1, 2, 3 s, then a 2.5-s validation, a checkpoint
    and the next epoch's first step end at 6 s (a steady step would end at 4 s), then 7, 8, 9.
    Each steady step waits 0.1 s for data and spends 0.8 s in Lightning's training batch."""
    ends = [0.0, 1.0, 2.0, 3.0, 6.0, 7.0, 8.0, 9.0]
    steps = [{"step": i + 1, "batch_idx": i % 4, "start": end - 0.8, "end": end,
              "fetch_s": 0.1, "batch_s": 0.8} for i, end in enumerate(ends)]
    checkpoint = "[Callback]ModelCheckpoint{'monitor': 'val/loss'}.on_validation_end"
    return {"steps": steps,
            "validations": [{"after_step": 4, "start": 3.1, "end": 5.6, "batches": 8}],
            "profiler_totals": {checkpoint: [1, 0.2], "run_training_batch": [8, 6.4]}}


def test_steady_steps_leave_out_the_warm_up_and_the_epoch_boundary() -> None:
    """After 1 warm-up step, the intervals are 1, 1, 3 (boundary), 1, 1, 1: steady 1 s per
    step, of which 0.1 s data and 0.8 s batch leave 0.1 s of loop; the boundary costs 2 s
    more, so at 250 steps per epoch a step costs 1 + 2 / 250 s."""
    out = cvpt_e2e.summarize(_record(), warmup=1, frames_per_step=512, recipe_epoch_steps=250)
    assert out["steps_timed"] == 5 and out["s_per_step"] == pytest.approx(1.0)
    assert out["frames_per_s"] == pytest.approx(512.0)
    assert out["data_wait_s_per_step"] == pytest.approx(0.1)
    assert out["loop_between_batches_s_per_step"] == pytest.approx(0.1)
    assert out["epoch_boundary_extra_s"] == pytest.approx(2.0)
    assert out["validation_s"] == pytest.approx(2.5)
    assert out["checkpoint_s_per_epoch"] == pytest.approx(0.2)
    assert out["window"] == {"steps": 6, "seconds": 8.0, "frames_per_s": 6 * 512 / 8.0}
    assert out["recipe_s_per_step"] == pytest.approx(1.0 + 2.0 / 250)


def test_too_few_steps_for_a_steady_state_is_an_error() -> None:
    record = _record()
    record["steps"] = record["steps"][:3]
    with pytest.raises(ValueError, match="warmup"):
        cvpt_e2e.summarize(record, warmup=1, frames_per_step=512, recipe_epoch_steps=250)


def test_the_derived_config_keeps_checkpoints_and_drops_wandb() -> None:
    """One folder replaces the sources; the epoch is 5 batches per worker; W&B goes, the CSV
    logger, the checkpoints and everything else stay; --e2e-set values are read as YAML."""
    recipe = {
        "trainer": {"precision": "bf16-mixed", "max_steps": 4750, "limit_val_batches": 8,
                    "logger": [{"class_path": "lightning.pytorch.loggers.WandbLogger"},
                               {"class_path": "lightning.pytorch.loggers.CSVLogger"}],
                    "callbacks": [{"class_path": "lightning.pytorch.callbacks.ModelCheckpoint"}]},
        "data": {"init_args": {"sources": [{"root": "a"}], "num_workers": 2,
                               "train_batches_per_epoch": 250, "val_fraction": 0.05}},
    }
    config = cvpt_e2e.derived_config(recipe, "data/x", 20, 5, "/tmp/r", "/tmp/r/s.json",
                                     ["data.init_args.val_fraction=0.25"])
    trainer, data = config["trainer"], config["data"]["init_args"]
    assert [lg["class_path"].rsplit(".", 1)[1] for lg in trainer["logger"]] == ["CSVLogger"]
    assert [c["class_path"] for c in trainer["callbacks"]] == [
        "lightning.pytorch.callbacks.ModelCheckpoint", "cvpt_e2e.StepTimer"]
    assert trainer["max_steps"] == 20 and trainer["limit_val_batches"] == 8
    assert data["root"] == "data/x" and data["sources"] is None
    assert data["train_batches_per_epoch"] == 10 and data["val_fraction"] == 0.25
    assert recipe["data"]["init_args"]["sources"] == [{"root": "a"}]  # the recipe is untouched


def test_an_epoch_gives_each_worker_an_equal_share() -> None:
    assert cvpt_e2e.epoch_batches(250, 1) == 250
    assert cvpt_e2e.epoch_batches(250, 0) == 250
    assert cvpt_e2e.epoch_batches(250, 4) == 248


def test_profile_rows_add_up_to_the_step_at_the_recipe_cadence() -> None:
    """Model parts of 0.5 s in all; `zoo fit` adds 0.1 s data wait, 0.2 s more in its batch,
    0.1 s of loop and 0.05 s of amortised boundary: the shares sum to one."""
    parts = dict.fromkeys(cvpt_profile.LABELS, 0.5 / len(cvpt_profile.LABELS)) | {"total": 0.5}
    e2e = {"data_wait_s_per_step": 0.1, "training_batch_s_per_step": 0.7,
           "loop_between_batches_s_per_step": 0.1, "s_per_step": 0.9,
           "recipe_s_per_step": 0.95, "recipe_epoch_steps": 250}
    rows = cvpt_profile.profile_rows(parts, e2e)
    assert sum(r["share"] for r in rows) == pytest.approx(1.0)
    assert sum(r["ms"] for r in rows) == pytest.approx(950.0)
    assert rows[-3]["ms"] == pytest.approx(200.0)
    alone = cvpt_profile.profile_rows(parts, None)
    assert sum(r["share"] for r in alone) == pytest.approx(1.0)


def _tiny_cvpt():
    import torch

    from lit_models.cvpt import CVPT

    torch.manual_seed(0)
    return CVPT(model="tiny", d_model=16, d_ff=32, n_heads=2, n_layers=1,
                impala_channels=[2, 4, 4], encoder_hidden=16, memory_len=8, input_downsample=2,
                cosine_steps=10).eval()


def test_the_channels_last_lever_is_the_same_model() -> None:
    """NHWC views into the encoder give the model's own logits (the lever changes speed only)."""
    import torch

    module = _tiny_cvpt()
    module.model.to(memory_format=torch.channels_last)
    g = torch.Generator().manual_seed(0)
    frames = torch.randint(0, 256, (2, 4, 144, 144, 3), dtype=torch.uint8, generator=g)
    first = torch.zeros(2, 4, dtype=torch.bool)
    state = module.model.initial_state(2)
    with torch.no_grad():
        want = module.model(frames, first, state)[0]
        got = cvpt_levers.channels_last_logits(module.model, frames, first, state)
    torch.testing.assert_close(got, want, atol=1e-5, rtol=1e-5)


def test_pre_downsampled_frames_are_the_rounded_2x2_mean() -> None:
    """A 2x2 block of 1, 2, 3, 4 is stored as round(2.5) = 3 (round half up), in its place."""
    import torch

    frames = torch.zeros(1, 2, 144, 144, 3, dtype=torch.uint8)
    frames[0, 1, 2:4, 2:4, 0] = torch.tensor([[1, 2], [3, 4]], dtype=torch.uint8)
    small = cvpt_levers.pooled({"frames": frames})["frames"]
    assert small.shape == (1, 2, 72, 72, 3) and small.dtype == torch.uint8
    assert small[0, 1, 1, 1, 0] == 3 and int(small.sum()) == 3


@pytest.mark.parametrize("option", ["foreach", "fused"])
def test_the_adamw_levers_reach_every_group_with_the_recipes_settings(option: str) -> None:
    """The lever's AdamW runs its own kernel in every group (a copied group's ``foreach: None``
    would silently win), with the module's lr, betas and per-group weight decay."""
    module = _tiny_cvpt()
    recipe, _ = cvpt_levers.lever_optimizer(module)
    lever, _ = cvpt_levers.lever_optimizer(module, **{option: True})
    assert all(g[option] is True for g in lever.param_groups)
    for a, b in zip(recipe.param_groups, lever.param_groups):
        assert a["params"] == b["params"] and a["weight_decay"] == b["weight_decay"]
        assert (a["lr"], a["betas"], a["eps"]) == (b["lr"], b["betas"], b["eps"])


def test_recipes_take_turns_and_the_speedup_is_the_ratio_of_mean_rates(monkeypatch) -> None:
    """Old, new, old, new: old at 500 then 700 frames/s (mean 600), new at 2,000 and 2,800
    (mean 2,400): a 4x speedup, and 4x again at the validation cadence."""
    rates = iter([500.0, 2000.0, 700.0, 2800.0])
    order = []

    def fake_fit(path, data, warmup, steps, epoch_steps, overrides, code_root=None):
        order.append((str(path), code_root))
        rate = next(rates)
        return {"frames_per_s": rate, "recipe_frames_per_s": rate * 0.9}

    monkeypatch.setattr(cvpt_e2e, "run_fit", fake_fit)
    out = cvpt_e2e.compare_recipes(Path("old.yaml"), Path("new.yaml"), "data/x", 1, 5, 3, [],
                                   old_code=Path("/tmp/before"))
    before, new = ("old.yaml", Path("/tmp/before")), ("new.yaml", None)
    assert order == [before, new, before, new]  # the old recipe on the old code
    assert out["frames_per_s"] == {"old": 600.0, "new": 2400.0}
    assert out["speedup"] == pytest.approx(4.0) and out["recipe_speedup"] == pytest.approx(4.0)
