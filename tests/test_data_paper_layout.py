"""The paper-layout data option (profile ``cpu_paper_layout``): cameras 10 m from
the ground origin and aimed at it, and a stature spread of real adults within a sex."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from airpose_lib.body import load_body_model, stature
from airpose_lib.body.forward import rest_body
from airpose_lib.data.still.scene import SceneConfig, sample_cameras, sample_person
from airpose_lib.errors import ConfigError
from airpose_lib.reproduce.configs import kit_configs


@pytest.fixture(scope="module")
def configs():
    return kit_configs("cpu").still, kit_configs("cpu_paper_layout").still


def test_only_the_scene_differs_from_cpu(configs):
    cpu, paper = configs
    assert paper.replace(scene=cpu.scene) == cpu  # sizes, seed, crops: cpu's
    changed = {k for k in cpu.scene.__dataclass_fields__ if getattr(cpu.scene, k) != getattr(paper.scene, k)}
    assert changed == {"camera_distance_jitter", "target_jitter", "target_height_range", "beta_std"}
    # the paper's (Sec. IV-A), as cpu's
    assert paper.scene.camera_distance == 10.0 and paper.scene.pitch_range_deg == (0.0, 45.0)
    assert paper.scene.person_extent == 2.75


def test_cameras_are_10_m_from_the_origin_and_aimed_at_it(configs):
    _, paper = configs
    rng = np.random.default_rng(0)
    cams = [c for _ in range(100) for c in sample_cameras(rng, paper.scene)]
    centres = np.stack([c.centre for c in cams])
    assert np.allclose(np.linalg.norm(centres, axis=1), 10.0, atol=1e-9)
    assert np.allclose(np.stack([c.target for c in cams]), 0.0)
    # the origin lies on every optical axis, 10 m ahead: it projects to the principal point
    origin_cam = np.stack([c.t_cw for c in cams])
    assert np.allclose(origin_cam, [0.0, 0.0, 10.0], atol=1e-9)
    pitch = np.degrees(np.arcsin(centres[:, 1] / 10.0))
    assert pitch.min() >= 0.0 and pitch.max() <= 45.0 and pitch.max() - pitch.min() > 35.0


def test_stature_spread_is_that_of_real_adults(configs):
    """Within a sex, real adults' stature SD is 6.5-7.5 cm; cpu's draws give 8.8-9.2 cm. 400
    subjects each, the same draws under both settings, T-pose statures from the body forward."""
    cpu, paper = configs
    no_pose = lambda rng, n: np.zeros((n, 21, 3))  # noqa: E731
    sd = {}
    for name, scene in (("cpu", cpu.scene), ("paper", paper.scene)):
        rng = np.random.default_rng(3)
        people = [sample_person(rng, scene, no_pose) for _ in range(800)]
        for g in ("male", "female"):
            betas = np.stack([p.betas for p in people if p.gender == g])
            v, _ = rest_body(load_body_model("open", g, dtype=torch.float64), betas, np.zeros((len(betas), 21, 3)))
            sd[name, g] = float(np.std(stature(v), ddof=1))
    for g in ("male", "female"):
        assert 0.065 <= sd["paper", g] <= 0.075, (g, sd)
        assert 0.085 <= sd["cpu", g] <= 0.097, (g, sd)
        assert sd["paper", g] / sd["cpu", g] == pytest.approx(1 / 1.3, abs=0.02)


def test_beta_std_per_coefficient():
    rng_a, rng_b = np.random.default_rng(5), np.random.default_rng(5)
    no_pose = lambda rng, n: np.zeros((n, 21, 3))  # noqa: E731
    a = sample_person(rng_a, SceneConfig(), no_pose)
    b = sample_person(rng_b, SceneConfig(beta_std=(1.0,) * 10), no_pose)
    assert np.array_equal(a.betas, b.betas)  # the default draw is unchanged
    c = sample_person(np.random.default_rng(5), SceneConfig(beta_std=(0.5,) + (1.0,) * 9), no_pose)
    assert c.betas[0] == pytest.approx(0.5 * a.betas[0]) and np.array_equal(c.betas[1:], a.betas[1:])
    with pytest.raises(ConfigError, match="beta_std"):
        SceneConfig(beta_std=(1.0, 1.0))
    with pytest.raises(ConfigError, match="beta_std"):
        SceneConfig(beta_std=-1.0)
