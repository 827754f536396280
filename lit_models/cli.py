"""LightningCLI for every model in the zoo: `zoo fit --config configs/<model>.yaml`.

Models and datamodules are chosen by ``class_path`` in the YAML (subclass mode), so C-VPT,
C-CLIP and the rest share this one entry point.
"""

from __future__ import annotations

import contextlib
import io
import logging
import os
import shutil
import sys
import time
import warnings
from pathlib import Path

import lightning as L
import torch
import yaml
from jsonargparse import Namespace
from lightning.pytorch.cli import LightningCLI, SaveConfigCallback
from lightning.pytorch.loggers import WandbLogger

from lit_models.prediction_writer import NpzPredictionWriter
from zoo.data.manifest import MissingDatasetError
from zoo.data.storage import is_url
from zoo.weights.checkpoint_io import CheckpointError


class WandbSaveConfigCallback(SaveConfigCallback):
    """Writes config.yaml (as usual) and also logs the full config to W&B on rank 0."""

    def save_config(self, trainer: L.Trainer, pl_module: L.LightningModule, stage: str) -> None:
        if not trainer.is_global_zero:
            return
        config = yaml.safe_load(self.parser.dump(self.config, skip_none=False))
        for logger in trainer.loggers:
            if isinstance(logger, WandbLogger):
                logger.log_hyperparams({"config": config})


RETIRED_HPARAMS: dict[str, object] = {"update_every": "window", "activation_checkpointing": False}
"""Model arguments this version removed, each with the one value whose behaviour it still has."""


def without_retired(hparams: dict, ckpt_path: str) -> dict:
    """A checkpoint's hyperparameters minus the retired ones, so a run saved before their
    removal resumes; one saved with behaviour the code no longer has is refused by name."""
    kept = dict(hparams)
    for key, value in RETIRED_HPARAMS.items():
        if key not in kept:
            continue
        if kept[key] != value:
            raise CheckpointError(
                f"{ckpt_path} was trained with model.init_args.{key}={kept[key]!r}, which this "
                f"version removed (only {value!r} remains; CHANGELOG.md, 'Removed'): resume it "
                "with crafter-zoo 0.1.0, or start a new run from its weights with "
                "--model.init_args.init_weights"
            )
        del kept[key]
    return kept


_RUN_DIRS_GIVEN: set[Path] = set()


def _new_run_dir(root: Path) -> Path:
    """``root/<time>-<pid>``, with a ``-N`` suffix when that folder exists or was handed to an
    earlier run of this process in the same second (a fit then a resume in a notebook).

    The folder is not created here: ``--print_config`` and ``run=False`` leave no trace."""
    stem = f"{time.strftime('%Y%m%d-%H%M%S')}-{os.getpid()}"
    run_dir, n = root / stem, 0
    while run_dir in _RUN_DIRS_GIVEN or run_dir.exists():
        n += 1
        run_dir = root / f"{stem}-{n}"
    _RUN_DIRS_GIVEN.add(run_dir)
    return run_dir


RUN_DIR_ENV = "ZOO_RUN_DIR"  # a run folder chosen by the user: every rank writes there
_LAUNCHED_RUN_DIR = "_ZOO_LAUNCHED_RUN_DIR"  # rank 0's folder, inherited by ranks it launches


class ZooTrainer(L.Trainer):
    """Lightning's Trainer with its batch limits typed int-first: ``typing`` caches
    ``Union[int, float]`` and ``Union[float, int]`` as one object, so once another library has
    built the float-first one (JAX does, in ``zoo pipeline``'s data stages), jsonargparse reads
    ``limit_val_batches=1`` as 1.0, which Lightning takes as every batch."""

    def __init__(
        self,
        *,
        limit_train_batches: int | float | None = None,
        limit_val_batches: int | float | None = None,
        limit_test_batches: int | float | None = None,
        limit_predict_batches: int | float | None = None,
        overfit_batches: int | float = 0.0,
        **kwargs,
    ) -> None:
        super().__init__(
            limit_train_batches=limit_train_batches, limit_val_batches=limit_val_batches,
            limit_test_batches=limit_test_batches, limit_predict_batches=limit_predict_batches,
            overfit_batches=overfit_batches, **kwargs,
        )


