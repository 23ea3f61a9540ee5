"""Pose sampler: limits, determinism, variety, anatomical directions, no gross self-penetration."""
from __future__ import annotations

import numpy as np
import pytest

from airpose_lib.body import joint_index
from airpose_lib.body.forward import rest_body
from airpose_lib.data.still.poses import (
    JOINT_LIMITS_DEG,
    POSE_JOINT_NAMES,
    PRIMITIVES,
    clip_to_limits,
    compose_pose,
    joint_limits,
    sample_body_pose,
    walking_params,
    within_limits,
)


def _joints(model, theta: np.ndarray) -> np.ndarray:
    """The 76 joints (B, 76, 3) of the mean body in pose theta."""
    return rest_body(model, np.zeros((len(theta), 10)), theta, mesh=False)[1]


def test_limits_table_is_consistent():
    assert joint_limits.shape == (21, 2, 3)
    assert set(JOINT_LIMITS_DEG) == set(POSE_JOINT_NAMES)
    assert np.all(joint_limits[:, 0] < joint_limits[:, 1])
    # the documented single-axis ranges
    k = POSE_JOINT_NAMES.index("left_knee")
    np.testing.assert_allclose(np.rad2deg(joint_limits[k, :, 0]), [0.0, 150.0])
    e = POSE_JOINT_NAMES.index("right_elbow")
    np.testing.assert_allclose(np.rad2deg(joint_limits[e, :, 1]), [0.0, 150.0])


def test_samples_within_limits_and_deterministic():
    a = sample_body_pose(np.random.default_rng(7), 3000)
    b = sample_body_pose(np.random.default_rng(7), 3000)
    c = sample_body_pose(np.random.default_rng(8), 3000)
    assert a.shape == (3000, 21, 3) and a.dtype == np.float64
    assert np.all(within_limits(a))
    np.testing.assert_array_equal(a, b)
    assert not np.allclose(a, c)
    knees = a[:, [POSE_JOINT_NAMES.index("left_knee"), POSE_JOINT_NAMES.index("right_knee")], 0]
    assert knees.min() >= 0.0 and knees.max() <= np.deg2rad(150) + 1e-12


def test_clip_to_limits_against_manual_loop():
    x = np.random.default_rng(0).uniform(-3, 3, (50, 21, 3))
    y = clip_to_limits(x)
    for j in range(21):
        for c in range(3):
            lo, hi = joint_limits[j, 0, c], joint_limits[j, 1, c]
            np.testing.assert_array_equal(y[:, j, c], np.minimum(np.maximum(x[:, j, c], lo), hi))
    assert within_limits(y).all() and not within_limits(x).any()


def test_variety_and_not_uniform():
    theta, lab = sample_body_pose(np.random.default_rng(3), 800, return_primitives=True)
    flat = theta.reshape(len(theta), -1)
    d = np.linalg.norm(flat[:400, None] - flat[None, 400:], axis=-1)
    assert np.median(d) > 0.8  # radians over 63 components: genuinely different poses
    assert (d < 0.05).mean() < 1e-3  # no near-duplicates
    assert set(np.unique(lab)) == set(range(len(PRIMITIVES)))
    # not uniform in the box: knee flexion of standing poses stays small, of squats large
    k = POSE_JOINT_NAMES.index("left_knee")
    stand = theta[lab == PRIMITIVES.index("standing"), k, 0]
    squat = theta[lab == PRIMITIVES.index("squatting"), k, 0]
    assert np.rad2deg(stand).max() < 30 and np.rad2deg(squat).mean() > 80


def test_primitive_selection():
    _, lab = sample_body_pose(np.random.default_rng(0), 50, {"walking": 1.0, "bending": 0.0},
                              return_primitives=True)
    assert np.all(lab == PRIMITIVES.index("walking"))
    _, lab = sample_body_pose(np.random.default_rng(0), 50, "crouching", return_primitives=True)
    assert np.all(lab == PRIMITIVES.index("crouching"))
    with pytest.raises(ValueError, match="unknown primitive"):
        sample_body_pose(np.random.default_rng(0), 5, ["flying"])
    with pytest.raises(KeyError):
        compose_pose({"tail_wag": np.zeros(2)})


def test_walking_gait_is_periodic_and_antisymmetric():
    ph = np.linspace(0, 2 * np.pi, 9)
    a = walking_params(ph)
    b = walking_params(ph + 2 * np.pi)
    c = walking_params(ph + np.pi)
    for k in a:
        np.testing.assert_allclose(a[k], b[k], atol=1e-12)
    np.testing.assert_allclose(a["l_hip_flex"], c["r_hip_flex"], atol=1e-12)
    np.testing.assert_allclose(a["l_knee"], c["r_knee"], atol=1e-12)


def _d(J, a, b):
    return J[joint_index(a)] - J[joint_index(b)]


def test_parameter_directions(open_model):
    """Each parameter moves the limb the anatomical way (model faces +Z, +X = its left, Y up)."""
    deg = np.deg2rad
    cases = compose_pose({
        "l_arm_flex": deg(np.array([90, 0, 0, 0, 0, 0, 0])),
        "l_elbow": deg(np.array([0, 90, 0, 0, 0, 0, 0])),
        "r_hip_flex": deg(np.array([0, 0, 90, 0, 0, 0, 0])),
        "r_knee": deg(np.array([0, 0, 0, 90, 0, 0, 0])),
        "spine_bend": deg(np.array([0, 0, 0, 0, 40, 0, 0])),
        "l_arm_abd": deg(np.array([0, 0, 0, 0, 0, 170, 0])),
        "l_hip_abd": deg(np.array([0, 0, 0, 0, 0, 0, 30])),
    })
    J = _joints(open_model, cases)
    assert _d(J[0], "left_wrist", "left_shoulder")[2] > 0.3  # arm forwards
    assert _d(J[1], "left_wrist", "left_elbow")[2] > 0.15  # forearm forwards
    assert _d(J[2], "right_knee", "right_hip")[2] > 0.3  # thigh forwards
    assert _d(J[3], "right_ankle", "right_knee")[2] < -0.3  # shank backwards
    assert _d(J[4], "neck", "pelvis")[2] > 0.15  # trunk forwards
    assert _d(J[5], "left_wrist", "left_shoulder")[1] > 0.4  # arm overhead
    assert _d(J[6], "left_knee", "left_hip")[0] > 0.15  # thigh to the subject's left
    # zero parameters: straight legs, hanging arms
    J0 = _joints(open_model, compose_pose({}, n=1))[0]
    assert _d(J0, "left_wrist", "left_shoulder")[1] < -0.4


def test_wrists_outside_torso(open_model):
    """Gross self-penetration check: wrists away from the pelvis-neck axis for >95 % of samples."""
    theta = sample_body_pose(np.random.default_rng(11), 1000)
    J = _joints(open_model, theta)
    a, b = J[:, joint_index("pelvis")], J[:, joint_index("neck")]
    ab = b - a
    for wrist in ("left_wrist", "right_wrist"):
        p = J[:, joint_index(wrist)]
        t = np.clip(((p - a) * ab).sum(-1) / (ab * ab).sum(-1), 0.0, 1.0)
        dist = np.linalg.norm(p - (a + t[:, None] * ab), axis=-1)
        assert (dist > 0.1).mean() > 0.95
    # the two ankles never swap sides (legs crossing through each other)
    lx = J[:, joint_index("left_ankle"), 0] - J[:, joint_index("right_ankle"), 0]
    assert (lx > 0).mean() > 0.95
