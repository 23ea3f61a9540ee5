r"""Evaluation metrics of the paper (Table I) and of the kit's real-data figures.

All functions are plain tensor maths on camera-frame quantities, with arbitrary leading batch
dimensions; metres and radians.

MPE (mean position error)
    ``||tau_est - tau_gt||`` per image and view, averaged over the images of both UAVs. The paper
    states it in the global frame using the ground-truth extrinsics; a rigid transform preserves
    distances, so with the same (ground-truth) extrinsics mapping both estimate and ground truth
    the camera-frame error is identical, and that is what we compute.
MPJPE
    Mean over the 22 SMPL-X body joints of the Euclidean joint error, "root translations aligned"
    without Procrustes: both skeletons are translated so that their pelvis (joint 0) is at the
    origin. Root orientation errors therefore count. (The official evaluation evaluates both
    skeletons with zero translation and SMPL-X's root rotation about the pelvis, which is the same
    alignment.)
PA-MPJPE
    MPJPE after the similarity transform (scale, rotation, translation) that best maps the
    prediction onto the ground truth (Umeyama), a common complement.
Root orientation error
    Geodesic angle between the predicted and ground-truth root rotations, and its two readable
    parts: the yaw error, the wrapped difference of the body headings in the camera
    (``geometry.heading_of``, the pretrained backbone's heading), and the tilt error, the angle
    between the predicted and true body up axes (what the rotation does out of the heading).
Jitter
    Mean norm of the second finite difference (acceleration) of joint positions over a sequence,
    per frame^2, or per s^2 when ``fps`` is given.
Relative camera
    The pose of camera 2 in camera 1 from the two per-view body poses
    (``geometry.relative_camera_pose``), against the same from ground truth (equivalently from the
    extrinsics: ``R_12 = R_1w R_2w^T``): translation error (m) and rotation error (rad).
"""

from __future__ import annotations

import torch
from torch import Tensor

from airpose_lib.geometry import geodesic_angle, heading_of, relative_camera_pose

__all__ = [
    "translation_error",
    "mpe",
    "align_root",
    "joint_errors",
    "mpjpe",
    "procrustes_align",
    "pa_joint_errors",
    "pa_mpjpe",
    "rotation_error",
    "root_yaw_tilt",
    "acceleration",
    "jitter",
    "acceleration_error",
    "relative_camera_errors",
    "relative_pose_errors",
]

PELVIS = 0


def translation_error(tau_pred: Tensor, tau_gt: Tensor) -> Tensor:
    """``||tau_pred - tau_gt||``: ``(..., 3)`` x2 -> ``(...)`` metres."""
    return torch.linalg.vector_norm(tau_pred - tau_gt, dim=-1)


def mpe(tau_pred: Tensor, tau_gt: Tensor) -> Tensor:
    """Mean position error over every leading entry (images x views): ``(..., 3)`` x2 -> scalar."""
    return translation_error(tau_pred, tau_gt).mean()


def align_root(joints: Tensor, root: int | None = PELVIS) -> Tensor:
    """Translate ``joints (..., J, 3)`` so that joint ``root`` is at the origin (None: unchanged)."""
    return joints if root is None else joints - joints[..., root : root + 1, :]


def joint_errors(j_pred: Tensor, j_gt: Tensor, root: int | None = PELVIS) -> Tensor:
    """Per-joint Euclidean errors after root alignment.

    Args:
        j_pred, j_gt: ``(..., J, 3)`` (camera frame, metres).
        root: joint aligned before comparing (pelvis; None: no alignment).

    Returns:
        ``(..., J)``.
    """
    return torch.linalg.vector_norm(align_root(j_pred, root) - align_root(j_gt, root), dim=-1)


def mpjpe(j_pred: Tensor, j_gt: Tensor, root: int | None = PELVIS) -> Tensor:
    """Mean per-joint position error per skeleton: ``(..., J, 3)`` x2 -> ``(...)`` metres."""
    return joint_errors(j_pred, j_gt, root).mean(dim=-1)


def procrustes_align(X: Tensor, Y: Tensor, scale: bool = True) -> Tensor:
    """Similarity transform of ``X`` best matching ``Y`` in least squares (Umeyama 1991).

    Finds ``s, R, t`` (R a proper rotation) minimising ``sum_j ||s R x_j + t - y_j||^2`` and
    returns ``s R X + t``.

    Args:
        X, Y: ``(..., J, 3)``.
        scale: estimate s (otherwise s = 1).

    Returns:
        ``(..., J, 3)``.
    """
    mx, my = X.mean(dim=-2, keepdim=True), Y.mean(dim=-2, keepdim=True)
    Xc, Yc = X - mx, Y - my
    C = Yc.transpose(-1, -2) @ Xc  # (..., 3, 3) cross-covariance
    U, S, Vh = torch.linalg.svd(C)
    d = torch.sign(torch.linalg.det(U @ Vh))
    D = torch.ones_like(S)
    D[..., -1] = torch.where(d == 0, torch.ones_like(d), d)  # no reflections
    R = U @ torch.diag_embed(D) @ Vh
    if scale:
        var = Xc.square().sum(dim=(-1, -2))
        s = (S * D).sum(dim=-1) / var.clamp_min(torch.finfo(X.dtype).tiny)
    else:
        s = torch.ones(X.shape[:-2], dtype=X.dtype, device=X.device)
    return s[..., None, None] * (Xc @ R.transpose(-1, -2)) + my


