"""Crop vector P, crop intrinsics, pixel maps, paper eq. (1)-(2) and the weak-perspective camera.

References: hand-computed values, cv2.projectPoints / cv2.warpAffine, and the paper's equations
written out literally in the tests.
"""

import math

import cv2
import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from airpose_lib.geometry import (
    crop_affine_matrix,
    crop_intrinsics,
    crop_to_full_pixels,
    crop_to_full_translation,
    crop_vector,
    full_to_crop_pixels,
    full_to_crop_translation,
    intrinsics_matrix,
    project_points,
    translation_to_weak_perspective,
    weak_perspective_to_translation,
)

DTYPES = [torch.float32, torch.float64]
SYN = (1475.0, 1475.0, 960.0, 540.0)  # synthetic data: 1920x1080, f = 1475 px
CAM0 = (1537.83, 1517.66, 1018.55, 577.52)  # real data, camera 0
CAM1 = (1361.11, 1378.80, 978.02, 667.23)  # real data, camera 1


def _cv2_project(X, K):
    uv, _ = cv2.projectPoints(X.double().numpy().reshape(-1, 3), np.zeros(3), np.zeros(3), K.double().numpy(), None)
    return torch.from_numpy(uv[:, 0, :])


def _random_scene(n, seed, dtype, K=CAM0):
    """Random person translations in front of the camera and boxes around their projections."""
    g = torch.Generator().manual_seed(seed)
    tau = torch.stack(
        [
            torch.empty(n, dtype=torch.float64).uniform_(-4, 4, generator=g),
            torch.empty(n, dtype=torch.float64).uniform_(-3, 3, generator=g),
            torch.empty(n, dtype=torch.float64).uniform_(5, 20, generator=g),
        ],
        dim=-1,
    )
    Kt = intrinsics_matrix(*K, dtype=torch.float64)
    centre = project_points(tau[:, None], Kt)[:, 0] + torch.randn(n, 2, generator=g, dtype=torch.float64) * 30
    wh = torch.empty(n, 2, dtype=torch.float64).uniform_(60, 600, generator=g)
    bbox = torch.cat([centre - wh / 2, centre + wh / 2], dim=-1)
    return tau.to(dtype), bbox.to(dtype), Kt.to(dtype)


# ----------------------------------------------------------------------------------- crop vector


@pytest.mark.parametrize("dtype", DTYPES)
def test_crop_vector_hand_computed(dtype):
    K = intrinsics_matrix(*SYN, dtype=dtype)
    bbox = torch.tensor([[860.0, 340.0, 1060.0, 740.0], [1200.0, 100.0, 1500.0, 300.0]], dtype=dtype)
    P = crop_vector(bbox, K)
    expected = torch.tensor(
        [
            [0.0, 0.0, 224.0 / 400.0],  # centred at the principal point, tall box -> side = h
            [1350.0 / 960.0 - 1.0, 200.0 / 540.0 - 1.0, 224.0 / 300.0],  # wide box -> side = w
        ],
        dtype=dtype,
    )
    assert P.shape == (2, 3) and P.dtype == dtype
    torch.testing.assert_close(P, expected)
    torch.testing.assert_close(crop_vector(bbox[1], K, input_size=256)[2], torch.tensor(256.0 / 300.0, dtype=dtype))


def test_crop_vector_uses_principal_point_not_image_centre():
    K = intrinsics_matrix(*CAM0, dtype=torch.float64)
    cx, cy = CAM0[2], CAM0[3]
    bbox = torch.tensor([cx - 50, cy - 100, cx + 50, cy + 100], dtype=torch.float64)
    torch.testing.assert_close(crop_vector(bbox, K), torch.tensor([0.0, 0.0, 224 / 200], dtype=torch.float64))
    # bx * cx is the crop-centre offset from the principal point, in pixels
    P = crop_vector(bbox + torch.tensor([37.0, -12.0, 37.0, -12.0], dtype=torch.float64), K)
    torch.testing.assert_close(P[:2] * torch.tensor([cx, cy], dtype=torch.float64), torch.tensor([37.0, -12.0], dtype=torch.float64))


