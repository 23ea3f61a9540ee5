"""Scene sampler, appearance regions and generation settings (no rendering)."""
from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
import torch

from airpose_lib.data.still.appearance import REGIONS, BodyPaint, body_regions, sample_appearance
from airpose_lib.data.still.generate import GenerationConfig
from airpose_lib.data.still.scene import (
    PersonSample,
    SceneConfig,
    body_world_pose,
    jitter_bbox,
    look_at_extrinsics,
    points_in_frame,
    sample_cameras,
    sample_environment,
    sample_person,
    tight_bbox,
)
from airpose_lib.errors import ProfileError
from airpose_lib.geometry import camera_center
from airpose_lib.reproduce.configs import kit_configs


def _project_cv(X_world, R, t, K):
    rvec, _ = cv2.Rodrigues(R)
    uv, _ = cv2.projectPoints(np.asarray(X_world, dtype=np.float64).reshape(-1, 1, 3), rvec, t, K, None)
    return uv[:, 0]


def test_default_scene_is_the_papers_protocol():
    cfg = SceneConfig()
    K = cfg.K
    assert cfg.num_views == 2 and cfg.image_size == (1920, 1080)
    assert K[0, 0] == K[1, 1] == 1475.0
    assert (K[0, 2], K[1, 2]) == (959.5, 539.5)  # the image centre with integer pixel centres
    assert cfg.person_extent == 2.75 and cfg.pitch_range_deg == (0.0, 45.0)
    assert cfg.bbox_margin_px == 20.0 and cfg.bbox_jitter_px == 200.0
    # ~66 degrees horizontal field of view, as the paper says
    assert math.degrees(2 * math.atan(960 / 1475)) == pytest.approx(66.1, abs=0.1)


@pytest.mark.parametrize("roll", [0.0, 0.3])
def test_look_at_extrinsics_against_opencv(roll):
    eye, target = np.array([3.0, 6.0, -8.0]), np.array([0.5, 1.0, 0.2])
    R, t = look_at_extrinsics(eye, target, roll)
    assert np.allclose(R @ R.T, np.eye(3), atol=1e-12) and np.linalg.det(R) == pytest.approx(1.0)
    centre = camera_center(torch.from_numpy(R), torch.from_numpy(t)).numpy()
    assert np.allclose(centre, eye, atol=1e-12)
    K = SceneConfig().K
    uv = _project_cv([target, target + [0, 1.0, 0]], R, t, K)
    assert np.allclose(uv[0], K[:2, 2], atol=1e-9)  # the target is at the principal point
    if roll == 0.0:
        # a point above the target appears straight above it (world Y up = image up)
        assert uv[1, 1] < uv[0, 1] and abs(uv[1, 0] - uv[0, 0]) < 1e-6


def test_cameras_follow_the_protocol():
    cfg = SceneConfig(num_views=3)
    rng = np.random.default_rng(0)
    for _ in range(50):
        cams = sample_cameras(rng, cfg)
        assert len(cams) == 3
        for c in cams:
            forward = c.R_cw[2]  # optical axis in the world
            pitch = math.degrees(math.asin(-forward[1]))
            assert 0.0 - 1e-9 <= pitch <= 45.0 + 1e-9
            assert pitch == pytest.approx(math.degrees(c.pitch), abs=1e-9)
            assert np.linalg.norm(c.centre - c.target) == pytest.approx(c.distance)
            assert 8.5 - 1e-9 <= c.distance <= 11.5 + 1e-9
            assert np.all(np.abs(c.target[[0, 2]]) <= 0.5) and 0.5 <= c.target[1] <= 1.2
            assert np.allclose(-c.R_cw.T @ c.t_cw, c.centre)


def test_person_stands_on_the_ground_inside_the_square():
    cfg = SceneConfig()
    rng = np.random.default_rng(1)
    zero_pose = lambda r, n: np.zeros((n, 21, 3))  # noqa: E731
    for _ in range(20):
        p = sample_person(rng, cfg, zero_pose)
        assert p.gender in cfg.genders and p.betas.shape == (10,) and np.all(np.abs(p.betas) <= 3.0)
        assert np.all(np.abs(p.position) <= 2.75)
    v0 = rng.normal(size=(100, 3)) + [0, 0.9, 0]
    person = PersonSample("male", np.zeros(10), np.zeros((21, 3)), np.array([1.0, -2.0]), 0.7)
    R_wb, t_wb = body_world_pose(person, v0)
    vw = v0 @ R_wb.T + t_wb
    assert vw[:, 1].min() == pytest.approx(0.0, abs=1e-12)
    assert t_wb[[0, 2]] == pytest.approx([1.0, -2.0])
    # heading turns the body's forward (+Z) towards +X for positive angles
    assert (R_wb @ [0, 0, 1.0]) == pytest.approx([math.sin(0.7), 0, math.cos(0.7)])


def test_boxes_tight_and_jittered():
    uv = np.array([[100.0, 200.0], [150.0, 400.0], [120.0, 300.0]])
    tight = tight_bbox(uv, 20.0)
    assert tight == pytest.approx([80.0, 180.0, 170.0, 420.0])
    rng = np.random.default_rng(2)
    for _ in range(100):
        b = jitter_bbox(tight, rng, 200.0, (1920, 1080))
        assert np.all(b[:2] <= tight[:2]) and np.all(b[2:] >= tight[2:])  # never tighter
        assert np.all(tight[:2] - b[:2] <= 200.0) and np.all(b[2:] - tight[2:] <= 200.0)
        assert b[0] >= -0.5 and b[1] >= -0.5 and b[2] <= 1919.5 and b[3] <= 1079.5
    assert jitter_bbox(tight, rng, 0.0, (1920, 1080)) == pytest.approx(tight)


