"""Pinhole camera helpers (OpenCV frame: x right, y down, z forward; pixels, metres).

Pixel coordinates are continuous with integer values at pixel centres, as in OpenCV
(``cv2.projectPoints``, ``cv2.warpAffine``).
"""

from __future__ import annotations

import torch
from torch import Tensor

__all__ = ["intrinsics_matrix", "split_intrinsics", "project_points", "transform_points"]


def intrinsics_matrix(
    fx: Tensor | float,
    fy: Tensor | float,
    cx: Tensor | float,
    cy: Tensor | float,
    *,
    dtype: torch.dtype | None = None,
    device: torch.device | str | None = None,
) -> Tensor:
    """Build the intrinsics matrix ``K = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]``.

    Args:
        fx, fy, cx, cy: floats or tensors of broadcastable shape ``(...)`` (pixels).
        dtype, device: of the result; by default taken from the first tensor argument, otherwise
            torch's default dtype on the CPU.

    Returns:
        ``(..., 3, 3)``.
    """
    ref = next((v for v in (fx, fy, cx, cy) if isinstance(v, Tensor)), None)
    if dtype is None:
        dtype = ref.dtype if ref is not None and ref.is_floating_point() else torch.get_default_dtype()
    if device is None:
        device = ref.device if ref is not None else None
    fx, fy, cx, cy = torch.broadcast_tensors(
        *(torch.as_tensor(v, dtype=dtype, device=device) for v in (fx, fy, cx, cy))
    )
    zero, one = torch.zeros_like(fx), torch.ones_like(fx)
    rows = (
        torch.stack((fx, zero, cx), dim=-1),
        torch.stack((zero, fy, cy), dim=-1),
        torch.stack((zero, zero, one), dim=-1),
    )
    return torch.stack(rows, dim=-2)


def split_intrinsics(K: Tensor) -> tuple[Tensor, Tensor, Tensor, Tensor]:
    """Return ``(fx, fy, cx, cy)``, each ``(...)``, from ``K (..., 3, 3)`` (skew is ignored)."""
    if K.shape[-2:] != (3, 3):
        raise ValueError(f"intrinsics must have shape (..., 3, 3), got {tuple(K.shape)}")
    return K[..., 0, 0], K[..., 1, 1], K[..., 0, 2], K[..., 1, 2]


def project_points(X: Tensor, K: Tensor, *, min_depth: float | None = None) -> Tensor:
    """Perspective projection of camera-frame points to pixels.

    Args:
        X: ``(..., N, 3)`` points in the camera frame (metres).
        K: ``(..., 3, 3)`` intrinsics, broadcastable with the batch dims of X (skew is honoured).
        min_depth: if given, depths are clamped to at least this value before dividing, so a
            wild prediction behind the camera gives large but finite pixels (useful in losses).
            By default no clamping: points at z = 0 give inf/NaN as in plain pinhole geometry.

    Returns:
        ``(..., N, 2)`` pixel coordinates ``(u, v)``.
    """
    p = X @ K.transpose(-1, -2)  # (..., N, 3) homogeneous pixels, third entry = z
    z = p[..., 2:]
    if min_depth is not None:
        z = z.clamp_min(min_depth)
    return p[..., :2] / z


def transform_points(X: Tensor, R: Tensor, t: Tensor) -> Tensor:
    """Apply the rigid transform ``x -> R x + t`` to a set of points.

    Args:
        X: ``(..., N, 3)``.
        R: ``(..., 3, 3)``.
        t: ``(..., 3)``.

    Returns:
        ``(..., N, 3)``.
    """
    return X @ R.transpose(-1, -2) + t.unsqueeze(-2)
