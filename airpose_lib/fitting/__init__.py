"""AirPose+ (paper Sec. III-D): offline refinement of a whole multi-view sequence with a pose
prior, robust 2D terms and temporal smoothness."""

from .airpose_plus import (
    DETECTOR_JOINTS,
    AirPosePlusConfig,
    AirPosePlusLoss,
    AirPosePlusResult,
    airpose_plus,
    fit_sequence,
    fitting_profile,
    frame_confidence,
    init_from_views,
)

__all__ = [
    "AirPosePlusConfig", "AirPosePlusLoss", "AirPosePlusResult", "DETECTOR_JOINTS", "airpose_plus", "fit_sequence",
    "fitting_profile", "frame_confidence", "init_from_views",
]
