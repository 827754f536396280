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
from collections.abc import Iterator
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


class ZooCLI(LightningCLI):
    """Puts each run in its own folder: ``<trainer.default_root_dir>/<time>-<pid>``.

    The logger's ``save_dir`` and a ModelCheckpoint without ``dirpath`` follow that folder,
    so config.yaml, W&B files and checkpoints of one run sit together and never collide.
    """

    def before_instantiate_classes(self) -> None:
        config = self.config[self.subcommand] if self.subcommand else self.config
        run_dir = _new_run_dir(Path(config.trainer.default_root_dir or "runs"))
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


@contextlib.contextmanager
def _argv_only_the_program() -> Iterator[None]:
    """LightningCLI warns when it gets ``args`` while ``sys.argv`` holds arguments too (it
    cannot tell which the user meant); ``zoo`` passes the parsed arguments as ``args``."""
    saved = sys.argv
    sys.argv = saved[:1]
    try:
        yield
    finally:
        sys.argv = saved


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
        with _argv_only_the_program():
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
