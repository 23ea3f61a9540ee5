"""The drones' poses from the ArUco markers on the ground, frame by frame.

One type for both sources: the marker search in a recording's images
(:func:`airpose_lib.data.sequences.markers.sequence_marker_poses`) and the official release's
marker files (:func:`airpose_lib.data.official.real.load_marker_poses`). Numpy only, so reading
the official files imports neither OpenCV nor torch.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["MarkerPoses"]


@dataclass
class MarkerPoses:
    """The ArUco board seen by each drone.

    Attributes:
        frames: ``(F,)`` frame numbers.
        R_cm: ``(F, V, 3, 3)`` marker -> camera rotation of each view.
        t_cm: ``(F, V, 3)`` marker -> camera translation (metres).
        valid: ``(F, V)`` bool, marker detected.
    """

    frames: np.ndarray
    R_cm: np.ndarray
    t_cm: np.ndarray
    valid: np.ndarray
