"""Joint names, the SMPL-X kinematic tree and keypoint mappings.

Every index here refers to the joints returned by ``smplx.SMPLX`` (``output.joints``) when the
model has no facial landmarks (the open model) or to their first 76 entries (the licensed
model, which appends 51 face landmarks after them):

====== =============================================================================
index  joints
====== =============================================================================
0-21   the 22 body joints (pelvis ... right_wrist); the paper's MPJPE uses these
22-24  jaw, left_eye_smplhf, right_eye_smplhf
25-39  left hand (index, middle, pinky, ring, thumb; 3 joints each)
40-54  right hand (same order)
55-59  nose, right_eye, left_eye, right_ear, left_ear (mesh vertices)
60-65  left_big_toe, left_small_toe, left_heel, right_big_toe, right_small_toe, right_heel
66-75  fingertips: left thumb, index, middle, ring, pinky; right thumb ... pinky
====== =============================================================================

OpenPose BODY_25 and COCO keypoints are selected from these joints; keypoints with no
SMPL-X counterpart are marked ``-1``.
"""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np

_FINGERS = ("index", "middle", "pinky", "ring", "thumb")  # SMPL-X hand order

SMPLX_JOINT_NAMES: tuple[str, ...] = (
    "pelvis", "left_hip", "right_hip", "spine1", "left_knee", "right_knee", "spine2",
    "left_ankle", "right_ankle", "spine3", "left_foot", "right_foot", "neck",
    "left_collar", "right_collar", "head", "left_shoulder", "right_shoulder",
    "left_elbow", "right_elbow", "left_wrist", "right_wrist",
    "jaw", "left_eye_smplhf", "right_eye_smplhf",
    *(f"left_{f}{k}" for f in _FINGERS for k in (1, 2, 3)),
    *(f"right_{f}{k}" for f in _FINGERS for k in (1, 2, 3)),
)
"""The 55 skeleton joints of SMPL-X, in model order."""

EXTRA_JOINT_NAMES: tuple[str, ...] = (
    "nose", "right_eye", "left_eye", "right_ear", "left_ear",
    "left_big_toe", "left_small_toe", "left_heel",
    "right_big_toe", "right_small_toe", "right_heel",
    "left_thumb", "left_index", "left_middle", "left_ring", "left_pinky",
    "right_thumb", "right_index", "right_middle", "right_ring", "right_pinky",
)
"""Keypoints that smplx appends after the skeleton, each read off one mesh vertex."""

OUTPUT_JOINT_NAMES: tuple[str, ...] = SMPLX_JOINT_NAMES + EXTRA_JOINT_NAMES
NUM_OUTPUT_JOINTS = len(OUTPUT_JOINT_NAMES)  # 76


def _smplx_parents() -> tuple[int, ...]:
    body = (-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19)
    head = (15, 15, 15)  # jaw and eyes hang off the head
    hands: list[int] = []
    for wrist, first in ((20, 25), (21, 40)):
        for finger in range(5):
            base = first + 3 * finger
            hands += [wrist, base, base + 1]
    return body + head + tuple(hands)


SMPLX_PARENTS: tuple[int, ...] = _smplx_parents()
"""Parent index of each of the 55 skeleton joints (-1 for the pelvis)."""

BODY22_NAMES: tuple[str, ...] = SMPLX_JOINT_NAMES[:22]
"""The 22 body joints over which the paper computes MPJPE (pelvis ... right_wrist)."""
NUM_BODY_JOINTS = 22
NUM_POSE_JOINTS = 21  # body joints without the root: theta has 21 x 6 = 126 numbers

