"""Evaluation: the paper's metrics (MPE, MPJPE) and companions (PA-MPJPE, root-orientation error,
jitter, relative-camera errors), and tidy pandas tables of them."""

from .metrics import (
    acceleration,
    acceleration_error,
    align_root,
    jitter,
    joint_errors,
    mpe,
    mpjpe,
    pa_joint_errors,
    pa_mpjpe,
    procrustes_align,
    relative_camera_errors,
    root_yaw_tilt,
    rotation_error,
    translation_error,
)
from .tables import (
    PER_VIEW_METRICS,
    paper_table,
    per_joint_table,
    per_view_table,
    relative_camera_table,
    sequence_table,
    summarize,
    to_long,
)

__all__ = [
    "translation_error", "mpe", "align_root", "joint_errors", "mpjpe", "procrustes_align",
    "pa_joint_errors", "pa_mpjpe", "rotation_error", "root_yaw_tilt", "acceleration", "jitter", "acceleration_error",
    "relative_camera_errors",
    "PER_VIEW_METRICS", "per_view_table", "per_joint_table", "relative_camera_table",
    "sequence_table", "summarize", "paper_table", "to_long",
]
