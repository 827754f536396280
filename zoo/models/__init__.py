"""Plain-torch models (no Lightning): encoders, Transformer-XL, the C-VPT policy."""

from zoo.models.cvpt import PAPER_PARAMS, PRESETS, CVPTConfig, CVPTModel
from zoo.models.impala import ImpalaEncoder
from zoo.models.trxl import TransformerXL, TrXLState

__all__ = [
    "PAPER_PARAMS",
    "PRESETS",
    "CVPTConfig",
    "CVPTModel",
    "ImpalaEncoder",
    "TransformerXL",
    "TrXLState",
]
