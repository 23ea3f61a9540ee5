"""Evaluation metrics on hand-computed cases."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from airpose_lib.eval import (
    acceleration,
    acceleration_error,
    jitter,
    joint_errors,
    mpe,
    mpjpe,
    pa_mpjpe,
    procrustes_align,
    relative_camera_errors,
    root_yaw_tilt,
    rotation_error,
    translation_error,
)
from airpose_lib.geometry import body_in_camera

DTYPES = [torch.float32, torch.float64]


def _rand_rot(n, seed, dtype=torch.float64):
    return torch.as_tensor(Rotation.random(n, random_state=seed).as_matrix(), dtype=dtype)


@pytest.mark.parametrize("dtype", DTYPES)
def test_mpe_known_offset(dtype):
    g = torch.Generator().manual_seed(0)
    tau = torch.randn(5, 2, 3, generator=g).to(dtype) + torch.tensor([0, 0, 10.0], dtype=dtype)
    off = torch.tensor([0.3, 0.0, 0.4], dtype=dtype)  # |off| = 0.5
    assert mpe(tau + off, tau).item() == pytest.approx(0.5, rel=1e-6)
    err = translation_error(tau + off, tau)
    assert err.shape == (5, 2) and err.dtype == dtype
    # per-view different errors average over images of both UAVs
    pred = tau.clone()
    pred[:, 1, 2] += 1.0
    assert mpe(pred, tau).item() == pytest.approx(0.5)


@pytest.mark.parametrize("dtype", DTYPES)
def test_mpjpe_aligns_pelvis_not_rotation(dtype):
    g = torch.Generator().manual_seed(1)
    gt = torch.randn(3, 22, 3, generator=g).to(dtype)
    # a pure translation: 0 after pelvis alignment, its norm without
    shifted = gt + torch.tensor([1.0, 2.0, 2.0], dtype=dtype)
    assert mpjpe(shifted, gt).abs().max().item() < 1e-6
    assert mpjpe(shifted, gt, root=None).numpy() == pytest.approx([3.0] * 3, rel=1e-6)
    # a single joint moved by 0.22 m -> MPJPE 0.01
    moved = gt.clone()
    moved[:, 5, 0] += 0.22
    assert mpjpe(moved, gt).numpy() == pytest.approx([0.01] * 3, rel=1e-5)
    e = joint_errors(moved, gt)
    assert e.shape == (3, 22) and e[:, 5].numpy() == pytest.approx([0.22] * 3, rel=1e-5)
    # moving the pelvis moves every other joint's aligned position by the same amount
    pel = gt.clone()
    pel[:, 0, 1] += 0.22
    assert mpjpe(pel, gt).numpy() == pytest.approx([0.21] * 3, rel=1e-5)


@pytest.mark.parametrize("dtype", DTYPES)
def test_pa_mpjpe_similarity_invariant(dtype):
    g = torch.Generator().manual_seed(2)
    gt = torch.randn(4, 22, 3, generator=g, dtype=torch.float64)
    R = _rand_rot(4, 3)
    pred = 1.3 * gt @ R.transpose(-1, -2) + torch.tensor([0.5, -1.0, 3.0], dtype=torch.float64)
    gt, pred = gt.to(dtype), pred.to(dtype)
    tol = 1e-4 if dtype == torch.float32 else 1e-10
    assert pa_mpjpe(pred, gt).abs().max().item() < tol
    assert (mpjpe(pred, gt) > 0.1).all()
    torch.testing.assert_close(procrustes_align(pred, gt), gt, atol=tol * 10, rtol=0)
    # without scale the 1.3 factor remains
    assert (pa_mpjpe(pred, gt, scale=False) > 0.01).all()


def test_procrustes_matches_scipy_align_vectors():
    """Reference: scipy's Rotation.align_vectors (proper rotations only) on centred points, then the
    least-squares scale."""
    g = np.random.default_rng(4)
    for trial in range(3):
        X, Y = g.normal(size=(22, 3)), g.normal(size=(22, 3))
        if trial == 2:
            Y = X * np.array([1, 1, -1]) + 0.01 * Y  # a near mirror image: the reflection is excluded
        Xc, Yc = X - X.mean(0), Y - Y.mean(0)
        rot, _ = Rotation.align_vectors(Yc, Xc)
        RX = rot.apply(Xc)
        s = np.sum(Yc * RX) / np.sum(Xc**2)
        ref = s * RX + Y.mean(0)
        got = procrustes_align(torch.as_tensor(X), torch.as_tensor(Y)).numpy()
        np.testing.assert_allclose(got, ref, atol=1e-9)


def test_rotation_error():
    R = _rand_rot(3, 5)
    Rz = torch.as_tensor(Rotation.from_euler("z", 30, degrees=True).as_matrix())
    assert rotation_error(R @ Rz, R).numpy() == pytest.approx([math.radians(30)] * 3)
    assert rotation_error(R, R).abs().max().item() < 1e-7


def _deg(x: torch.Tensor) -> np.ndarray:
    return np.degrees(x.numpy())


def _euler(seq, angles):
    return torch.as_tensor(Rotation.from_euler(seq, angles, degrees=True).as_matrix())


def test_root_yaw_tilt_on_hand_made_rotations():
    upright = torch.eye(3, dtype=torch.float64)  # up along the camera's y axis, facing away
    facing = _euler("x", 180)  # up along -y, facing the camera
    for gt in (upright, facing):
        yaw, tilt = root_yaw_tilt(gt @ _euler("y", 30), gt)  # a pure turn of 30 deg about the body's up axis
        assert _deg(yaw) == pytest.approx(30) and _deg(tilt) == pytest.approx(0, abs=1e-6)
    yaw, tilt = root_yaw_tilt(upright @ _euler("x", 20), upright)  # leaning 20 deg forward: no heading change
    assert _deg(yaw) == pytest.approx(0, abs=1e-6) and _deg(tilt) == pytest.approx(20)
    yaw, tilt = root_yaw_tilt(upright @ _euler("y", 180), upright)  # a front/back flip
    assert _deg(yaw) == pytest.approx(180) and _deg(tilt) == pytest.approx(0, abs=1e-6)
    yaw, _ = root_yaw_tilt(_euler("y", -170), _euler("y", 170))  # headings -170 and 170: 20 deg apart
    assert _deg(yaw) == pytest.approx(20)


def test_root_yaw_tilt_against_scipy():
    """Random ground truths turned by a random alpha about the body's up axis (+Y) and tilted by a
    random beta about its x axis: the tilt is |beta| (a turn about +Y keeps the up axis); the yaw is
    the wrapped difference of scipy's headings, the first angle of the intrinsic Y-X-Z Euler
    decomposition (R = Ry(a) Rx(b) Rz(c) puts the forward axis R e_z at azimuth a)."""
    rng = np.random.default_rng(21)
    n = 200
    gt = Rotation.random(n, random_state=22)
    alpha, beta = rng.uniform(-180, 180, n), rng.uniform(-80, 80, n)
    pred = gt * Rotation.from_euler("y", alpha[:, None], degrees=True) * Rotation.from_euler("x", beta[:, None],
                                                                                           degrees=True)
    P, G = (torch.as_tensor(r.as_matrix()) for r in (pred, gt))
    yaw, tilt = root_yaw_tilt(P, G)
    assert yaw.shape == tilt.shape == (n,)
    np.testing.assert_allclose(_deg(tilt), np.abs(beta), atol=1e-9)
    d = pred.as_euler("YXZ")[:, 0] - gt.as_euler("YXZ")[:, 0]
    np.testing.assert_allclose(_deg(yaw), np.degrees(np.abs(np.arctan2(np.sin(d), np.cos(d)))), atol=1e-9)
    geodesic = np.degrees((gt.inv() * pred).magnitude())
    assert (_deg(tilt) <= geodesic + 1e-9).all()
    # broadcasting: one ground truth against many predictions
    yaw1, tilt1 = root_yaw_tilt(P, G[0])
    assert yaw1.shape == tilt1.shape == (n,)


def test_jitter_and_acceleration():
    T = 6
    t = torch.arange(T, dtype=torch.float64)
    x = torch.zeros(T, 2, 3, dtype=torch.float64)
    x[:, 0, 0] = 0.5 * t  # constant velocity: no acceleration
    x[:, 1, 1] = 0.1 * t**2  # constant acceleration 0.2 m/frame^2
    a = acceleration(x)
    assert a.shape == (T - 2, 2, 3)
    assert jitter(x).item() == pytest.approx(0.1)  # mean over the two joints
    assert jitter(x, fps=10).item() == pytest.approx(10.0)
    assert acceleration_error(x, x).item() == 0.0
    noisy = x.clone()
    noisy[3, 0, 2] += 0.01  # one spike: accelerations 0.01, -0.02, 0.01 in frames 2-4
    assert acceleration_error(noisy, x).item() == pytest.approx(0.04 / (4 * 2))
    assert jitter(torch.stack([x, noisy])).shape == (2,)
    with pytest.raises(ValueError):
        acceleration(x[:2])


def test_relative_camera_errors_from_body_poses():
    g = torch.Generator().manual_seed(6)
    N = 4
    R_wb, t_wb = _rand_rot(N, 7), torch.randn(N, 3, generator=g, dtype=torch.float64)
    R_cw, t_cw = _rand_rot(2 * N, 8).reshape(N, 2, 3, 3), torch.randn(N, 2, 3, generator=g, dtype=torch.float64)
    phi, tau = body_in_camera(R_wb[:, None], t_wb[:, None], R_cw, t_cw)
    t_err, r_err = relative_camera_errors(phi, tau, phi, tau)
    assert t_err.abs().max() < 1e-12 and r_err.abs().max() < 1e-6
    # ground truth equals the relative pose from the extrinsics: R_12 = R_1w R_2w^T
    from airpose_lib.geometry import relative_camera_pose

    R12, t12 = relative_camera_pose(phi[:, 0], tau[:, 0], phi[:, 1], tau[:, 1])
    torch.testing.assert_close(R12, R_cw[:, 0] @ R_cw[:, 1].transpose(-1, -2))
    c2 = -(R_cw[:, 1].transpose(-1, -2) @ t_cw[:, 1, :, None])[..., 0]  # camera 2 centre in world
    torch.testing.assert_close(t12, (R_cw[:, 0] @ c2[..., None])[..., 0] + t_cw[:, 0])
    # a translation error d in view 1's tau moves camera 2 by exactly d in camera 1
    tau_p = tau.clone()
    tau_p[:, 0] += torch.tensor([0.0, 0.3, 0.4], dtype=torch.float64)
    t_err, r_err = relative_camera_errors(phi, tau_p, phi, tau)
    assert t_err.numpy() == pytest.approx([0.5] * N) and r_err.abs().max() < 1e-6
    # a root rotation error of 10 degrees in view 2 gives a 10 degree relative rotation error
    phi_p = phi.clone()
    phi_p[:, 1] = phi[:, 1] @ torch.as_tensor(Rotation.from_euler("x", 10, degrees=True).as_matrix())
    _, r_err = relative_camera_errors(phi_p, tau, phi, tau)
    assert r_err.numpy() == pytest.approx([math.radians(10)] * N)
