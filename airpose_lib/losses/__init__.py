"""Training and fitting losses."""

from .robust import geman_mcclure
from .supervised import (
    AirPoseLossConfig,
    BaselineLossConfig,
    FullcamLossConfig,
    LossConfig,
    MultiviewLossConfig,
    SupervisedLoss,
    cross_view_mse,
    limb_weights,
    loss_config,
    official_variations,
    view_mse,
)

__all__ = [
    "geman_mcclure",
    "LossConfig",
    "BaselineLossConfig",
    "MultiviewLossConfig",
    "FullcamLossConfig",
    "AirPoseLossConfig",
    "loss_config",
    "official_variations",
    "SupervisedLoss",
    "view_mse",
    "cross_view_mse",
    "limb_weights",
]
