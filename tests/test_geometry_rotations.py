"""Rotations: 6D (column convention) <-> matrix <-> axis-angle, geodesic angle.

References: roma, scipy.spatial.transform.Rotation and a hand-written numpy Gram-Schmidt.
"""

import math

import numpy as np
import pytest
import roma
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from airpose_lib.geometry import (
    axis_angle_to_matrix,
    axis_angle_to_rot6d,
    geodesic_angle,
    matrix_to_axis_angle,
    matrix_to_rot6d,
    rot6d_to_axis_angle,
    rot6d_to_matrix,
)

DTYPES = [torch.float32, torch.float64]
TOL = {torch.float32: 1e-5, torch.float64: 1e-12}


def _random_rotmats(n, seed, dtype):
    return torch.as_tensor(Rotation.random(n, random_state=seed).as_matrix(), dtype=dtype)


def _numpy_gram_schmidt(x6):
    """Independent reference: columns a1, a2 of the (3, 2) reshape, classic Gram-Schmidt."""
    out = []
    for v in x6.reshape(-1, 6):
        m = v.reshape(3, 2)
        a1, a2 = m[:, 0], m[:, 1]
        b1 = a1 / np.linalg.norm(a1)
        u2 = a2 - np.dot(b1, a2) * b1
        b2 = u2 / np.linalg.norm(u2)
        b3 = np.cross(b1, b2)
        out.append(np.stack([b1, b2, b3], axis=1))
    return np.stack(out).reshape(*x6.shape[:-1], 3, 3)


def test_column_convention_on_known_rotation():
    # 90 degrees about z: x -> y, y -> -x.
    Rz = torch.tensor([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]], dtype=torch.float64)
    r6 = matrix_to_rot6d(Rz)
    # first two COLUMNS (1,0,0)->(0,1,0) and (0,1,0)->(-1,0,0), laid out row-major in (3, 2)
    assert torch.equal(r6, torch.tensor([0.0, -1.0, 1.0, 0.0, 0.0, 0.0], dtype=torch.float64))
    assert torch.equal(r6.reshape(3, 2), Rz[:, :2])
    torch.testing.assert_close(rot6d_to_matrix(r6), Rz)
    aa = torch.tensor([0.0, 0.0, math.pi / 2], dtype=torch.float64)
    torch.testing.assert_close(axis_angle_to_matrix(aa), Rz, atol=1e-12, rtol=0)
    torch.testing.assert_close(axis_angle_to_rot6d(aa), r6, atol=1e-12, rtol=0)
    # rows would be [0, -1, 0, 1, 0, 0] (PyTorch3D layout): make sure we are not using it
    assert not torch.allclose(r6, Rz[:2, :].reshape(6))


def test_180_about_x_mean_root():
    # The mean root rotation of the paper's initialisation: 180 degrees about x.
    Rx = torch.diag(torch.tensor([1.0, -1.0, -1.0]))
    torch.testing.assert_close(matrix_to_rot6d(Rx), torch.tensor([1.0, 0.0, 0.0, -1.0, 0.0, 0.0]))
    torch.testing.assert_close(rot6d_to_matrix(matrix_to_rot6d(Rx)), Rx)


@pytest.mark.parametrize("dtype", DTYPES)
def test_matrix_rot6d_round_trip(dtype):
    R = _random_rotmats(200, seed=0, dtype=dtype).reshape(10, 20, 3, 3)
    r6 = matrix_to_rot6d(R)
    assert r6.shape == (10, 20, 6) and r6.dtype == dtype
    torch.testing.assert_close(rot6d_to_matrix(r6), R, atol=TOL[dtype], rtol=0)


@pytest.mark.parametrize("dtype", DTYPES)
def test_gram_schmidt_against_roma_and_numpy(dtype):
    g = torch.Generator().manual_seed(1)
    x = torch.randn(4, 50, 6, generator=g, dtype=torch.float64)
    ours = rot6d_to_matrix(x.to(dtype))
    ref_roma = roma.special_gramschmidt(x.reshape(4, 50, 3, 2)).to(dtype)
    ref_np = torch.from_numpy(_numpy_gram_schmidt(x.numpy())).to(dtype)
    tol = 1e-5 if dtype == torch.float32 else 1e-12
    torch.testing.assert_close(ours, ref_roma, atol=tol, rtol=0)
    torch.testing.assert_close(ours, ref_np, atol=tol, rtol=0)
    # a proper rotation
    eye = torch.eye(3, dtype=dtype).expand_as(ours)
    torch.testing.assert_close(ours.transpose(-1, -2) @ ours, eye, atol=10 * tol, rtol=0)
    torch.testing.assert_close(torch.linalg.det(ours), torch.ones(4, 50, dtype=dtype), atol=10 * tol, rtol=0)
    # first column is the normalised a1 (Gram-Schmidt starts from column 1, not row 1)
    a1 = x.reshape(4, 50, 3, 2)[..., 0].to(dtype)
    torch.testing.assert_close(ours[..., 0], a1 / a1.norm(dim=-1, keepdim=True), atol=tol, rtol=0)