class ZooCLI(LightningCLI):
    """Puts each run in its own folder: ``<trainer.default_root_dir>/<time>-<pid>``.

    The logger's ``save_dir`` and a ModelCheckpoint without ``dirpath`` follow that folder,
    so config.yaml, W&B files and checkpoints of one run sit together and never collide.
    """

    def parse_arguments(self, parser, args) -> None:
        """``zoo`` hands LightningCLI the command line as ``args``; ``sys.argv`` is hidden while
        parsing only (LightningCLI warns when both are set): DDP's launcher starts the other
        ranks by running ``sys.argv`` again, so it must hold the real command line.

        A run whose local data path does not exist stops here, in one line, before the seed,
        W&B and the model summary print."""
        saved = sys.argv
        sys.argv = saved[:1]
        try:
            super().parse_arguments(parser, args)
        finally:
            sys.argv = saved
        subcommand = self.config.get("subcommand")
        if subcommand:  # a run, not a test building the CLI from a config's placeholders
            check_data_paths(self.config[subcommand].data)

    def _parse_ckpt_path(self) -> None:
        """Lightning's merge of a ``--ckpt_path`` checkpoint's hyperparameters into the model
        config (they win over the config's), after dropping the retired ones: Lightning's own
        merge fails on any argument the module no longer takes."""
        subcommand = self.config.get("subcommand")
        ckpt_path = self.config[subcommand].get("ckpt_path") if subcommand else None
        if not ckpt_path or is_url(ckpt_path) or not Path(ckpt_path).is_file():
            return
        saved = torch.load(ckpt_path, weights_only=True, map_location="cpu")
        hparams = without_retired(saved.get("hyper_parameters", {}), ckpt_path)
        hparams.pop("_instantiator", None)
        if not hparams:
            return
        if "_class_path" in hparams:
            hparams = {"class_path": hparams.pop("_class_path"), "dict_kwargs": hparams}
        self.config = self.parser.parse_object({subcommand: {"model": hparams}}, self.config)

    def before_instantiate_classes(self) -> None:
        config = self.config[self.subcommand] if self.subcommand else self.config
        # ZOO_RUN_DIR (set by the user for torchrun/SLURM jobs, whose processes start on their
        # own) names the folder of every rank; ranks that Lightning's DDP launcher started
        # (LOCAL_RANK > 0) join the folder their rank 0 chose
        launched = os.environ.get(_LAUNCHED_RUN_DIR) if int(os.environ.get("LOCAL_RANK", "0")) else None
        if os.environ.get(RUN_DIR_ENV):
            run_dir = Path(os.environ[RUN_DIR_ENV])
            run_dir.mkdir(parents=True, exist_ok=True)
        elif launched:
            run_dir = Path(launched)
        else:
            run_dir = _new_run_dir(Path(config.trainer.default_root_dir or "runs"))
        os.environ[_LAUNCHED_RUN_DIR] = str(run_dir)
        config.trainer.default_root_dir = str(run_dir)
        loggers = config.trainer.logger
        for logger in loggers if isinstance(loggers, list) else [loggers]:
            init_args = getattr(logger, "init_args", None)
            if init_args is not None and "save_dir" in init_args:
                init_args.save_dir = str(run_dir)
        # validate/test/predict restore each ModelCheckpoint's state from --ckpt_path, and
        # Lightning warns when its folder is not the one saved there; outside fit they save
        # nothing, so they keep the folder of the checkpoint they read
        ckpt_path = config.get("ckpt_path") if self.subcommand != "fit" else None
        restored = ckpt_path and not is_url(ckpt_path) and Path(ckpt_path).is_file()
        checkpoints = Path(ckpt_path).parent if restored else run_dir / "checkpoints"
        for callback in config.trainer.callbacks or []:
            init_args = getattr(callback, "init_args", None)
            if callback.class_path.endswith("ModelCheckpoint") and init_args.dirpath is None:
                init_args.dirpath = str(checkpoints)

    def after_instantiate_classes(self) -> None:
        if self.subcommand:  # W&B warns when the folder it is given does not exist yet
            Path(self.trainer.default_root_dir).mkdir(parents=True, exist_ok=True)
        for logger in self.trainer.loggers:
            if isinstance(logger, WandbLogger) and logger._wandb_init.get("anonymous") is None:
                # Lightning hands wandb.init anonymous=None whatever the config says, and wandb
                # warns on any value since anonymous mode was removed (wandb/wandb#10909)
                logger._wandb_init.pop("anonymous", None)