def test_points_in_frame():
    uv = np.array([[0.0, 0.0], [-0.6, 10.0], [1919.5, 1079.5], [10.0, 1080.0], [5.0, 5.0]])
    z = np.array([1.0, 1.0, 1.0, 1.0, -1.0])
    assert points_in_frame(uv, z, (1920, 1080)).tolist() == [True, False, True, False, False]


def _segment_distance(p, a, b):
    ab = b - a
    t = np.clip(np.dot(p - a, ab) / np.dot(ab, ab), 0, 1)
    return np.linalg.norm(p - (a + t * ab))


def test_distractors_never_stand_between_a_camera_and_the_person():
    cfg = SceneConfig(num_distractors=(4, 4))
    rng = np.random.default_rng(3)
    seen = 0
    for _ in range(30):
        cams = sample_cameras(rng, cfg)
        person = rng.uniform(-2.75, 2.75, size=2)
        env = sample_environment(rng, cfg, 7, person, np.stack([c.centre for c in cams]))
        assert 0 <= env.ground_texture < 7
        assert env.light_dir[1] < 0 and np.linalg.norm(env.light_dir) == pytest.approx(1.0)
        for d in env.distractors:
            seen += 1
            r = 0.5 * np.hypot(d.size[0], d.size[2])
            for c in cams:
                assert _segment_distance(d.position, c.centre[[0, 2]], person) > r + cfg.distractor_clearance
    assert seen > 60  # most placements succeed


def test_body_regions_cover_the_body(open_model):
    paint = BodyPaint.from_model(open_model)
    counts = np.bincount(paint.regions, minlength=len(REGIONS))
    assert np.all(counts > 50), dict(zip(REGIONS, counts))
    v = open_model.v_template.numpy()
    hair, skin = paint.regions == REGIONS.index("hair"), paint.regions == REGIONS.index("skin")
    shoe = paint.regions == REGIONS.index("shoe")
    assert v[hair, 1].mean() > v[skin, 1].mean() > v[shoe, 1].mean()
    lo, hi = v[:, 1].min(), v[:, 1].max()
    assert v[shoe, 1].max() < lo + 0.15 * (hi - lo)  # shoes: the lowest part of the body
    assert v[hair, 1].min() > lo + 0.85 * (hi - lo)  # hair: the top of the head
    # the same regions straight from body_regions
    J = (open_model.J_regressor @ open_model.v_template).numpy()
    assert np.array_equal(body_regions(open_model.lbs_weights.numpy(), v, J), paint.regions)


def test_appearance_colours_follow_regions(open_model):
    paint = BodyPaint.from_model(open_model)
    rng = np.random.default_rng(4)
    looks = [sample_appearance(rng) for _ in range(20)]
    cols = [paint.colors(a, shading_strength=0.0) for a in looks]
    assert all(c.shape == (len(open_model.v_template), 3) and c.dtype == np.uint8 for c in cols)
    a, c = looks[0], cols[0]
    regions = paint.regions_for(a)
    for r in range(len(REGIONS)):
        assert np.allclose(c[regions == r], np.round(a.region_colors[r] * 255), atol=1)
    assert len({tuple(np.asarray(c).mean(0).round()) for c in cols}) == 20  # varied looks
    shaded = paint.colors(a, shading_strength=0.12).astype(float)
    assert 0 < np.abs(shaded - c).max() <= 0.12 * 255 + 1


def test_generation_config_round_trip_and_splits():
    cfg = GenerationConfig(num_samples=105, shard_size=10, scene=SceneConfig(num_views=3))
    again = GenerationConfig.from_dict(cfg.to_dict())
    assert again == cfg and again.fingerprint() == cfg.fingerprint()
    assert cfg.num_shards == 11 and cfg.shard_samples(10) == 5 and cfg.num_test_shards == 1
    assert [cfg.shard_split(k) for k in range(11)] == ["train"] * 9 + ["val", "test"]
    assert cfg.replace(seed=1).fingerprint() != cfg.fingerprint()
    with pytest.raises(ValueError, match="scene: unknown key 'num_view'.*did you mean 'num_views'"):
        GenerationConfig.from_dict({"scene": {"num_view": 2}})
    with pytest.raises(ValueError, match="data: unknown key 'samples'"):
        GenerationConfig.from_dict({"samples": 2})


def test_profiles_define_the_dataset_sizes():
    """paper: the paper's size; cpu: more samples than paper's (its regressors train on a frozen
    backbone's cached features and need many distinct crops) but fewer pixels, about 0.6 GB."""
    smoke, cpu, paper = (kit_configs(p).still for p in ("smoke", "cpu", "paper"))
    assert paper.num_samples == 30000 and paper.crop_size == 224
    assert smoke.num_samples < cpu.num_samples
    assert cpu.num_samples * cpu.crop_size ** 2 < paper.num_samples * paper.crop_size ** 2 / 2
    assert 6000 <= cpu.num_samples <= 40000
    for c in (smoke, cpu, paper):
        assert c.scene == SceneConfig() and 0.05 <= c.num_test_shards / c.num_shards <= 0.15
    with pytest.raises(ProfileError, match="unknown profile"):  # at the entry, before any section
        kit_configs("nope")
