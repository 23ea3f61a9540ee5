"""Scene renderer: pixel-exact camera against OpenCV, crops rendered with crop intrinsics, padding."""
from __future__ import annotations

import cv2
import numpy as np
import pytest
import pyvista as pv
import torch

from airpose_lib.data.still.render import SceneRenderer, ground_textures
from airpose_lib.data.still.scene import Distractor, EnvironmentSample, SceneConfig, look_at_extrinsics
from airpose_lib.geometry import box_in_crop, crop_intrinsics, full_to_crop_pixels, pad_outside_box


@pytest.fixture(scope="module")
def textures():
    return ground_textures(64)


def _env(texture=0, distractors=()):
    return EnvironmentSample(texture, 3.0, 0.3, np.zeros(2), np.array([0.6, 0.7, 0.5]),
                             np.array([0.7, 0.8, 0.9]), np.array([0.3, -0.9, 0.2]), 0.9, 0.35,
                             list(distractors))


def _sphere(centre, radius):
    s = pv.Sphere(radius=radius, center=centre, theta_resolution=40, phi_resolution=40)
    return np.asarray(s.points, dtype=np.float64), np.asarray(s.regular_faces)


def _cv_project(X, R, t, K):
    rvec, _ = cv2.Rodrigues(R)
    uv, _ = cv2.projectPoints(np.asarray(X, dtype=np.float64).reshape(-1, 1, 3), rvec, t, K, None)
    return uv[:, 0]


def _centroid(mask):
    ys, xs = np.nonzero(mask)
    return np.array([xs.mean(), ys.mean()])


def test_ground_textures():
    tex = ground_textures(64)
    names = [n for n, _ in tex]
    assert {"grass", "gravel", "brick"} <= set(names) and len(names) == len(set(names)) >= 7
    for _, img in tex:
        assert img.shape == (64, 64) and img.dtype == np.uint8 and img.std() > 5


def test_full_frame_render_matches_opencv(textures):
    """A small sphere lands where OpenCV projects its centre, with an off-centre principal point."""
    W, H = 320, 200
    K = np.array([[300.0, 0, 170.3], [0, 300.0, 88.7], [0, 0, 1]])
    R, t = look_at_extrinsics(np.array([4.0, 5.0, 7.0]), np.array([0.0, 0.5, 0.0]))
    centre = np.array([0.4, 0.8, -0.3])
    v, f = _sphere(centre, 0.2)
    with SceneRenderer((W, H), textures=textures) as r:
        r.set_environment(_env())
        r.set_body(v, f, np.full((len(v), 3), 255, np.uint8))
        img = r.render(K, R, t, body_only=True)
        full = r.render(K, R, t)
    assert img.shape == (H, W, 3)
    mask = img.sum(-1) > 0
    assert mask.sum() > 20
    assert np.allclose(_centroid(mask), _cv_project(centre, R, t, K)[0], atol=0.25)
    # the scene render has the ground everywhere below the horizon: no black pixels
    assert (full.sum(-1) == 0).mean() == 0.0


def test_crop_rendered_with_crop_intrinsics_matches_full_to_crop_pixels(textures):
    cfg = SceneConfig()
    K = cfg.K
    R, t = look_at_extrinsics(np.array([-6.0, 6.0, 6.0]), np.array([0.0, 0.9, 0.0]))
    centre = np.array([1.5, 0.9, 1.0])  # off the optical axis: the crop is far from the centre
    uv = _cv_project(centre, R, t, K)[0]
    bbox = np.array([uv[0] - 30.0, uv[1] - 90.0, uv[0] + 50.0, uv[1] + 70.0])
    S = 96
    Kc = crop_intrinsics(torch.from_numpy(K), torch.from_numpy(bbox), S).numpy()
    v, f = _sphere(centre, 0.05)
    with SceneRenderer(S, textures=textures) as r:
        r.set_environment(_env())
        r.set_body(v, f, np.full((len(v), 3), 200, np.uint8))
        img = r.render(Kc, R, t, body_only=True)
    expected = full_to_crop_pixels(torch.from_numpy(uv[None]), torch.from_numpy(bbox), S).numpy()[0]
    assert np.allclose(_centroid(img.sum(-1) > 0), expected, atol=0.3)


def test_environment_changes_the_picture(textures):
    R, t = look_at_extrinsics(np.array([0.0, 3.0, 8.0]), np.array([0.0, 0.5, 0.0]))
    K = np.array([[200.0, 0, 63.5], [0, 200.0, 63.5], [0, 0, 1]])
    v, f = _sphere([0.0, 0.5, 0.0], 0.3)
    box = Distractor("box", np.array([2.0, -1.0]), np.array([1.0, 1.0, 1.0]), 0.3, np.array([1.0, 0, 0]))
    with SceneRenderer(128, textures=textures) as r:
        r.set_body(v, f, np.full((len(v), 3), 128, np.uint8))
        r.set_environment(_env(0))
        a = r.render(K, R, t)
        r.set_environment(_env(3))
        b = r.render(K, R, t)
        r.set_environment(_env(3, [box]))
        c = r.render(K, R, t)
        r.set_environment(_env(3))
        silhouette = r.render(K, R, t, body_only=True)
        d = r.render(K, R, t)
    assert np.abs(a.astype(int) - b).mean() > 3  # another ground texture
    red = (c[..., 0] > 120) & (c[..., 1] < 60) & (c[..., 2] < 60)
    assert red.sum() > 50  # the red box is drawn ...
    assert np.array_equal(b, d)  # ... and gone again; a body-only render leaves no trace either
    body = silhouette.sum(-1) > 0
    assert body.sum() > 100 and np.all(silhouette[~body] == 0)


def test_pad_outside_box_matches_the_crop_geometry():
    bbox = np.array([100.0, 50.0, 160.0, 250.0])  # tall box: padding left and right
    S = 64
    u0, v0, u1, v1 = box_in_crop(bbox, S)
    corners = full_to_crop_pixels(torch.tensor([[[100.0, 50.0], [160.0, 250.0]]], dtype=torch.float64),
                                  torch.from_numpy(bbox)[None], S).numpy()[0]
    assert (u0, v0, u1, v1) == pytest.approx(corners.reshape(-1).tolist())
    img = pad_outside_box(np.full((S, S, 3), 200, np.uint8), bbox)
    cols = np.arange(S)
    inside = (cols >= u0) & (cols <= u1)
    assert np.all(img[:, inside] == 200) and np.all(img[:, ~inside] == 0)
    assert inside.sum() == pytest.approx(S * 60 / 200, abs=1)