@pytest.mark.parametrize(
    "bbox, message",
    [
        ([100.0, 100.0, 100.0, 200.0], "degenerate"),  # zero width
        ([100.0, 200.0, 150.0, 100.0], "degenerate"),  # negative height
        ([100.0, float("nan"), 150.0, 300.0], "non-finite"),
        ([100.0, 100.0, float("inf"), 300.0], "non-finite"),
    ],
)
@pytest.mark.parametrize(
    "fn",
    [
        lambda b, K: crop_vector(b, K),
        lambda b, K: crop_intrinsics(K, b),
        lambda b, K: crop_affine_matrix(b),
        lambda b, K: full_to_crop_pixels(torch.zeros(1, 2, dtype=b.dtype), b),
        lambda b, K: crop_to_full_pixels(torch.zeros(1, 2, dtype=b.dtype), b),
    ],
    ids=["crop_vector", "crop_intrinsics", "crop_affine_matrix", "full_to_crop_pixels", "crop_to_full_pixels"],
)
def test_bad_bbox_raises(fn, bbox, message):
    K = intrinsics_matrix(*SYN, dtype=torch.float64)
    with pytest.raises(ValueError, match=message):
        fn(torch.tensor(bbox, dtype=torch.float64), K)
    # one bad box inside a batch is enough
    batch = torch.tensor([[0.0, 0.0, 10.0, 10.0], bbox, [5.0, 5.0, 20.0, 30.0]], dtype=torch.float64)
    with pytest.raises(ValueError, match=message):
        fn(batch, K)


def test_degenerate_message_names_the_box():
    K = intrinsics_matrix(*SYN)
    with pytest.raises(ValueError, match=r"width 0\.0 and height 50\.0"):
        crop_vector(torch.tensor([[0.0, 0.0, 10.0, 10.0], [3.0, 0.0, 3.0, 50.0]]), K)


def test_bad_principal_point_and_input_size_raise():
    bbox = torch.tensor([0.0, 0.0, 10.0, 10.0])
    with pytest.raises(ValueError, match="principal point"):
        crop_vector(bbox, intrinsics_matrix(1000.0, 1000.0, 0.0, 540.0))
    with pytest.raises(ValueError, match="input_size"):
        crop_vector(bbox, intrinsics_matrix(*SYN), input_size=0)


# ------------------------------------------------------------------------ crop intrinsics, pixels


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("cam", [SYN, CAM0, CAM1], ids=["syn", "cam0", "cam1"])
def test_crop_intrinsics_consistent_with_pixel_map_and_opencv(dtype, cam):
    tau, bbox, K = _random_scene(8, seed=10, dtype=dtype, K=cam)
    g = torch.Generator().manual_seed(11)
    X = tau[:, None, :] + (torch.randn(8, 30, 3, generator=g, dtype=torch.float64) * 0.5).to(dtype)  # body-sized clouds
    Kc = crop_intrinsics(K, bbox)
    assert Kc.shape == (8, 3, 3) and Kc.dtype == dtype
    via_full = full_to_crop_pixels(project_points(X, K), bbox)
    direct = project_points(X, Kc)
    tol = 2e-3 if dtype == torch.float32 else 1e-8
    torch.testing.assert_close(direct, via_full, atol=tol, rtol=0)
    for b in range(8):
        torch.testing.assert_close(direct[b], _cv2_project(X[b], Kc[b]).to(dtype), atol=tol, rtol=0)


def test_crop_intrinsics_hand_computed():
    K = intrinsics_matrix(*SYN, dtype=torch.float64)
    bbox = torch.tensor([1200.0, 100.0, 1500.0, 300.0], dtype=torch.float64)  # centre (1350, 200), side 300
    s = 224 / 300
    expected = torch.tensor(
        [[1475 * s, 0, 112 + s * (960 - 1350)], [0, 1475 * s, 112 + s * (540 - 200)], [0, 0, 1]], dtype=torch.float64
    )
    torch.testing.assert_close(crop_intrinsics(K, bbox), expected)
    # box corners land on the padded square: the wide box spans the full width, height is centred
    corners = torch.tensor([[1200.0, 100.0], [1500.0, 300.0]], dtype=torch.float64)
    torch.testing.assert_close(
        full_to_crop_pixels(corners, bbox),
        torch.tensor([[0.0, 112 - 100 * s], [224.0, 112 + 100 * s]], dtype=torch.float64),
    )


def test_crop_affine_matrix_drives_cv2_warp_affine():
    img = np.zeros((1080, 1920), np.uint8)
    bbox = torch.tensor([700.0, 300.0, 1100.0, 748.0])  # centre (900, 524), side 448 -> s = 0.5
    dots = [(900, 524), (720, 310), (1080, 740), (950, 400)]  # (u, v), full-image pixels
    for i, (u, v) in enumerate(dots):
        img[v, u] = 50 + 40 * i
    A = crop_affine_matrix(bbox, 224).numpy()[:2].astype(np.float64)
    crop = cv2.warpAffine(img, A, (224, 224), flags=cv2.INTER_LINEAR, borderValue=0)
    uv_crop = full_to_crop_pixels(torch.tensor(dots, dtype=torch.float32), bbox)
    for i, (uc, vc) in enumerate(uv_crop.tolist()):
        assert uc == int(uc) and vc == int(vc)  # chosen so the dots land on integer crop pixels
        assert crop[int(vc), int(uc)] == 50 + 40 * i
    assert int(crop.astype(np.int64).sum()) == sum(50 + 40 * i for i in range(len(dots)))