def test_degenerate_6d_gives_finite_output():
    x = torch.zeros(2, 6, requires_grad=True)
    R = rot6d_to_matrix(x)
    assert torch.isfinite(R).all()
    R.sum().backward()
    assert torch.isfinite(x.grad).all()


@pytest.mark.parametrize("dtype", DTYPES)
def test_axis_angle_against_scipy(dtype):
    rots = Rotation.random(100, random_state=2)
    aa = torch.as_tensor(rots.as_rotvec(), dtype=dtype)
    R_ref = torch.as_tensor(rots.as_matrix(), dtype=dtype)
    R = axis_angle_to_matrix(aa)
    torch.testing.assert_close(R, R_ref, atol=TOL[dtype] * 10, rtol=0)
    torch.testing.assert_close(matrix_to_axis_angle(R_ref), aa, atol=TOL[dtype] * 100, rtol=0)
    # and the roma functions named in the brief agree with scipy
    torch.testing.assert_close(roma.rotvec_to_rotmat(aa), R_ref, atol=TOL[dtype] * 10, rtol=0)


@pytest.mark.parametrize("dtype", DTYPES)
def test_axis_angle_rot6d_round_trip_batched(dtype):
    aa = torch.as_tensor(Rotation.random(60, random_state=3).as_rotvec(), dtype=dtype).reshape(3, 20, 3)
    r6 = axis_angle_to_rot6d(aa)
    assert r6.shape == (3, 20, 6)
    torch.testing.assert_close(rot6d_to_axis_angle(r6), aa, atol=TOL[dtype] * 100, rtol=0)
    # 6D equals the first two columns of the scipy matrix
    R_ref = torch.as_tensor(Rotation.from_rotvec(aa.reshape(-1, 3).double().numpy()).as_matrix(), dtype=dtype)
    torch.testing.assert_close(r6.reshape(-1, 6), R_ref[:, :, :2].reshape(-1, 6), atol=TOL[dtype] * 10, rtol=0)


@pytest.mark.parametrize("dtype", DTYPES)
def test_geodesic_angle_known_values(dtype):
    axis = torch.tensor([1.0, 2.0, -2.0], dtype=torch.float64) / 3.0
    angles = torch.tensor([0.0, 1e-4, 0.3, 1.5, 3.0, math.pi - 1e-4], dtype=torch.float64)
    R0 = _random_rotmats(1, seed=4, dtype=torch.float64)[0]
    R1 = R0.expand(len(angles), 3, 3)
    R2 = R0 @ axis_angle_to_matrix(angles[:, None] * axis)
    got = geodesic_angle(R1.to(dtype), R2.to(dtype))
    # float32: the rotation entries themselves carry ~1e-7 error, hence the looser bound
    tol = 1e-6 if dtype == torch.float32 else 1e-10
    torch.testing.assert_close(got, angles.to(dtype), atol=tol, rtol=0)
    # symmetric
    torch.testing.assert_close(geodesic_angle(R2.to(dtype), R1.to(dtype)), got, atol=tol, rtol=0)


def test_geodesic_angle_against_scipy():
    R1 = Rotation.random(100, random_state=5)
    R2 = Rotation.random(100, random_state=6)
    ref = torch.as_tensor((R1.inv() * R2).magnitude())
    got = geodesic_angle(torch.as_tensor(R1.as_matrix()), torch.as_tensor(R2.as_matrix()))
    torch.testing.assert_close(got, ref, atol=1e-10, rtol=0)


_coord = st.floats(min_value=-1.0, max_value=1.0, allow_nan=False)


@settings(max_examples=60, deadline=None, derandomize=True)
@given(st.tuples(_coord, _coord, _coord), st.floats(min_value=1e-3, max_value=math.pi - 1e-3))
def test_hypothesis_axis_angle_round_trip(direction, angle):
    d = torch.tensor(direction, dtype=torch.float64)
    if d.norm() < 1e-3:
        d = torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64)
    aa = angle * d / d.norm()
    torch.testing.assert_close(rot6d_to_axis_angle(axis_angle_to_rot6d(aa)), aa, atol=1e-9, rtol=0)


@settings(max_examples=60, deadline=None, derandomize=True)
@given(
    st.lists(st.floats(min_value=-10, max_value=10, allow_nan=False), min_size=6, max_size=6),
)
def test_hypothesis_rot6d_projection_is_idempotent(values):
    x = torch.tensor(values, dtype=torch.float64)
    m = x.reshape(3, 2)
    a1, a2 = m[:, 0], m[:, 1]
    # skip inputs too close to degenerate for Gram-Schmidt to be well conditioned
    if a1.norm() < 1e-2 or torch.linalg.cross(a1, a2).norm() < 1e-2 * a1.norm() * max(a2.norm(), 1e-2):
        return
    R = rot6d_to_matrix(x)
    torch.testing.assert_close(rot6d_to_matrix(matrix_to_rot6d(R)), R, atol=1e-10, rtol=0)
    torch.testing.assert_close(R.T @ R, torch.eye(3, dtype=torch.float64), atol=1e-10, rtol=0)
