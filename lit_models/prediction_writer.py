"""``zoo predict`` output: each batch's predictions as a plain ``.npz`` in the run folder.

LightningCLI's predict keeps predictions in memory and prints nothing; a researcher wants
files to load in a notebook (``np.load(path)``, no pickle, no Lightning) next to the run's
config.yaml.
"""

from __future__ import annotations

from pathlib import Path

import lightning as L
import numpy as np
import torch
from lightning.pytorch.callbacks import BasePredictionWriter


class NpzPredictionWriter(BasePredictionWriter):
    """Writes ``<run dir>/predictions/batch-{dataloader}-{batch:06d}.npz`` of numeric arrays.

    Args:
        subdir: folder under the trainer's ``default_root_dir`` (the run folder).
    """

    def __init__(self, subdir: str = "predictions") -> None:
        super().__init__(write_interval="batch")
        self.subdir = subdir

    def write_on_batch_end(
        self,
        trainer: L.Trainer,
        pl_module: L.LightningModule,
        prediction: dict[str, torch.Tensor],
        batch_indices,
        batch,
        batch_idx: int,
        dataloader_idx: int = 0,
    ) -> None:
        if not isinstance(prediction, dict):
            raise TypeError(
                f"{type(pl_module).__name__}.predict_step must return a dict of tensors, "
                f"got {type(prediction).__name__}"
            )
        out = Path(trainer.default_root_dir) / self.subdir
        out.mkdir(parents=True, exist_ok=True)
        rank = f"-rank{trainer.global_rank}" if trainer.world_size > 1 else ""
        arrays = {key: value.detach().cpu().numpy() for key, value in prediction.items()}
        np.savez(out / f"batch-{dataloader_idx}-{batch_idx:06d}{rank}.npz", **arrays)
