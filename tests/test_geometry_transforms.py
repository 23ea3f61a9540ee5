"""Rigid transforms: identities, body-in-camera, and the relative UAV pose from two body poses."""

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from airpose_lib.geometry import (
    apply_transform,
    body_in_camera,
    camera_center,
    compose,
    invert_transform,
    make_transform,
    relative_camera_pose,
    split_transform,
    transform_points,
)

DTYPES = [torch.float32, torch.float64]


def _look_at(C, target=(0.0, 0.0, 0.0)):
    """World->camera extrinsics (OpenCV camera, world Y up) for a camera at C looking at target."""
    C = np.asarray(C, float)
    f = np.asarray(target, float) - C
    f /= np.linalg.norm(f)
    r = np.cross(f, [0.0, 1.0, 0.0])
    r /= np.linalg.norm(r)
    d = np.cross(f, r)  # OpenCV: y = z x x points down
    R_cw = np.stack([r, d, f])  # rows: camera axes in world coordinates
    return torch.from_numpy(R_cw), torch.from_numpy(-R_cw @ C)


def _random_transform(n, seed, dtype):
    R = torch.as_tensor(Rotation.random(n, random_state=seed).as_matrix(), dtype=dtype)
    t = torch.as_tensor(np.random.default_rng(seed).normal(size=(n, 3)) * 5, dtype=dtype)
    return R, t


def test_look_at_helper_is_a_proper_opencv_camera():
    R_cw, t_cw = _look_at([0.0, 0.0, -10.0])
    # world origin straight ahead, world up (+Y) is image up (-y), right-handed
    torch.testing.assert_close(R_cw @ torch.zeros(3, dtype=torch.float64) + t_cw, torch.tensor([0.0, 0.0, 10.0], dtype=torch.float64))
    torch.testing.assert_close(R_cw @ torch.tensor([0.0, 1.0, 0.0], dtype=torch.float64), torch.tensor([0.0, -1.0, 0.0], dtype=torch.float64))
    assert torch.linalg.det(R_cw) == pytest.approx(1.0)
    torch.testing.assert_close(camera_center(R_cw, t_cw), torch.tensor([0.0, 0.0, -10.0], dtype=torch.float64))


def test_relative_camera_pose_hand_built_scene():
    # UAV1 10 m in front of the person (at -z), UAV2 10 m to the side (+x), 3 m higher; both look at the origin.
    R1w, t1w = _look_at([0.0, 0.0, -10.0])
    R2w, t2w = _look_at([10.0, 3.0, 0.0])
    # person at the origin area, turned and offset; root pose in the world (model-origin convention)
    R_wb = torch.as_tensor(Rotation.from_euler("yxz", [40, -5, 3], degrees=True).as_matrix())
    t_wb = torch.tensor([0.7, 0.9, -1.2], dtype=torch.float64)
    R1, t1 = body_in_camera(R_wb, t_wb, R1w, t1w)
    R2, t2 = body_in_camera(R_wb, t_wb, R2w, t2w)
    R12, t12 = relative_camera_pose(R1, t1, R2, t2)
    # UAV2's position in UAV1's frame, by hand: C2 - C1 = (10, 3, 10) in the world; UAV1's right axis is
    # world -x, its down axis world -y, its forward axis world +z -> (-10, -3, 10).
    torch.testing.assert_close(t12, torch.tensor([-10.0, -3.0, 10.0], dtype=torch.float64))
    # and from the extrinsics: R_12 = R_1w R_2w^T, t_12 = R_1w C2 + t_1w
    torch.testing.assert_close(R12, R1w @ R2w.T)
    torch.testing.assert_close(t12, R1w @ camera_center(R2w, t2w) + t1w)
    # the relative pose does not depend on where the person stands
    R1b, t1b = body_in_camera(torch.eye(3, dtype=torch.float64), torch.zeros(3, dtype=torch.float64), R1w, t1w)
    R2b, t2b = body_in_camera(torch.eye(3, dtype=torch.float64), torch.zeros(3, dtype=torch.float64), R2w, t2w)
    R12b, t12b = relative_camera_pose(R1b, t1b, R2b, t2b)
    torch.testing.assert_close(R12b, R12)
    torch.testing.assert_close(t12b, t12)


