"""Trained weights in and out: the one loader, export folders, safe checkpoint reads.

``load_model(path, kind=None)`` rebuilds any of the four networks (C-VPT, C-CLIP, the CVAE
prior, C-Steve-1) without Lightning from a ``zoo fit`` ``.ckpt`` or a ``zoo export`` folder
(``zoo/weights/export.py``: export, checksums; ``zoo/weights/kinds.py``: the kinds); ``inference_settings``
says what a model plays with beyond its weights (C-Steve-1's guidance scale and temperature, as
its export records them); ``checkpoint_io`` reads torch files weights-only with errors that name
the file. ``CVPTPolicy.load`` wraps ``load_model`` for acting, ``CSteve1Policy.load`` both.
Imported lazily: ``zoo --help`` must not load torch.
"""

from __future__ import annotations


def __getattr__(name: str):
    if name in __all__:
        from zoo.weights import export

        return getattr(export, name)
    raise AttributeError(f"module 'zoo.weights' has no attribute {name!r}")


__all__ = ["inference_settings", "load_model"]
