"""LightningCLI for every model in the zoo: `zoo fit --config configs/<model>.yaml`.

Models and datamodules are chosen by ``class_path`` in the YAML (subclass mode), so C-VPT,
C-CLIP and the rest share this one entry point.
"""

from __future__ import annotations

import contextlib
import io
import os
import shutil
import sys
import time
from pathlib import Path

import lightning as L
import yaml
from lightning.pytorch.cli import LightningCLI, SaveConfigCallback
from lightning.pytorch.loggers import WandbLogger

from lit_models.prediction_writer import NpzPredictionWriter


class WandbSaveConfigCallback(SaveConfigCallback):
    """Writes config.yaml (as usual) and also logs the full config to W&B on rank 0."""

    def save_config(self, trainer: L.Trainer, pl_module: L.LightningModule, stage: str) -> None:
        if not trainer.is_global_zero:
            return
        config = yaml.safe_load(self.parser.dump(self.config, skip_none=False))
        for logger in trainer.loggers:
            if isinstance(logger, WandbLogger):
                logger.log_hyperparams({"config": config})


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


class ZooCLI(LightningCLI):
    """Puts each run in its own folder: ``<trainer.default_root_dir>/<time>-<pid>``.

    The logger's ``save_dir`` and a ModelCheckpoint without ``dirpath`` follow that folder,
    so config.yaml, W&B files and checkpoints of one run sit together and never collide.
    """

    def parse_arguments(self, parser, args) -> None:
        """``zoo`` hands LightningCLI the command line as ``args``; ``sys.argv`` is hidden while
        parsing only (LightningCLI warns when both are set): DDP's launcher starts the other
        ranks by running ``sys.argv`` again, so it must hold the real command line."""
        saved = sys.argv
        sys.argv = saved[:1]
        try:
            super().parse_arguments(parser, args)
        finally:
            sys.argv = saved

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
        for callback in config.trainer.callbacks or []:
            init_args = getattr(callback, "init_args", None)
            if callback.class_path.endswith("ModelCheckpoint") and init_args.dirpath is None:
                init_args.dirpath = str(run_dir / "checkpoints")


class DataNotFoundError(FileNotFoundError):
    """A run's data is missing (a user error: reported in one line, not as a traceback)."""


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

    A missing data folder raises ``DataNotFoundError``; any failure before the first checkpoint
    removes the run's folder.
    """
    predicting = bool(argv) and argv[0] == "predict"
    given_before = set(_RUN_DIRS_GIVEN)
    try:
        cli = ZooCLI(
            L.LightningModule,
            L.LightningDataModule,
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
        if isinstance(err, FileNotFoundError) and "manifest.json" in str(err):
            raise DataNotFoundError(str(err)) from err
        raise
    for logger in cli.trainer.loggers:
        if isinstance(logger, WandbLogger):  # the next in-process run gets its own W&B run
            logger.experiment.finish()
    return cli
