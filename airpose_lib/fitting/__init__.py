"""AirPose+ (paper Sec. III-D): offline refinement of a whole multi-view sequence with a pose
prior, robust 2D terms and temporal smoothness."""

from .airpose_plus import (
    DETECTOR_JOINTS,
    AirPosePlusConfig,
    AirPosePlusLoss,
    AirPosePlusResult,
    airpose_plus,
    fit_sequence,
    frame_confidence,
    init_from_views,
)
from .recording import fit_config, initialisation_for, open_initialisation, refined_path, save_refinement

__all__ = [
    "AirPosePlusConfig", "AirPosePlusLoss", "AirPosePlusResult", "DETECTOR_JOINTS", "airpose_plus", "fit_sequence",
    "frame_confidence", "init_from_views", "fit_config", "initialisation_for",
    "open_initialisation", "refined_path", "save_refinement",
]