_box = st.tuples(
    st.floats(-200, 1900), st.floats(-200, 1000), st.floats(1.0, 1500), st.floats(1.0, 1500)
).map(lambda t: [t[0], t[1], t[0] + t[2], t[1] + t[3]])


@settings(max_examples=80, deadline=None, derandomize=True)
@given(_box, st.lists(st.tuples(st.floats(-3000, 3000), st.floats(-3000, 3000)), min_size=1, max_size=5))
def test_hypothesis_pixel_round_trip(box, pts):
    bbox = torch.tensor(box, dtype=torch.float64)
    uv = torch.tensor(pts, dtype=torch.float64)
    torch.testing.assert_close(crop_to_full_pixels(full_to_crop_pixels(uv, bbox), bbox), uv, atol=1e-8, rtol=1e-10)
    A = crop_affine_matrix(bbox)
    homog = torch.cat([uv, torch.ones(len(pts), 1, dtype=torch.float64)], dim=-1)
    torch.testing.assert_close((homog @ A.T)[:, :2], full_to_crop_pixels(uv, bbox), atol=1e-8, rtol=1e-10)


# ---------------------------------------------------------------------------- paper eq. (1)-(2)


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("cam", [SYN, CAM0, CAM1], ids=["syn", "cam0", "cam1"])
def test_eq_1_2_translation_projects_like_paper_crop_camera(dtype, cam):
    tau, bbox, K = _random_scene(50, seed=20, dtype=dtype, K=cam)
    P = crop_vector(bbox, K)
    tau_c = full_to_crop_translation(tau, P, K)
    bx, by, s = P.double().unbind(-1)
    fx, fy, cx, cy = cam
    tol = 1e-4 if dtype == torch.float32 else 1e-10
    # (1) z = z_c s
    torch.testing.assert_close(tau_c[:, 2] * P[:, 2], tau[:, 2], rtol=tol, atol=0)
    # (2) literally: fx x / z = (fx / s) x_c / z_c + bx cx, and the same for y
    t, tc = tau.double(), tau_c.double()
    ptol = 1e-2 if dtype == torch.float32 else 1e-8  # pixels
    torch.testing.assert_close(fx * t[:, 0] / t[:, 2], fx / s * tc[:, 0] / tc[:, 2] + bx * cx, atol=ptol, rtol=0)
    torch.testing.assert_close(fy * t[:, 1] / t[:, 2], fy / s * tc[:, 1] / tc[:, 2] + by * cy, atol=ptol, rtol=0)
    # tau (camera K) and tau_c (paper's crop camera: focal f/s, principal point offset by bx cx, by cy)
    # hit the same full-image pixel; checked with OpenCV
    for i in range(50):
        Kp = torch.tensor(
            [[fx / s[i], 0, cx + bx[i] * cx], [0, fy / s[i], cy + by[i] * cy], [0, 0, 1]], dtype=torch.float64
        )
        torch.testing.assert_close(_cv2_project(tau_c[i], Kp), _cv2_project(tau[i], K), atol=ptol, rtol=0)
    # in crop pixels, tau_c is seen by a camera with the full-image focal length centred on the crop
    Kcc = intrinsics_matrix(fx, fy, 112.0, 112.0, dtype=dtype)
    torch.testing.assert_close(
        project_points(tau_c[:, None], Kcc), full_to_crop_pixels(project_points(tau[:, None], K), bbox), atol=ptol, rtol=0
    )


def test_crop_to_full_translation_hand_computed():
    K = intrinsics_matrix(*SYN, dtype=torch.float64)
    P = torch.tensor([0.25, -0.5, 0.8], dtype=torch.float64)
    tau_c = torch.tensor([0.1, 0.2, 12.5], dtype=torch.float64)
    z = 12.5 * 0.8
    expected = torch.tensor([0.1 + 0.25 * 960 * z / 1475, 0.2 - 0.5 * 540 * z / 1475, z], dtype=torch.float64)
    torch.testing.assert_close(crop_to_full_translation(tau_c, P, K), expected)


_tau = st.tuples(st.floats(-10, 10), st.floats(-10, 10), st.floats(0.5, 60))
_P = st.tuples(st.floats(-1, 1), st.floats(-1, 1), st.floats(0.05, 20))


@settings(max_examples=80, deadline=None, derandomize=True)
@given(_tau, _P, st.sampled_from([SYN, CAM0, CAM1]))
def test_hypothesis_translation_round_trips(tau, P, cam):
    tau = torch.tensor(tau, dtype=torch.float64)
    P = torch.tensor(P, dtype=torch.float64)
    K = intrinsics_matrix(*cam, dtype=torch.float64)
    torch.testing.assert_close(crop_to_full_translation(full_to_crop_translation(tau, P, K), P, K), tau, atol=1e-9, rtol=1e-9)
    torch.testing.assert_close(full_to_crop_translation(crop_to_full_translation(tau, P, K), P, K), tau, atol=1e-9, rtol=1e-9)
    cam_w = translation_to_weak_perspective(tau, P, K)
    torch.testing.assert_close(weak_perspective_to_translation(cam_w, P, K), tau, atol=1e-9, rtol=1e-9)