def pa_joint_errors(j_pred: Tensor, j_gt: Tensor, scale: bool = True) -> Tensor:
    """Per-joint errors after Procrustes alignment: ``(..., J, 3)`` x2 -> ``(..., J)``."""
    return torch.linalg.vector_norm(procrustes_align(j_pred, j_gt, scale) - j_gt, dim=-1)


def pa_mpjpe(j_pred: Tensor, j_gt: Tensor, scale: bool = True) -> Tensor:
    """Procrustes-aligned MPJPE: ``(..., J, 3)`` x2 -> ``(...)``."""
    return pa_joint_errors(j_pred, j_gt, scale).mean(dim=-1)


def rotation_error(R_pred: Tensor, R_gt: Tensor) -> Tensor:
    """Geodesic angle between rotations: ``(..., 3, 3)`` x2 -> ``(...)`` radians in ``[0, pi]``."""
    return geodesic_angle(R_pred, R_gt)


#: The body's up axis in its model frame (SMPL-X: +Y up, facing +Z).
_UP = 1


def root_yaw_tilt(R_pred: Tensor, R_gt: Tensor) -> tuple[Tensor, Tensor]:
    """The root-orientation error split into yaw and tilt.

    Args:
        R_pred, R_gt: ``(..., 3, 3)`` root rotations (model -> camera), broadcastable.

    Returns:
        ``yaw (...)``: ``|heading_of(R_pred) - heading_of(R_gt)|`` wrapped to ``[0, pi]`` (the
        body's heading in the camera's x-z plane, :func:`airpose_lib.geometry.heading_of`);
        ``tilt (...)``: the angle between the predicted and true body up axes ``R[..., :, 1]``,
        ``[0, pi]``. Radians. A turn about the body's own up axis is all yaw and no tilt (the yaw
        is the turn's angle when that axis lies along the camera's y axis); the tilt never exceeds
        the geodesic error.
    """
    d = heading_of(R_pred) - heading_of(R_gt)
    yaw = torch.atan2(torch.sin(d), torch.cos(d)).abs()
    u, v = R_pred[..., :, _UP], R_gt[..., :, _UP]
    u, v = torch.broadcast_tensors(u, v)
    # atan2(|u x v|, u . v): accurate near 0 and pi, where acos of the dot product is not
    tilt = torch.atan2(torch.linalg.vector_norm(torch.linalg.cross(u, v), dim=-1), (u * v).sum(-1))
    return yaw, tilt


def acceleration(x: Tensor, fps: float | None = None) -> Tensor:
    """Second finite difference over time ``x_{t+1} - 2 x_t + x_{t-1}``.

    Args:
        x: ``(..., T, J, 3)`` positions of a sequence (T >= 3).
        fps: frames per second; given, the result is in m/s^2, otherwise m/frame^2.

    Returns:
        ``(..., T - 2, J, 3)``.
    """
    if x.shape[-3] < 3:
        raise ValueError(f"acceleration needs at least 3 frames, got {x.shape[-3]}")
    a = x[..., 2:, :, :] - 2 * x[..., 1:-1, :, :] + x[..., :-2, :, :]
    return a * fps**2 if fps is not None else a


def jitter(x: Tensor, fps: float | None = None) -> Tensor:
    """Mean acceleration norm over frames and joints: ``(..., T, J, 3)`` -> ``(...)``."""
    return torch.linalg.vector_norm(acceleration(x, fps), dim=-1).mean(dim=(-1, -2))


def acceleration_error(x_pred: Tensor, x_gt: Tensor, fps: float | None = None) -> Tensor:
    """Mean norm of the acceleration difference: ``(..., T, J, 3)`` x2 -> ``(...)``."""
    d = acceleration(x_pred, fps) - acceleration(x_gt, fps)
    return torch.linalg.vector_norm(d, dim=-1).mean(dim=(-1, -2))


def relative_camera_errors(phi_pred: Tensor, tau_pred: Tensor, phi_gt: Tensor, tau_gt: Tensor,
                           views: tuple[int, int] = (0, 1)) -> tuple[Tensor, Tensor]:
    """Errors of camera 2's pose in camera 1 computed from the per-view body poses.

    Args:
        phi_pred, phi_gt: ``(..., V, 3, 3)`` root rotations per view.
        tau_pred, tau_gt: ``(..., V, 3)`` root translations per view.
        views: the (camera 1, camera 2) view indices.

    Returns:
        ``t_err (...)`` metres (camera 2's position in camera 1) and ``R_err (...)`` radians.
    """
    i, j = views
    R_p, t_p = relative_camera_pose(phi_pred[..., i, :, :], tau_pred[..., i, :],
                                    phi_pred[..., j, :, :], tau_pred[..., j, :])
    R_g, t_g = relative_camera_pose(phi_gt[..., i, :, :], tau_gt[..., i, :],
                                    phi_gt[..., j, :, :], tau_gt[..., j, :])
    return relative_pose_errors(R_p, t_p, R_g, t_g)


def relative_pose_errors(R: Tensor, t: Tensor, R_ref: Tensor, t_ref: Tensor) -> tuple[Tensor, Tensor]:
    """Errors of camera 2's pose in camera 1 against a reference of the same quantity (from the
    ground-truth body poses, the generated cameras or the ArUco markers).

    Args:
        R, R_ref: ``(..., 3, 3)`` camera 2's orientation in camera 1; t, t_ref: ``(..., 3)`` its position.

    Returns:
        ``t_err (...)`` metres and ``R_err (...)`` radians (geodesic).
    """
    return translation_error(t, t_ref), geodesic_angle(R, R_ref)