@pytest.mark.parametrize("dtype", DTYPES)
def test_relative_camera_pose_maps_body_points_between_views(dtype):
    R_wb, t_wb = _random_transform(16, seed=1, dtype=torch.float64)
    R1w, t1w = _random_transform(16, seed=2, dtype=torch.float64)
    R2w, t2w = _random_transform(16, seed=3, dtype=torch.float64)
    X_B = torch.as_tensor(np.random.default_rng(4).normal(size=(16, 25, 3)))
    R1, t1 = body_in_camera(R_wb, t_wb, R1w, t1w)
    R2, t2 = body_in_camera(R_wb, t_wb, R2w, t2w)
    # body_in_camera against explicit body -> world -> camera
    X_c1 = transform_points(transform_points(X_B, R_wb, t_wb), R1w, t1w)
    X_c2 = transform_points(transform_points(X_B, R_wb, t_wb), R2w, t2w)
    torch.testing.assert_close(transform_points(X_B, R1, t1), X_c1)
    R12, t12 = relative_camera_pose(R1.to(dtype), t1.to(dtype), R2.to(dtype), t2.to(dtype))
    assert R12.shape == (16, 3, 3) and t12.shape == (16, 3) and R12.dtype == dtype
    tol = 1e-4 if dtype == torch.float32 else 1e-10
    torch.testing.assert_close(transform_points(X_c2.to(dtype), R12, t12), X_c1.to(dtype), atol=tol, rtol=0)
    # UAV2's position in UAV1's frame = its world centre seen by camera 1
    C2_in_1 = transform_points(camera_center(R2w, t2w)[:, None], R1w, t1w)[:, 0]
    torch.testing.assert_close(t12, C2_in_1.to(dtype), atol=tol, rtol=0)


@pytest.mark.parametrize("dtype", DTYPES)
def test_invert_compose_apply_identities(dtype):
    R, t = _random_transform(10, seed=5, dtype=dtype)
    T = make_transform(R, t)
    assert T.shape == (10, 4, 4)
    torch.testing.assert_close(T[:, 3], torch.tensor([0, 0, 0, 1], dtype=dtype).expand(10, 4))
    Rs, ts = split_transform(T)
    assert torch.equal(Rs, R) and torch.equal(ts, t)
    eye = torch.eye(4, dtype=dtype).expand(10, 4, 4)
    tol = 1e-5 if dtype == torch.float32 else 1e-12
    Ti = invert_transform(T)
    torch.testing.assert_close(compose(T, Ti), eye, atol=tol, rtol=0)
    torch.testing.assert_close(compose(Ti, T), eye, atol=tol, rtol=0)
    torch.testing.assert_close(Ti, torch.linalg.inv(T), atol=tol, rtol=0)
    R2, t2 = _random_transform(10, seed=6, dtype=dtype)
    T2 = make_transform(R2, t2)
    X = torch.as_tensor(np.random.default_rng(7).normal(size=(10, 5, 3)), dtype=dtype)
    # compose(A, B) applies B first
    torch.testing.assert_close(apply_transform(compose(T, T2), X), apply_transform(T, apply_transform(T2, X)), atol=10 * tol, rtol=0)
    torch.testing.assert_close(apply_transform(T, X), transform_points(X, R, t))
    torch.testing.assert_close(invert_transform(compose(T, T2)), compose(invert_transform(T2), Ti), atol=10 * tol, rtol=0)
    torch.testing.assert_close(compose(T, T2, Ti), T @ T2 @ Ti)
    # body_in_camera agrees with composing 4x4 transforms
    Rc, tc = body_in_camera(R, t, R2, t2)
    torch.testing.assert_close(make_transform(Rc, tc), compose(T2, T), atol=tol, rtol=0)
    with pytest.raises(ValueError):
        compose()


def test_make_transform_broadcasts():
    R = torch.eye(3).expand(2, 1, 3, 3)
    t = torch.arange(9.0).reshape(3, 3)
    T = make_transform(R, t)
    assert T.shape == (2, 3, 4, 4)
    assert torch.equal(T[1, 2, :3, 3], t[2])