def test_translation_broadcasts_over_batch():
    tau, bbox, K = _random_scene(6, seed=30, dtype=torch.float64)
    P = crop_vector(bbox, K)
    Kb = K.expand(6, 3, 3)
    batched = full_to_crop_translation(tau, P, K)
    assert batched.shape == (6, 3)
    torch.testing.assert_close(batched, full_to_crop_translation(tau, P, Kb))
    for i in range(6):
        torch.testing.assert_close(batched[i], full_to_crop_translation(tau[i], P[i], K))


# ------------------------------------------------------------------------- weak perspective


def test_weak_perspective_depth_hand_computed():
    K = intrinsics_matrix(*SYN, dtype=torch.float64)
    bbox = torch.tensor([860.0, 340.0, 1060.0, 740.0], dtype=torch.float64)  # side 400, centred
    P = crop_vector(bbox, K)
    tau = weak_perspective_to_translation(torch.tensor([0.9, 0.1, -0.2], dtype=torch.float64), P, K)
    # tz = 2 f / (L s_w); crop centred on the principal point -> no lateral offset
    torch.testing.assert_close(tau, torch.tensor([0.1, -0.2, 2 * 1475 / (400 * 0.9)], dtype=torch.float64))
    # official form 2 f_crop / (224 s_w) with f_crop = f s the crop focal in crop pixels
    torch.testing.assert_close(tau[2], torch.tensor(2 * 1475 * (224 / 400) / (224 * 0.9), dtype=torch.float64))


@pytest.mark.parametrize("dtype", DTYPES)
def test_weak_perspective_origin_projects_to_weak_camera_pixel(dtype):
    cam = (1400.0, 1400.0, 1010.0, 530.0)  # square pixels, off-centre principal point
    _, bbox, K = _random_scene(40, seed=40, dtype=dtype, K=cam)
    g = torch.Generator().manual_seed(41)
    cam_w = torch.stack(
        [
            torch.empty(40, dtype=torch.float64).uniform_(0.5, 1.5, generator=g),
            torch.empty(40, dtype=torch.float64).uniform_(-0.3, 0.3, generator=g),
            torch.empty(40, dtype=torch.float64).uniform_(-0.3, 0.3, generator=g),
        ],
        dim=-1,
    ).to(dtype)
    P = crop_vector(bbox, K)
    tau = weak_perspective_to_translation(cam_w, P, K)
    assert tau.shape == (40, 3) and tau.dtype == dtype
    # weak camera: body point X -> crop pixel (1 + s_w (X_xy + t)) * 224 / 2; the origin X = 0:
    weak_crop = (1 + cam_w[:, 0:1] * cam_w[:, 1:]) * 112
    weak_full = crop_to_full_pixels(weak_crop[:, None], bbox)
    tol = 2e-3 if dtype == torch.float32 else 1e-8
    torch.testing.assert_close(project_points(tau[:, None], K), weak_full, atol=tol, rtol=0)
    # points on the fronto-parallel plane through tau project exactly as the weak camera says
    d = torch.randn(40, 10, 3, generator=g, dtype=torch.float64).to(dtype) * 0.5
    d[..., 2] = 0
    persp = project_points(tau[:, None] + d, crop_intrinsics(K, bbox))
    weak = (1 + cam_w[:, None, 0:1] * (d[..., :2] + cam_w[:, None, 1:])) * 112
    torch.testing.assert_close(persp, weak, atol=tol, rtol=0)


def test_weak_perspective_non_square_pixels_scale_y_by_fy_over_fx():
    # documented behaviour: depth from fx, so the vertical weak scale is s_w fy / fx
    K = intrinsics_matrix(*CAM0, dtype=torch.float64)
    bbox = torch.tensor([900.0, 300.0, 1100.0, 700.0], dtype=torch.float64)
    cam_w = torch.tensor([1.1, 0.05, 0.2], dtype=torch.float64)
    tau = weak_perspective_to_translation(cam_w, crop_vector(bbox, K), K)
    uv_crop = project_points(tau[None], crop_intrinsics(K, bbox))[0]
    fx, fy = CAM0[0], CAM0[1]
    expected = torch.tensor([(1 + 1.1 * 0.05) * 112, (1 + 1.1 * fy / fx * 0.2) * 112], dtype=torch.float64)
    torch.testing.assert_close(uv_crop, expected)
    assert not math.isclose(float(uv_crop[1]), (1 + 1.1 * 0.2) * 112, abs_tol=1e-3)
