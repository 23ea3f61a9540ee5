"""The field camera pipeline of the recordings (``data.sequences.field``): each part against
hand-computed values or OpenCV, and the option's promise that off changes nothing."""
from __future__ import annotations

import dataclasses
import hashlib
import json

import cv2
import numpy as np
import pytest

from airpose_lib.data.sequences import SequenceConfig, sequence_configs_from_profile
from airpose_lib.data.sequences.field import (
    RENDER_GAMMA,
    FieldConfig,
    exposure_white_balance,
    field_frame,
    field_rng,
    from_linear,
    jpeg_compress,
    lens_distortion,
    motion_blur,
    motion_blur_kernel,
    person_image_velocity,
    sensor_noise,
    to_linear,
)
from airpose_lib.errors import ProfileSettingError
from airpose_lib.reproduce.configs import kit_configs


def _textured(h: int = 96, w: int = 128, seed: int = 0) -> np.ndarray:
    """(h, w, 3) uint8: smooth gradients plus a blocky texture (something JPEG has to work on)."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:h, 0:w]
    base = np.stack([x / w, y / h, (x + y) / (w + h)], -1) * 160 + 40
    blocks = cv2.resize(rng.uniform(-40, 40, (h // 8, w // 8, 3)), (w, h), interpolation=cv2.INTER_NEAREST)
    return np.clip(base + blocks, 0, 255).astype(np.uint8)


# -- the parts ------------------------------------------------------------------------------------
def test_gamma_round_trip_and_hand_values():
    x = np.arange(256, dtype=np.uint8).reshape(16, 16, 1).repeat(3, -1)
    for g in (RENDER_GAMMA, 1.8, 2.6):
        np.testing.assert_array_equal(from_linear(to_linear(x, g), g), x)
    assert to_linear(np.array([[[128, 0, 255]]], np.uint8))[0, 0] == pytest.approx([(128 / 255) ** 2.2, 0, 1], rel=1e-6)
    # another tone curve on mid-grey: 255 ((100/255)^2.2)^(1/1.8) = 80.97 -> 81
    assert from_linear(to_linear(np.full((1, 1, 3), 100, np.uint8)), 1.8)[0, 0, 0] == 81
    assert from_linear(np.array([[[-0.5, 1.5, 0.5]]], np.float32))[0, 0].tolist() == [0, 255, 186]


def test_exposure_and_white_balance_are_linear_gains():
    lin = np.full((2, 2, 3), 0.25, np.float32)
    out = exposure_white_balance(lin, 1.0, (1.0, 0.5, 2.0))
    np.testing.assert_allclose(out[0, 0], [0.5, 0.25, 1.0])
    # +1 EV on mid-grey 100 through the render's own curve: 100 * 2^(1/2.2) = 137.0
    cfg = FieldConfig(enabled=True, exposure_ev=1.0)
    assert field_frame(np.full((4, 4, 3), 100, np.uint8), cfg, field_rng(0, 0, 0))[0, 0, 0] == 137


def test_noise_variance_follows_the_poissonian_gaussian_model():
    a, sigma_b = 0.01, 0.02
    rng = np.random.default_rng(5)
    for y in (0.05, 0.2, 0.6):
        flat = np.full((256, 256, 3), y, np.float32)
        z = sensor_noise(flat, a, sigma_b, rng)
        expected = a * y + sigma_b ** 2  # Foi et al. 2008, eq. (3)
        assert z.mean() == pytest.approx(y, abs=5e-4)
        assert z.var() == pytest.approx(expected, rel=0.03)
    # same generator state -> same noise; a zero model leaves the signal alone
    np.testing.assert_array_equal(sensor_noise(flat, a, sigma_b, np.random.default_rng(1)),
                                  sensor_noise(flat, a, sigma_b, np.random.default_rng(1)))
    np.testing.assert_array_equal(sensor_noise(flat, 0.0, 0.0, rng), flat)


def test_motion_blur_spreads_a_point_along_the_velocity():
    img = np.zeros((41, 41, 1), np.float32)
    img[20, 20] = 1.0
    v, shutter = np.array([6.0, 8.0]), 0.5  # |v| = 10 px/frame -> a 5 px streak
    out = motion_blur(img, v, shutter)
    out = out.reshape(41, 41)
    assert out.sum() == pytest.approx(1.0, abs=1e-5)
    ys, xs = np.nonzero(out > 1e-6)
    d = v / np.linalg.norm(v)
    along = (xs - 20) * d[0] + (ys - 20) * d[1]
    across = -(xs - 20) * d[1] + (ys - 20) * d[0]
    assert np.abs(across).max() < 1.5  # on the line (bilinear splat: at most a pixel off)
    assert 2.5 - 1.0 <= along.max() <= 2.5 + 1.5 and -2.5 - 1.5 <= along.min() <= -2.5 + 1.0
    w = out[ys, xs]
    mean_along = (w * along).sum()
    var_along = (w * (along - mean_along) ** 2).sum()
    assert mean_along == pytest.approx(0.0, abs=0.05)  # centred on the frame's time
    # a uniform segment of length L has variance L^2 / 12 (2.08); the splat adds < 1/2
    assert 25 / 12 <= var_along <= 25 / 12 + 0.5
    # under a pixel of motion: nothing to do
    assert motion_blur_kernel((1.0, 0.0), 0.5) is None
    assert motion_blur(img, (1.0, 0.0), 0.5) is img


def test_lens_distortion_moves_a_point_where_the_model_says():
    W, H = 320, 180
    K = np.array([[250.0, 0, 165.0], [0, 240.0, 88.0], [0, 0, 1]])
    img = np.zeros((H, W, 1), np.float32)
    assert lens_distortion(img, K, 0.0, 0.0) is img  # k = 0: identity
    p_u = np.array([270.0, 150.0])  # pinhole pixel, far from the centre
    yy, xx = np.mgrid[0:H, 0:W]
    blob = np.exp(-((xx - p_u[0]) ** 2 + (yy - p_u[1]) ** 2) / (2 * 1.2 ** 2)).astype(np.float32)
    k1, k2 = -0.25, 0.08
    out = lens_distortion(blob[..., None], K, k1, k2).reshape(H, W)
    # where the distortion formula sends the point (OpenCV's own forward model)
    x_n = np.linalg.solve(K, [*p_u, 1.0])
    p_d = cv2.projectPoints(x_n[None], np.zeros(3), np.zeros(3), K, np.array([k1, k2, 0, 0]))[0][0, 0]
    r2 = x_n[0] ** 2 + x_n[1] ** 2  # and by hand
    by_hand = K[:2, :2] @ (x_n[:2] * (1 + k1 * r2 + k2 * r2 ** 2)) + K[:2, 2]
    np.testing.assert_allclose(p_d, by_hand, atol=1e-6)
    assert np.linalg.norm(p_d - p_u) > 5  # a real displacement
    m = out > 1e-3
    centroid = np.array([(out * xx)[m].sum(), (out * yy)[m].sum()]) / out[m].sum()
    np.testing.assert_allclose(centroid, p_d, atol=0.15)
    back = cv2.undistortPoints(centroid[None, None], K, np.array([k1, k2, 0, 0]), P=K)[0, 0]
    np.testing.assert_allclose(back, p_u, atol=0.2)


def test_jpeg_quality_orders_the_error():
    img = _textured()

    def err(q):
        return np.abs(jpeg_compress(img, q).astype(float) - img).mean()

    assert jpeg_compress(img, 90).shape == img.shape and jpeg_compress(img, 90).dtype == np.uint8
    assert err(100) < err(60) < err(10)
    assert err(10) > 2 * err(90)
    # quality 100 keeps a grey image nearly exactly (the colour image loses its sharp colour
    # edges to 4:2:0 chroma subsampling even at 100, as a camera's video does)
    grey = np.repeat(img.mean(-1, keepdims=True).astype(np.uint8), 3, -1)
    assert np.abs(jpeg_compress(grey, 100).astype(float) - grey).mean() < 0.2
    assert np.abs(jpeg_compress(grey, 10).astype(float) - grey).mean() > 1.0
    # the channel order survives (a red image stays red)
    red = np.zeros((32, 32, 3), np.uint8)
    red[..., 0] = 200
    assert jpeg_compress(red, 80)[..., 0].mean() > 150 > jpeg_compress(red, 80)[..., 2].mean() + 100


# -- the pipeline ---------------------------------------------------------------------------------
def test_off_and_identity_keep_every_byte():
    img = _textured()
    rng = field_rng(0, 3, 1)
    loud = FieldConfig(exposure_ev=2.0, shot_noise=0.1, shutter=1.0, jpeg_quality=5, distortion=(0.3, 0.1))
    assert not loud.enabled
    assert field_frame(img, loud, rng, velocity_px=(20.0, 0.0)) is img  # off: nothing runs
    ident = FieldConfig(enabled=True)
    np.testing.assert_array_equal(field_frame(img, ident, rng, velocity_px=(20.0, 0.0)), img)
    # shutter on but no motion: still every byte
    np.testing.assert_array_equal(field_frame(img, dataclasses.replace(ident, shutter=0.5), rng), img)


def test_pipeline_is_seeded_per_frame_and_view():
    img = _textured()
    K = np.array([[100.0, 0, 64], [0, 100.0, 48], [0, 0, 1]])
    cfg = FieldConfig(enabled=True, exposure_ev=-0.5, white_balance=(1.1, 1.0, 0.9), gamma=2.0,
                      shot_noise=2e-3, read_noise=3e-3, shutter=0.5, distortion=(-0.1, 0.02), jpeg_quality=60)
    a = field_frame(img, cfg, field_rng(7, 2, 0), K=K, velocity_px=(4.0, 1.0))
    b = field_frame(img, cfg, field_rng(7, 2, 0), K=K, velocity_px=(4.0, 1.0))
    c = field_frame(img, cfg, field_rng(7, 2, 1), K=K, velocity_px=(4.0, 1.0))
    assert a.shape == img.shape and a.dtype == np.uint8
    np.testing.assert_array_equal(a, b)
    assert np.any(a != c)  # another drone: other noise
    assert np.abs(a.astype(float) - img).mean() > 3
    with pytest.raises(ValueError, match="intrinsics"):
        field_frame(img, cfg, field_rng(7, 2, 0))


def test_person_image_velocity_of_a_uniform_motion():
    t = np.arange(6, dtype=float)[:, None, None, None]  # (F, 1, 1, 1)
    j2d = np.array([[10.0, 20.0], [30.0, 60.0]])[None, None] + t * np.array([[[[2.0, -1.0]]], [[[0.5, 0.0]]]]).reshape(1, 2, 1, 2)
    v = person_image_velocity(j2d)  # (6, 2, 2)
    np.testing.assert_allclose(v[:, 0], [[2.0, -1.0]] * 6)
    np.testing.assert_allclose(v[:, 1], [[0.5, 0.0]] * 6)
    assert person_image_velocity(j2d[:1]).tolist() == [[[0.0, 0.0], [0.0, 0.0]]]


# -- the option in the recordings' settings -------------------------------------------------------
def _key(cfg: SequenceConfig) -> str:
    return hashlib.sha256(json.dumps(cfg.to_dict(), sort_keys=True).encode()).hexdigest()[:16]


def test_off_by_default_keeps_the_recordings_keys():
    # The settings dicts (the recordings' cache key, ``cache._is_complete``) as made before the
    # option existed (commit 462ba9f): the committed recordings stay current.
    assert _key(SequenceConfig()) == "8c759625ec8a5cb0"
    # smoke and cpu put ArUco markers on their field recordings only (`sequences: field_markers: {}`):
    # the clean recordings keep the keys of 462ba9f
    recs = {p: kit_configs(p).sequences for p in ("smoke", "cpu", "paper")}
    assert all(c.markers is None for r in recs.values() for c in r.values())
    assert {p: {k: _key(c) for k, c in r.items()} for p, r in recs.items()} == {
        "smoke": {"person1": "d2012b0c0901be57", "person2": "78765eac4941ace4"},
        "cpu": {"person1": "9c09252796577e29", "person2": "ffd84e642696b7e2"},
        "paper": {"person1": "f7f9b0226585b467", "person2": "431236088a97577f"},
    }
    assert "field" not in SequenceConfig(field=FieldConfig(exposure_ev=1.0)).to_dict()
    on = SequenceConfig(field=FieldConfig(enabled=True, jpeg_quality=40))
    assert on.to_dict()["field"]["jpeg_quality"] == 40 and _key(on) != _key(SequenceConfig())


def test_field_option_from_a_profile_section():
    section = {"fps": 30, "field": {"enabled": True, "exposure_ev": -0.5, "white_balance": [1.1, 1.0, 0.9],
                                    "distortion": [-0.1, 0.02], "jpeg_quality": 50},
               "recordings": {"person1": {"n_frames": 10}, "person2": {"n_frames": 10, "field": {"enabled": False}}}}
    recs = sequence_configs_from_profile(section)
    f = recs["person1"].field
    assert f.enabled and f.white_balance == (1.1, 1.0, 0.9) and f.distortion == (-0.1, 0.02)
    assert not recs["person2"].field.enabled
    back = SequenceConfig.from_dict(json.loads(json.dumps(recs["person1"].to_dict())))
    assert back.field == f
    with pytest.raises(ProfileSettingError, match="did you mean 'shutter'"):
        sequence_configs_from_profile({"field": {"shuter": 0.5}, "recordings": {"person1": {}}})
    with pytest.raises(ProfileSettingError, match="jpeg_quality"):
        sequence_configs_from_profile({"field": {"jpeg_quality": 0}, "recordings": {"person1": {}}})


def test_renderer_applies_the_option_only_when_on(open_model_files):
    from airpose_lib.data.sequences import SequenceRenderer, simulate_sequence

    sim = simulate_sequence(SequenceConfig(person="person1", n_frames=3, seed=2, render_scale=0.25,
                                           anti_aliasing=False))

    def render(field: FieldConfig) -> list[np.ndarray]:
        s = dataclasses.replace(sim, config=dataclasses.replace(sim.config, field=field))
        with SequenceRenderer(s) as r:
            return next(r.render_frames([1]))[1]

    clean = render(FieldConfig())
    off = render(FieldConfig(exposure_ev=2.0, jpeg_quality=5))
    on = render(FieldConfig(enabled=True, exposure_ev=1.0, read_noise=0.01))
    for v in range(2):
        np.testing.assert_array_equal(off[v], clean[v])
        assert on[v].mean() > clean[v].mean() + 10  # a stop brighter
        expected = field_frame(clean[v], FieldConfig(enabled=True, exposure_ev=1.0, read_noise=0.01),
                               field_rng(2, 1, v), K=sim.gt["K"][v])
        np.testing.assert_array_equal(on[v], expected)


def test_a_recording_that_keeps_some_of_the_video_frames(open_model_files):
    """``fps: 1, video_fps: 2`` (every second video frame kept): the motion blur is that of one
    video frame, half the image motion between two kept frames; video_fps unset keeps the settings."""
    from airpose_lib.data.sequences import SequenceRenderer, simulate_sequence
    from airpose_lib.errors import ConfigError

    cfg = SequenceConfig(person="person1", n_frames=3, seed=2, render_scale=0.25, anti_aliasing=False,
                         fps=1.0, video_fps=2.0)
    assert cfg.frame_step == 2.0 and SequenceConfig().frame_step == 1.0
    assert cfg.to_dict()["video_fps"] == 2.0 and "video_fps" not in SequenceConfig().to_dict()
    assert SequenceConfig.from_dict(json.loads(json.dumps(cfg.to_dict()))).to_dict() == cfg.to_dict()
    with pytest.raises(ConfigError, match="video_fps"):
        SequenceConfig(fps=30.0, video_fps=6.0)
    sim = simulate_sequence(cfg)
    blur = FieldConfig(enabled=True, shutter=1.0)

    def render(field: FieldConfig) -> list[np.ndarray]:
        s = dataclasses.replace(sim, config=dataclasses.replace(sim.config, field=field))
        with SequenceRenderer(s) as r:
            return next(r.render_frames([1]))[1]

    clean, blurred = render(FieldConfig()), render(blur)
    velocity = person_image_velocity(sim.gt["j2d"])[1]  # (V, 2) pixels per kept frame
    assert np.hypot(*velocity.T).min() > 2.0  # both blurs a pixel or more: their lengths tell
    for v in range(2):
        expected = field_frame(clean[v], blur, field_rng(2, 1, v), K=sim.gt["K"][v], velocity_px=velocity[v] / 2)
        np.testing.assert_array_equal(blurred[v], expected)
        assert not np.array_equal(blurred[v], field_frame(clean[v], blur, field_rng(2, 1, v), K=sim.gt["K"][v],
                                                          velocity_px=velocity[v]))
