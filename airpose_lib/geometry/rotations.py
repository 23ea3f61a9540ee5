"""Rotation representations used by the AirPose network and its losses.

The network regresses every rotation (root orientation phi and the 21 body joints theta) in the
continuous 6D representation of Zhou et al. (CVPR 2019), with the convention of SPIN and the
official AirPose code: the 6 numbers reshaped to ``(3, 2)`` are the first two **columns** of the
rotation matrix,

    rot6d = R[..., :, :2].reshape(..., 6) = [R00, R01, R10, R11, R20, R21].

Decoding orthonormalises the two columns by Gram-Schmidt and takes their cross product as the third
column. (PyTorch3D uses the first two *rows* instead; the two conventions are not interchangeable.)

Axis-angle (rotation vector) conversions are delegated to roma. All functions accept arbitrary
leading batch dimensions and keep dtype and device.
"""

from __future__ import annotations

import roma
import torch
from torch import Tensor

__all__ = [
    "rot6d_to_matrix",
    "matrix_to_rot6d",
    "axis_angle_to_matrix",
    "matrix_to_axis_angle",
    "axis_angle_to_rot6d",
    "rot6d_to_axis_angle",
    "geodesic_angle",
    "heading_of",
]

# Floor on column norms in Gram-Schmidt: keeps a degenerate network output (zero or colinear
# columns) from producing NaNs; any such output is far from a rotation anyway.
_GS_EPS = 1e-12


def rot6d_to_matrix(x: Tensor) -> Tensor:
    """Decode the 6D representation into rotation matrices (Gram-Schmidt, column convention).

    Args:
        x: ``(..., 6)``; reshaped to ``(..., 3, 2)``, its columns a1, a2 are the (unnormalised)
            first two columns of R.

    Returns:
        ``(..., 3, 3)`` rotation matrices with columns ``b1 = a1/|a1|``,
        ``b2 = normalise(a2 - (b1.a2) b1)``, ``b3 = b1 x b2``.
    """
    if x.shape[-1] != 6:
        raise ValueError(f"rot6d_to_matrix expects (..., 6), got shape {tuple(x.shape)}")
    m = x.reshape(*x.shape[:-1], 3, 2)
    a1, a2 = m[..., 0], m[..., 1]
    b1 = a1 / a1.norm(dim=-1, keepdim=True).clamp_min(_GS_EPS)
    a2 = a2 - (b1 * a2).sum(dim=-1, keepdim=True) * b1
    b2 = a2 / a2.norm(dim=-1, keepdim=True).clamp_min(_GS_EPS)
    b3 = torch.linalg.cross(b1, b2, dim=-1)
    return torch.stack((b1, b2, b3), dim=-1)


def matrix_to_rot6d(R: Tensor) -> Tensor:
    """Encode rotation matrices as 6D: the first two columns, row-major.

    Args:
        R: ``(..., 3, 3)``.

    Returns:
        ``(..., 6)`` equal to ``R[..., :, :2].reshape(..., 6)``.
    """
    if R.shape[-2:] != (3, 3):
        raise ValueError(f"matrix_to_rot6d expects (..., 3, 3), got shape {tuple(R.shape)}")
    return R[..., :, :2].reshape(*R.shape[:-2], 6)


def axis_angle_to_matrix(aa: Tensor) -> Tensor:
    """Rotation vectors (axis * angle, radians) ``(..., 3)`` -> rotation matrices ``(..., 3, 3)``."""
    return roma.rotvec_to_rotmat(aa)


def matrix_to_axis_angle(R: Tensor) -> Tensor:
    """Rotation matrices ``(..., 3, 3)`` -> rotation vectors ``(..., 3)``, angle in ``[0, pi]``."""
    return roma.rotmat_to_rotvec(R)


def axis_angle_to_rot6d(aa: Tensor) -> Tensor:
    """Rotation vectors ``(..., 3)`` -> 6D ``(..., 6)`` (column convention)."""
    return matrix_to_rot6d(axis_angle_to_matrix(aa))


def rot6d_to_axis_angle(x: Tensor) -> Tensor:
    """6D ``(..., 6)`` -> rotation vectors ``(..., 3)`` (via Gram-Schmidt decoding)."""
    return matrix_to_axis_angle(rot6d_to_matrix(x))


def geodesic_angle(R1: Tensor, R2: Tensor) -> Tensor:
    """Angle of the relative rotation ``R1^T R2`` in radians, in ``[0, pi]``.

    Uses ``atan2(|sin|, cos)`` from the skew and trace parts of ``R1^T R2``, which stays accurate
    both near 0 (where ``acos`` of the trace loses precision) and near pi.

    Args:
        R1: ``(..., 3, 3)``.
        R2: ``(..., 3, 3)``, broadcastable with R1.

    Returns:
        ``(...)`` angles.
    """
    R = R1.transpose(-1, -2) @ R2
    cos = 0.5 * (R[..., 0, 0] + R[..., 1, 1] + R[..., 2, 2] - 1.0)
    # The skew-symmetric part of R is sin(angle) [axis]_x.
    skew = torch.stack(
        (R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]),
        dim=-1,
    )
    sin = 0.5 * torch.linalg.vector_norm(skew, dim=-1)
    return torch.atan2(sin, cos)


def heading_of(phi: Tensor) -> Tensor:
    """Heading of the body in the camera, radians in ``(-pi, pi]``.

    The targets of the pretrained backbone's heading head (``losses.pretrain.heading_bin``) and the
    yaw of the root-orientation error (``eval.metrics.root_yaw_tilt``): one definition for both.

    Args:
        phi: ``(..., 3, 3)`` root rotation (model -> camera); the model faces +Z.

    Returns:
        ``(...)`` azimuth of the body's forward axis ``phi[..., :, 2]`` in the camera's x-z plane
        (0: facing away from the camera, pi: facing it).
    """
    forward = phi[..., :, 2]
    return torch.atan2(forward[..., 0], forward[..., 2])
