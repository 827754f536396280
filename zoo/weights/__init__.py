"""Trained weights in and out: the one loader, export folders, safe checkpoint reads.

``load_model(path, kind=None)`` rebuilds any of the four networks (C-VPT, C-CLIP, the CVAE
prior, C-Steve-1) without Lightning from a ``zoo fit`` ``.ckpt`` or a ``zoo export`` folder
(``zoo/weights/export.py``: the kinds registry, export, checksums); ``checkpoint_io`` reads
torch files weights-only with errors that name the file. ``CVPTPolicy.load`` and
``StevePolicy.load`` wrap ``load_model`` for acting. Imported lazily: ``zoo --help`` must not
load torch.
"""

from __future__ import annotations


def __getattr__(name: str):
    if name == "load_model":
        from zoo.weights.export import load_model

        return load_model
    raise AttributeError(f"module 'zoo.weights' has no attribute {name!r}")


__all__ = ["load_model"]
