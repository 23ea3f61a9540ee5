"""Pinhole camera helpers against OpenCV and hand-computed values."""

import cv2
import numpy as np
import pytest
import torch

from airpose_lib.geometry import intrinsics_matrix, project_points, split_intrinsics, transform_points
from airpose_lib.geometry.rotations import axis_angle_to_matrix

DTYPES = [torch.float32, torch.float64]
# Real-data intrinsics of the paper's camera 0 (non-square pixels, off-centre principal point).
CAM0 = (1537.83, 1517.66, 1018.55, 577.52)


def _points_in_front(n, seed, dtype):
    g = torch.Generator().manual_seed(seed)
    X = torch.randn(n, 3, generator=g, dtype=torch.float64) * torch.tensor([2.0, 2.0, 1.0], dtype=torch.float64)
    X[:, 2] += 10.0
    return X.to(dtype)


def test_intrinsics_matrix_layout_and_broadcast():
    K = intrinsics_matrix(*CAM0)
    expected = torch.tensor([[CAM0[0], 0, CAM0[2]], [0, CAM0[1], CAM0[3]], [0, 0, 1]], dtype=K.dtype)
    torch.testing.assert_close(K, expected)
    fx = torch.tensor([1000.0, 1475.0], dtype=torch.float64)
    Kb = intrinsics_matrix(fx, fx, 960.0, 540.0)
    assert Kb.shape == (2, 3, 3) and Kb.dtype == torch.float64
    assert torch.equal(Kb[:, 0, 0], fx) and torch.equal(Kb[:, 2], torch.tensor([[0.0, 0, 1]] * 2, dtype=torch.float64))
    assert split_intrinsics(Kb)[2].tolist() == [960.0, 960.0]
    assert intrinsics_matrix(1, 2, 3, 4, dtype=torch.float32).dtype == torch.float32


@pytest.mark.parametrize("dtype", DTYPES)
def test_project_points_matches_opencv(dtype):
    X = _points_in_front(100, seed=0, dtype=dtype)
    K = intrinsics_matrix(*CAM0, dtype=dtype)
    ref, _ = cv2.projectPoints(X.double().numpy(), np.zeros(3), np.zeros(3), K.double().numpy(), None)
    got = project_points(X, K)
    assert got.shape == (100, 2) and got.dtype == dtype
    tol = 1e-3 if dtype == torch.float32 else 1e-8
    torch.testing.assert_close(got, torch.as_tensor(ref[:, 0, :], dtype=dtype), atol=tol, rtol=0)


def test_project_points_hand_value_and_batching():
    K = intrinsics_matrix(1475.0, 1475.0, 960.0, 540.0, dtype=torch.float64)
    X = torch.tensor([[1.0, -0.5, 10.0]], dtype=torch.float64)
    torch.testing.assert_close(project_points(X, K), torch.tensor([[960 + 147.5, 540 - 73.75]], dtype=torch.float64))
    # per-batch K broadcasts over points
    Xb = _points_in_front(2 * 7, seed=1, dtype=torch.float64).reshape(2, 7, 3)
    Kb = torch.stack([K, intrinsics_matrix(*CAM0, dtype=torch.float64)])
    got = project_points(Xb, Kb)
    for b in range(2):
        torch.testing.assert_close(got[b], project_points(Xb[b], Kb[b]))


def test_project_points_min_depth():
    K = intrinsics_matrix(100.0, 100.0, 0.0, 0.0, dtype=torch.float64)
    X = torch.tensor([[1.0, 1.0, -2.0], [1.0, 1.0, 0.0]], dtype=torch.float64)
    got = project_points(X, K, min_depth=0.5)
    torch.testing.assert_close(got, torch.full((2, 2), 200.0, dtype=torch.float64))
    assert not torch.isfinite(project_points(X, K)[1]).all()
    # without clamping, plain pinhole maths also behind the camera (the image is mirrored)
    torch.testing.assert_close(project_points(X[:1], K), torch.full((1, 2), -50.0, dtype=torch.float64))


@pytest.mark.parametrize("dtype", DTYPES)
def test_transform_points_matches_opencv_extrinsics(dtype):
    X = _points_in_front(50, seed=2, dtype=torch.float64)
    rvec = np.array([0.1, -0.4, 0.25])
    tvec = np.array([0.3, -0.2, 1.5])
    R = axis_angle_to_matrix(torch.as_tensor(rvec))
    K = intrinsics_matrix(*CAM0, dtype=torch.float64)
    Xc = transform_points(X.to(dtype), R.to(dtype), torch.as_tensor(tvec, dtype=dtype))
    torch.testing.assert_close(Xc, (X @ R.T + torch.as_tensor(tvec)).to(dtype))
    ref, _ = cv2.projectPoints(X.numpy(), rvec, tvec, K.numpy(), None)
    tol = 1e-3 if dtype == torch.float32 else 1e-8
    torch.testing.assert_close(project_points(Xc, K.to(dtype)), torch.as_tensor(ref[:, 0], dtype=dtype), atol=tol, rtol=0)
