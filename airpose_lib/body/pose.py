"""Small helpers to write SMPL-X body poses by hand, on named joints."""
from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from .forward import rest_body
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


def pose_at_origin(model, body_pose: np.ndarray | None = None,
                   betas: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """One body at the model origin with no root rotation (``V0``).

    A one-body adapter of :func:`airpose_lib.body.forward.rest_body` for the notebooks.

    Args:
        model: a body model (:func:`~airpose_lib.body.load_body_model`, 10 betas).
        body_pose: ``(63,)`` axis-angle of the 21 body joints (None: rest pose).
        betas: ``(10,)`` shape (None: the mean shape).
    Returns:
        vertices ``(V, 3)`` and the 76 joints ``(76, 3)``, float32 numpy, metres.
    """
    theta = np.zeros((1, 63)) if body_pose is None else np.asarray(body_pose, dtype=np.float64)[None]
    beta = np.zeros((1, 10)) if betas is None else np.asarray(betas, dtype=np.float64)[None]
    v, j = rest_body(model, beta, theta)
    return v[0].astype(np.float32), j[0].astype(np.float32)