BODY_25_NAMES: tuple[str, ...] = (
    "Nose", "Neck", "RShoulder", "RElbow", "RWrist", "LShoulder", "LElbow", "LWrist",
    "MidHip", "RHip", "RKnee", "RAnkle", "LHip", "LKnee", "LAnkle", "REye", "LEye",
    "REar", "LEar", "LBigToe", "LSmallToe", "LHeel", "RBigToe", "RSmallToe", "RHeel",
)
COCO17_NAMES: tuple[str, ...] = (
    "nose", "left_eye", "right_eye", "left_ear", "right_ear", "left_shoulder",
    "right_shoulder", "left_elbow", "right_elbow", "left_wrist", "right_wrist",
    "left_hip", "right_hip", "left_knee", "right_knee", "left_ankle", "right_ankle",
)
COCO18_NAMES: tuple[str, ...] = (
    "Nose", "Neck", "RShoulder", "RElbow", "RWrist", "LShoulder", "LElbow", "LWrist",
    "RHip", "RKnee", "RAnkle", "LHip", "LKnee", "LAnkle", "REye", "LEye", "REar", "LEar",
)
"""OpenPose's COCO-18 layout (COCO-17 plus a neck), as AlphaPose writes it for OpenPose tools."""


def left_right_permutation(names: Sequence[str], parts: Sequence[str] | None = None) -> np.ndarray:
    """(J,) index permutation exchanging left/right keypoints (``L...`` <-> ``R...``).

    Args:
        names: keypoint names (OpenPose style).
        parts: only exchange these parts (e.g. ``("Shoulder", "Elbow", "Wrist")``); None = all.
    """
    perm = np.arange(len(names))
    index = {n: i for i, n in enumerate(names)}
    for i, n in enumerate(names):
        if len(n) > 1 and n[0] in "LR" and n[1].isupper():
            other = ("R" if n[0] == "L" else "L") + n[1:]
            if other in index and (parts is None or n[1:] in parts):
                perm[i] = index[other]
    return perm


# Which SMPL-X output joint stands for each keypoint. MidHip and Neck have no exact
# counterpart; like SMPLify-X we use the pelvis and neck joints.
_KEYPOINT_TO_SMPLX = {
    "Nose": "nose", "Neck": "neck", "MidHip": "pelvis",
    "RShoulder": "right_shoulder", "RElbow": "right_elbow", "RWrist": "right_wrist",
    "LShoulder": "left_shoulder", "LElbow": "left_elbow", "LWrist": "left_wrist",
    "RHip": "right_hip", "RKnee": "right_knee", "RAnkle": "right_ankle",
    "LHip": "left_hip", "LKnee": "left_knee", "LAnkle": "left_ankle",
    "REye": "right_eye", "LEye": "left_eye", "REar": "right_ear", "LEar": "left_ear",
    "LBigToe": "left_big_toe", "LSmallToe": "left_small_toe", "LHeel": "left_heel",
    "RBigToe": "right_big_toe", "RSmallToe": "right_small_toe", "RHeel": "right_heel",
}


def joint_index(name: str) -> int:
    """Index of an SMPL-X output joint (skeleton or extra keypoint) by name."""
    try:
        return OUTPUT_JOINT_NAMES.index(name)
    except ValueError:
        raise KeyError(f"unknown SMPL-X joint {name!r}; see OUTPUT_JOINT_NAMES") from None


def _select(names: tuple[str, ...]) -> tuple[int, ...]:
    out = []
    for n in names:
        target = _KEYPOINT_TO_SMPLX.get(n, n)
        out.append(joint_index(target) if target in OUTPUT_JOINT_NAMES else -1)
    return tuple(out)


BODY_25_FROM_SMPLX: tuple[int, ...] = _select(BODY_25_NAMES)
"""(25,) index into the SMPL-X output joints for each OpenPose BODY_25 keypoint."""
COCO17_FROM_SMPLX: tuple[int, ...] = _select(COCO17_NAMES)
"""(17,) index into the SMPL-X output joints for each COCO-17 keypoint."""
COCO18_FROM_SMPLX: tuple[int, ...] = _select(COCO18_NAMES)
"""(18,) index into the SMPL-X output joints for each OpenPose-COCO-18 keypoint."""

BODY_25_EDGES: tuple[tuple[int, int], ...] = (
    (1, 8), (1, 2), (1, 5), (2, 3), (3, 4), (5, 6), (6, 7), (8, 9), (9, 10), (10, 11),
    (8, 12), (12, 13), (13, 14), (1, 0), (0, 15), (15, 17), (0, 16), (16, 18),
    (14, 19), (19, 20), (14, 21), (11, 22), (22, 23), (11, 24),
)
"""Limb pairs of BODY_25 for drawing skeletons."""
