"""Small helpers to write SMPL-X body poses by hand, on named joints."""
from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from .joint_sets import NUM_POSE_JOINTS, joint_index


def axis_angle(*steps: tuple[str, float]) -> np.ndarray:
    """Axis-angle (3,) of rotations about the parent frame's x/y/z axes, applied in order.

    In the SMPL-X rest pose every joint frame is aligned with the world: x = the subject's left,
    y = up, z = forward. ``axis_angle(("z", -1.2), ("x", 0.3))`` first rotates -1.2 rad about z,
    then 0.3 rad about x.
    """
    r = Rotation.identity()
    for axis, angle in steps:
        r = Rotation.from_rotvec(angle * np.eye(3)["xyz".index(axis)]) * r
    return r.as_rotvec()


def body_pose_from_joints(rotations: dict[str, np.ndarray]) -> np.ndarray:
    """(63,) axis-angle body pose from ``{SMPL-X joint name: axis-angle (3,)}``.

    Joints not named stay at rest. Only the 21 body joints (left_hip ... right_wrist) are allowed:
    the pelvis rotation is the root rotation phi, not part of the body pose.
    """
    theta = np.zeros((NUM_POSE_JOINTS, 3))
    for name, rotvec in rotations.items():
        k = joint_index(name) - 1  # body_pose starts at joint 1 (left_hip)
        if not 0 <= k < NUM_POSE_JOINTS:
            raise KeyError(f"{name!r} is not one of the 21 body joints of body_pose")
        theta[k] = rotvec
    return theta.reshape(-1)