class DataNotFoundError(FileNotFoundError):
    """A run's data is missing (a user error: reported in one line, not as a traceback)."""


DATA_PATH_ARGS = ("root", "embeddings")
"""Datamodule arguments that name data on disk (or at a URL), in every datamodule that has them."""


def check_data_paths(data: Namespace) -> None:
    """Fail on a local data path that does not exist, naming the config field, before W&B
    starts and the model is built (a URL is only read later, by fsspec)."""
    init_args = getattr(data, "init_args", None)
    if init_args is None:
        return
    given = [(f"data.init_args.{name}", init_args.get(name)) for name in DATA_PATH_ARGS]
    given += [
        (f"data.init_args.sources[{i}].root", source.get("root"))
        for i, source in enumerate(init_args.get("sources") or [])
        if isinstance(source, dict)
    ]
    for field, path in given:
        if isinstance(path, str | os.PathLike) and not is_url(path) and not Path(path).exists():
            raise DataNotFoundError(f"{field}={path}: no such file or folder")


def _not_a_tip(record: logging.LogRecord) -> bool:
    return not record.getMessage().startswith("💡 Tip:")


def _silence_dependency_notices() -> None:
    """Drop two messages every run printed that say nothing about the run: Lightning's
    advertisement for litlogger/litmodels (printed whenever neither is used), and torch's
    FutureWarning on ``LeafSpec``, which Lightning's own ``utilities/_pytree.py`` instantiates
    (Lightning 2.6 with a newer torch); nothing in this repository uses LeafSpec."""
    logging.getLogger("lightning.pytorch.utilities.rank_zero").addFilter(_not_a_tip)
    warnings.filterwarnings(
        "ignore",
        message=r"`isinstance\(treespec, LeafSpec\)` is deprecated",
        category=FutureWarning,
        module=r"lightning\.pytorch\.utilities\._pytree",
    )


def _remove_failed_run_dirs(run_dirs: set[Path]) -> None:
    """A run that failed before saving a checkpoint leaves nothing worth keeping: its folder
    (config.yaml, an empty W&B run) would only be mistaken for a result."""
    for run_dir in run_dirs:
        checkpoints = run_dir / "checkpoints"
        if run_dir.is_dir() and not (checkpoints.is_dir() and any(checkpoints.iterdir())):
            shutil.rmtree(run_dir, ignore_errors=True)


def run_lightning_cli(argv: list[str]) -> LightningCLI:
    """Run ``zoo fit|validate|test|predict ARGS`` (argv starts with the verb); ``predict``
    writes its outputs to ``<run dir>/predictions/*.npz``.

    A missing data path raises ``DataNotFoundError``; any failure before the first checkpoint
    removes the run's folder.
    """
    _silence_dependency_notices()
    predicting = bool(argv) and argv[0] == "predict"
    given_before = set(_RUN_DIRS_GIVEN)
    try:
        cli = ZooCLI(
            L.LightningModule,
            L.LightningDataModule,
            trainer_class=ZooTrainer,
            subclass_mode_model=True,
            subclass_mode_data=True,
            save_config_callback=WandbSaveConfigCallback,
            save_config_kwargs={"overwrite": True},
            auto_configure_optimizers=False,
            trainer_defaults={"callbacks": [NpzPredictionWriter()]} if predicting else None,
            args=argv,
            run=True,
        )
    except BaseException as err:
        # a run that failed must not stay the active W&B run: the next in-process run (a
        # notebook's retry) would log into it
        wandb = sys.modules.get("wandb")
        if wandb is not None and wandb.run is not None:
            # its footer would point at the folder removed below
            with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
                wandb.finish(exit_code=1)
        _remove_failed_run_dirs(_RUN_DIRS_GIVEN - given_before)
        if isinstance(err, MissingDatasetError):
            raise DataNotFoundError(
                f"{err}; or point data.init_args at an existing folder"
            ) from err
        raise
    for logger in cli.trainer.loggers:
        if isinstance(logger, WandbLogger):  # the next in-process run gets its own W&B run
            logger.experiment.finish()
    return cli
