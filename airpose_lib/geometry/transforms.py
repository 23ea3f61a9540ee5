"""Rigid transforms between body, camera and world frames.

Notation: ``R_ab, t_ab`` maps coordinates of frame b to frame a, ``x_a = R_ab x_b + t_ab``; the
matching 4x4 matrix is ``T_ab``. Frames: B (body model), W (world, Y up), C (camera, OpenCV).

The paper's root convention makes the body pose a plain rigid transform: vertices are posed as
``V = R V0 + t`` about the SMPL-X **model origin** (t is not the pelvis position), so the
root rotation and translation of a view are exactly ``(R_cb, t_cb)`` and compose like any
other transform.
"""

from __future__ import annotations

import torch
from torch import Tensor

__all__ = [
    "make_transform",
    "split_transform",
    "invert_transform",
    "compose",
    "apply_transform",
    "body_in_camera",
    "relative_camera_pose",
    "camera_center",
]


def make_transform(R: Tensor, t: Tensor) -> Tensor:
    """Stack ``R (..., 3, 3)`` and ``t (..., 3)`` (broadcastable) into ``T (..., 4, 4)``."""
    batch = torch.broadcast_shapes(R.shape[:-2], t.shape[:-1])
    dtype = torch.promote_types(R.dtype, t.dtype)
    T = torch.zeros(*batch, 4, 4, dtype=dtype, device=R.device)
    T[..., :3, :3] = R
    T[..., :3, 3] = t
    T[..., 3, 3] = 1.0
    return T


def split_transform(T: Tensor) -> tuple[Tensor, Tensor]:
    """Split ``T (..., 4, 4)`` into ``R (..., 3, 3)`` and ``t (..., 3)``."""
    return T[..., :3, :3], T[..., :3, 3]


def invert_transform(T: Tensor) -> Tensor:
    """Inverse of a rigid transform ``T (..., 4, 4)``: ``[R^T, -R^T t]`` (no general inverse)."""
    R, t = split_transform(T)
    Rt = R.transpose(-1, -2)
    return make_transform(Rt, -(Rt @ t.unsqueeze(-1)).squeeze(-1))


def compose(*Ts: Tensor) -> Tensor:
    """Matrix product ``T1 @ T2 @ ... @ Tn`` of ``(..., 4, 4)`` transforms (Tn is applied first).

    E.g. ``compose(T_cw, T_wb) = T_cb``.
    """
    if not Ts:
        raise ValueError("compose needs at least one transform")
    out = Ts[0]
    for T in Ts[1:]:
        out = out @ T
    return out


def apply_transform(T: Tensor, X: Tensor) -> Tensor:
    """Apply ``T (..., 4, 4)`` to points ``X (..., N, 3)``; returns ``(..., N, 3)``."""
    R, t = split_transform(T)
    return X @ R.transpose(-1, -2) + t.unsqueeze(-2)


def body_in_camera(R_wb: Tensor, t_wb: Tensor, R_cw: Tensor, t_cw: Tensor) -> tuple[Tensor, Tensor]:
    """Body pose in a camera from the body pose in the world and the world->camera extrinsics.

    ``x_c = R_cw (R_wb x_B + t_wb) + t_cw``, so ``R_cb = R_cw R_wb`` and
    ``t_cb = R_cw t_wb + t_cw``.

    Args:
        R_wb: ``(..., 3, 3)`` body root rotation in the world.
        t_wb: ``(..., 3)`` body (model-origin) translation in the world.
        R_cw: ``(..., 3, 3)`` world->camera rotation (extrinsics).
        t_cw: ``(..., 3)`` world->camera translation.

    Returns:
        ``R_cb (..., 3, 3)``, ``t_cb (..., 3)``.
    """
    R_cb = R_cw @ R_wb
    t_cb = (R_cw @ t_wb.unsqueeze(-1)).squeeze(-1) + t_cw
    return R_cb, t_cb


def relative_camera_pose(R1: Tensor, t1: Tensor, R2: Tensor, t2: Tensor) -> tuple[Tensor, Tensor]:
    """Pose of camera 2 in camera 1 from the two per-view body poses.

    Each view c sees the same body as ``x_c = R_c x_B + t_c``. Eliminating x_B:
    ``x_c1 = R_12 x_c2 + t_12`` with ``R_12 = R1 R2^T`` and ``t_12 = t1 - R1 R2^T t2``.
    ``t_12`` is camera 2's optical centre (UAV2's position) in camera 1's frame and the columns
    of ``R_12`` are camera 2's axes in camera 1.

    Args:
        R1, t1: ``(..., 3, 3)``, ``(..., 3)`` body root pose in camera 1.
        R2, t2: ``(..., 3, 3)``, ``(..., 3)`` body root pose in camera 2.

    Returns:
        ``R_12 (..., 3, 3)``, ``t_12 (..., 3)``.
    """
    R_12 = R1 @ R2.transpose(-1, -2)
    t_12 = t1 - (R_12 @ t2.unsqueeze(-1)).squeeze(-1)
    return R_12, t_12


def camera_center(R_cw: Tensor, t_cw: Tensor) -> Tensor:
    """Optical centre in the world ``-R_cw^T t_cw`` ``(..., 3)`` from extrinsics ``R_cw (..., 3, 3)``, ``t_cw (..., 3)``."""
    return -(R_cw.transpose(-1, -2) @ t_cw.unsqueeze(-1)).squeeze(-1)
