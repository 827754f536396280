"""`zoo fit` through LightningCLI on the smoke config: runs in-process and resumes."""

from __future__ import annotations

import os
from pathlib import Path

import lightning as L
import pytest
import torch
import yaml
from lightning.pytorch.loggers import WandbLogger

from lit_models.cli import run_lightning_cli
from lit_models.cvpt import CVPT
from zoo.agents import dataset_agent
from zoo.data.generate import GenerationConfig, generate

CONFIG = Path(__file__).resolve().parents[1] / "configs" / "cvpt_smoke.yaml"


@pytest.fixture(scope="module")
def crafterplay(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("crafterplay")
    config = GenerationConfig(
        expert="random", episodes=6, seed=1, env="crafter", episodes_per_shard=2,
        chunk_length=32, max_steps=80,
    )
    generate(config, out, progress=False, build_agent=dataset_agent)
    return out


def _fit(crafterplay: Path, root: Path, max_steps: int, *extra: str, wandb: bool = False,
         windows: int = 1):
    """An in-process `zoo fit` of the smoke config; W&B (a service start each, up to a minute on
    a loaded machine) only in the one test that checks it. Sequences of 8 steps in ``windows``
    TBPTT windows: one optimizer step per window."""
    return run_lightning_cli([
        "fit", f"--config={CONFIG}", f"--trainer.default_root_dir={root}",
        f"--trainer.max_steps={max_steps}", "--trainer.limit_val_batches=1",
        "--trainer.enable_progress_bar=false", f"--data.init_args.root={crafterplay}",
        "--data.init_args.seq_len=8", "--data.init_args.batch_size=2",
        "--data.init_args.num_workers=0", "--data.init_args.val_fraction=0.3",
        "--data.init_args.train_batches_per_epoch=2", f"--model.init_args.tbptt_len={8 // windows}",
        "--model.init_args.memory_len=4", *([] if wandb else ["--trainer.logger=false"]), *extra,
    ])


def test_fit_writes_run_folder_and_resumes_at_the_same_step(
    crafterplay: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    started: list[int] = []
    monkeypatch.setattr(CVPT, "on_train_start", lambda self: started.append(self.global_step))
    logged: list[dict] = []
    log_hyperparams = WandbLogger.log_hyperparams
    monkeypatch.setattr(
        WandbLogger, "log_hyperparams", lambda self, p: (logged.append(dict(p)), log_hyperparams(self, p))
    )
    first = _fit(crafterplay, tmp_path, 2, wandb=True)
    assert first.trainer.global_step == 2
    (run_dir,) = tmp_path.iterdir()
    assert (run_dir / "config.yaml").is_file() and (run_dir / "wandb").is_dir()
    last = run_dir / "checkpoints" / "last.ckpt"
    saved = torch.load(last, weights_only=True)
    assert saved["global_step"] == 2
    # the config file's width and the command line's override, as the checkpoint rebuilds them
    hparams = saved["hyper_parameters"]
    assert (hparams["d_model"], hparams["memory_len"], hparams["tbptt_len"]) == (64, 4, 8)
    assert any(p.name.startswith("best-") for p in (run_dir / "checkpoints").iterdir())
    full_configs = [p["config"] for p in logged if "config" in p]
    assert full_configs[0]["model"]["class_path"] == "lit_models.cvpt.CVPT"
    assert full_configs[0]["trainer"]["max_steps"] == 2

    # the checkpoint plays and exports without Lightning
    from zoo.cli import main as zoo_main
    from zoo.weights import load_model

    assert zoo_main(["export", str(last), str(tmp_path / "export")]) == 0
    assert load_model(tmp_path / "export").config == load_model(last, "cvpt").config

    resumed = _fit(crafterplay, tmp_path, 3, f"--ckpt_path={last}")
    assert started == [0, 2]
    assert resumed.trainer.global_step == 3
    assert len([p for p in tmp_path.iterdir() if p.name != "export"]) == 2  # resumed run: own folder


def test_a_checkpoint_with_retired_arguments_resumes_and_other_behaviour_is_refused(
    crafterplay: Path, tmp_path: Path
) -> None:
    """Checkpoints saved before ``update_every``/``activation_checkpointing`` were removed hold
    them in their hyperparameters, which Lightning merges into the config of a resume."""
    from zoo.weights.checkpoint_io import CheckpointError

    _fit(crafterplay, tmp_path / "first", 2)
    (run_dir,) = (tmp_path / "first").iterdir()
    saved = torch.load(run_dir / "checkpoints" / "last.ckpt", weights_only=True)
    saved["hyper_parameters"] |= {"update_every": "window", "activation_checkpointing": False}
    old = tmp_path / "saved_before_the_removal.ckpt"
    torch.save(saved, old)
    resumed = _fit(crafterplay, tmp_path / "resumed", 3, f"--ckpt_path={old}", "--model.init_args.lr=0.123")
    assert resumed.trainer.global_step == 3
    # a resume is the same run: the checkpoint's model arguments win over the command line's
    assert resumed.model.hparams.lr == saved["hyper_parameters"]["lr"] != 0.123

    saved["hyper_parameters"]["update_every"] = "batch"  # a behaviour this version lacks
    torch.save(saved, old)
    with pytest.raises(CheckpointError, match=r"update_every='batch'.*crafter-zoo 0\.1\.0"):
        _fit(crafterplay, tmp_path / "refused", 3, f"--ckpt_path={old}")


def test_last_checkpoint_is_the_newest_not_the_best(crafterplay: Path, tmp_path: Path) -> None:
    # Three validations (every 2 steps); whichever is best, last.ckpt must hold step 6, or a
    # resume would silently redo the steps after the best one.
    cli = _fit(crafterplay, tmp_path, 6)
    (run_dir,) = tmp_path.iterdir()
    checkpoints = run_dir / "checkpoints"
    assert torch.load(checkpoints / "last.ckpt", weights_only=True)["global_step"] == 6
    best = cli.trainer.checkpoint_callbacks[0].best_model_path
    assert Path(best).parent == checkpoints and Path(best).name.startswith("best-step")


CONFIGS = sorted(  # the PPO expert and the pipeline have their own CLIs
    p for p in CONFIG.parent.glob("*.yaml") if not p.name.startswith(("expert_", "pipeline_"))
)


@pytest.mark.parametrize("config", CONFIGS, ids=lambda p: p.stem)
def test_every_shipped_config_parses_and_builds(config: Path) -> None:
    """Each YAML in configs/ names real arguments and builds its model and datamodule (GPU
    configs on this machine's CPU: the hardware flags are overridden, every other value is the
    file's)."""
    from lightning.pytorch.cli import SaveConfigCallback

    from lit_models.cli import ZooCLI

    cli = ZooCLI(
        L.LightningModule, L.LightningDataModule, subclass_mode_model=True,
        subclass_mode_data=True, save_config_callback=SaveConfigCallback,
        auto_configure_optimizers=False, run=False,
        args=[
            f"--config={config}", "--trainer.logger=false", "--trainer.callbacks=[]",
            "--trainer.accelerator=cpu", "--trainer.devices=1", "--trainer.strategy=auto",
            "--trainer.precision=32",
        ],
    )
    # save_hyperparameters() keeps every value the file sets: checkpoints rebuild the model alone
    init_args = yaml.safe_load(config.read_text())["model"]["init_args"]
    assert {k: cli.model.hparams.get(k, "<missing>") for k in init_args} == init_args
    data = cli.datamodule.hparams
    roots = [data["root"]] if data.get("root") else [s["root"] for s in data["sources"]]
    assert roots and all(root.startswith("data/") for root in roots)


def test_predict_writes_the_test_episodes_actions_and_distributions(crafterplay: Path, tmp_path: Path) -> None:
    import numpy as np

    from datamodules.crafterplay import episode_split

    _fit(crafterplay, tmp_path / "fit", 2)
    (run_dir,) = (tmp_path / "fit").iterdir()
    cli = run_lightning_cli([
        "predict", f"--config={CONFIG}", f"--trainer.default_root_dir={tmp_path / 'predict'}",
        "--trainer.enable_progress_bar=false", f"--data.init_args.root={crafterplay}",
        "--data.init_args.seq_len=8", "--data.init_args.batch_size=2",
        "--data.init_args.num_workers=0", "--data.init_args.test_fraction=0.5",
        "--data.init_args.val_fraction=0.3", "--model.init_args.tbptt_len=4",
        "--model.init_args.memory_len=4", f"--ckpt_path={run_dir / 'checkpoints' / 'last.ckpt'}",
    ])
    files = sorted(Path(cli.trainer.default_root_dir, "predictions").glob("batch-0-*.npz"))
    assert files
    for file in files:
        with np.load(file, allow_pickle=False) as pred:
            b, s = pred["action"].shape
            assert pred["probs"].shape == (b, s, 17) and pred["probs"].dtype == np.float32
            np.testing.assert_allclose(pred["probs"].sum(-1), 1.0, rtol=1e-5)
            assert np.array_equal(pred["predicted"], pred["probs"].argmax(-1))
            assert pred["step"].dtype == np.int64 and (pred["step"] >= 0).all()
            assert {episode_split(e, 0.3, 0.5) for e in pred["episode"].ravel()} == {"test"}


def test_two_runs_started_in_the_same_second_get_their_own_folders(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from lit_models import cli

    monkeypatch.setattr(cli.time, "strftime", lambda fmt: "20260101-000000")
    first = cli._new_run_dir(tmp_path)
    second = cli._new_run_dir(tmp_path)
    (tmp_path / f"20260101-000000-{os.getpid()}-2").mkdir()  # left by another session
    third = cli._new_run_dir(tmp_path)
    assert len({first, second, third}) == 3 and not first.exists()
    assert third.name == f"20260101-000000-{os.getpid()}-3"


def _last_checkpoint(root: Path) -> dict:
    (run,) = root.iterdir()
    return torch.load(run / "checkpoints" / "last.ckpt", weights_only=True)


def test_fits_with_one_seed_are_bit_identical_and_other_seeds_differ(
    crafterplay: Path, tmp_path: Path
) -> None:
    # seed_everything fixes the initial weights and (through the datamodule) the order of the
    # shard and sequence shuffles: the same seed must give the same weights, bit for bit.
    for name, seed in (("a", 0), ("b", 0), ("c", 1)):
        _fit(crafterplay, tmp_path / name, 3, f"--seed_everything={seed}")
    a, b, c = (_last_checkpoint(tmp_path / name)["state_dict"] for name in "abc")
    torch.testing.assert_close(b, a, rtol=0, atol=0)
    assert any(not torch.equal(a[k], c[k]) for k in a)


def test_fit_with_the_data_order_alone_changed_ends_elsewhere(
    crafterplay: Path, tmp_path: Path
) -> None:
    # The same initial weights (seed_everything) but another data seed: the weights after 3
    # steps differ, so the bit-identical fits above did depend on the data order being seeded.
    for name, data_seed in (("a", 0), ("b", 1)):
        _fit(crafterplay, tmp_path / name, 3, f"--data.init_args.seed={data_seed}")
    a, b = (_last_checkpoint(tmp_path / name)["state_dict"] for name in "ab")
    assert any(not torch.equal(a[k], b[k]) for k in a)


@pytest.mark.parametrize("windows", [1, 2])
def test_fit_resumed_from_last_ckpt_ends_like_a_straight_fit(
    crafterplay: Path, tmp_path: Path, windows: int
) -> None:
    """2 batches, then --ckpt_path=last.ckpt on to 4, against a straight 4-batch fit: the same
    parameters, optimizer state and LR schedule, bit for bit (CPU, no dropout); with one
    optimizer step per batch and with two (one per TBPTT window)."""
    # An epoch is train_batches_per_epoch=2 batches; last.ckpt is written by the validation at
    # the end of epoch 0 (batch 2). The resumed fit's shuffles must be seeded with the restored
    # epoch 1, as the straight fit's second epoch is, or batches 3-4 train on others.
    # The cosine length is fixed at the full run's steps: the interrupted fit is the same run.
    same = (f"--model.init_args.cosine_steps={4 * windows}",)
    _fit(crafterplay, tmp_path / "straight", 4 * windows, *same, windows=windows)
    _fit(crafterplay, tmp_path / "interrupted", 2 * windows, *same, windows=windows)
    (interrupted,) = (tmp_path / "interrupted").iterdir()
    first_part = interrupted / "checkpoints" / "last.ckpt"
    assert torch.load(first_part, weights_only=True)["global_step"] == 2 * windows
    _fit(crafterplay, tmp_path / "resumed", 4 * windows, *same, f"--ckpt_path={first_part}",
         windows=windows)

    a, b = (_last_checkpoint(tmp_path / run) for run in ("straight", "resumed"))
    assert a["global_step"] == b["global_step"] == 4 * windows
    torch.testing.assert_close(b["state_dict"], a["state_dict"], rtol=0, atol=0)
    (opt_a,), (opt_b,) = a["optimizer_states"], b["optimizer_states"]
    torch.testing.assert_close(opt_b["state"], opt_a["state"], rtol=0, atol=0)
    assert opt_b["param_groups"] == opt_a["param_groups"]
    assert b["lr_schedulers"] == a["lr_schedulers"]


def test_missing_data_is_one_line_and_leaves_no_run_folder(tmp_path: Path, capsys) -> None:
    from zoo.cli import main

    missing = tmp_path / "no-data"
    missing.mkdir()  # a folder without a manifest (a path that does not exist: test_cli_errors)
    argv = ["fit", f"--config={CONFIG}", f"--trainer.default_root_dir={tmp_path / 'runs'}",
            f"--data.init_args.root={missing}", "--trainer.logger=false",
            "--trainer.enable_progress_bar=false", "--data.init_args.num_workers=0"]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1] == (
        f"zoo fit: {missing / 'manifest.json'} not found: not a CrafterPlay folder (make it with "
        "`zoo data generate`); or point data.init_args at an existing folder"
    )
    assert "Traceback" not in "\n".join(err)
    assert not any((tmp_path / "runs").glob("*"))  # the failed run's folder is gone


def test_unreadable_init_weights_is_one_line_without_the_unsafe_advice(
    crafterplay: Path, tmp_path: Path, capsys
) -> None:
    """`zoo fit --model.init_args.init_weights GARBAGE`: torch's weights_only=False advice
    must not reach the user, and no traceback either."""
    from zoo.cli import main

    garbage = tmp_path / "garbage.ckpt"
    garbage.write_bytes(b"not a checkpoint at all")
    argv = ["fit", f"--config={CONFIG}", f"--trainer.default_root_dir={tmp_path / 'runs'}",
            f"--data.init_args.root={crafterplay}", "--trainer.logger=false",
            "--trainer.enable_progress_bar=false", "--data.init_args.num_workers=0",
            f"--model.init_args.init_weights={garbage}"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.strip().splitlines()[-1] == (
        f"zoo fit: model.init_weights: {garbage}: not a readable checkpoint (not a torch zip "
        "archive); expected a `zoo fit` checkpoint (.ckpt) or a `zoo export` folder"
    )
    assert "Traceback" not in err and "weights_only" not in err


def test_fit_from_the_command_line_gives_no_args_warning(
    crafterplay: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import warnings

    monkeypatch.setattr("sys.argv", ["zoo", "fit", "--config", str(CONFIG)])  # as `zoo` sees it
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        _fit(crafterplay, tmp_path, 1)
    assert not [w for w in caught if "not recommended to provide both" in str(w.message)]


@pytest.mark.slow
def test_ddp_on_two_cpu_processes_trains_one_run_to_the_step_count(
    crafterplay: Path, tmp_path: Path
) -> None:
    """`zoo fit` with the DDP strategy: Lightning starts rank 1 by running the command line
    again, which must be the real one, and rank 1 must join rank 0's run folder."""
    import subprocess
    import sys

    zoo = Path(sys.executable).parent / "zoo"
    argv = [
        str(zoo), "fit", f"--config={CONFIG}", f"--trainer.default_root_dir={tmp_path}",
        "--trainer.max_steps=3", "--trainer.limit_val_batches=1", "--trainer.logger=false",
        "--trainer.enable_progress_bar=false", "--trainer.accelerator=cpu",
        "--trainer.devices=2", "--trainer.strategy=ddp", f"--data.init_args.root={crafterplay}",
        "--data.init_args.seq_len=8", "--data.init_args.batch_size=2",
        "--data.init_args.num_workers=0", "--data.init_args.val_fraction=0.3",
        "--data.init_args.train_batches_per_epoch=2", "--model.init_args.tbptt_len=8",
        "--model.init_args.memory_len=4",
    ]
    env = {k: v for k, v in os.environ.items() if "ZOO_" not in k} | {"OMP_NUM_THREADS": "1"}
    done = subprocess.run(argv, env=env, capture_output=True, text=True, timeout=600, check=False)
    assert done.returncode == 0, done.stderr[-2000:]
    (run,) = [p for p in tmp_path.iterdir() if p.is_dir()]  # one folder for both ranks
    assert torch.load(run / "checkpoints" / "last.ckpt", weights_only=True)["global_step"] == 3
