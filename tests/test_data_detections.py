"""Simulated keypoint detectors: the documented noise, miss, swap and confidence model."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from airpose_lib.body.joint_sets import BODY_25_NAMES, COCO18_NAMES
from airpose_lib.data.sequences.detections import (
    ALPHAPOSE,
    OPENPOSE,
    DetectorModel,
    detect_keypoints,
    simulate_detections,
)

CLEAN = dict(outlier_rate=0.0, swap_rate=0.0, limb_swap_rate=0.0, background_limb_rate=0.0, miss_rate=0.0,
             frame_miss_rate=0.0)


def _scene(F=3000, sizes=(80.0, 400.0), J=25, W=1920, H=1080, seed=0):
    """Keypoints scattered well inside the frame; view v has apparent person size sizes[v]."""
    rng = np.random.default_rng(seed)
    kp = rng.uniform([200, 200], [W - 200, H - 200], (1, len(sizes), J, 2)).repeat(F, 0)
    size = np.broadcast_to(np.asarray(sizes), (F, len(sizes))).copy()
    return kp, size, np.array([[W, H]] * len(sizes))


def test_noise_std_matches_model_and_grows_relative_to_size():
    det = dataclasses.replace(OPENPOSE, **CLEAN)
    kp, size, wh = _scene()
    out = detect_keypoints(kp, size, wh, det, np.random.default_rng(1))
    err = out.keypoints[..., :2] - kp  # (F, V, J, 2)
    sigma = det.sigma(size[0])  # (V, J)
    measured = err.std(axis=(0, 3))  # pooled over frames and both coordinates
    np.testing.assert_allclose(measured, sigma, rtol=0.12)
    np.testing.assert_allclose(sigma, det.difficulty * (det.sigma_px + det.sigma_rel * size[0][:, None]))
    # error relative to the apparent size is larger for the small (far) person
    rel = np.linalg.norm(err, axis=-1).mean(axis=(0, 2)) / size[0]
    assert rel[0] > 1.5 * rel[1]
    # mean 2D error of a Gaussian: sigma * sqrt(pi / 2)
    mean_err = np.linalg.norm(err, axis=-1).mean(0)
    np.testing.assert_allclose(mean_err, sigma * np.sqrt(np.pi / 2), rtol=0.1)


def test_metric_error_grows_with_distance():
    """Persons of 1.7 m at 5..20 m seen with f = 1500 px: the error at the person grows."""
    det = dataclasses.replace(OPENPOSE, **CLEAN)
    depth = np.array([5.0, 10.0, 20.0])
    size = 1500 * 1.7 / depth
    kp, s, wh = _scene(F=2000, sizes=size)
    out = detect_keypoints(kp, s, wh, det, np.random.default_rng(2))
    px = np.linalg.norm(out.keypoints[..., :2] - kp, axis=-1).mean(axis=(0, 2))
    metric = px * depth / 1500
    assert np.all(np.diff(metric) > 0)
    assert np.all(np.diff(px / size) > 0)


def test_temporal_correlation():
    det = dataclasses.replace(OPENPOSE, temporal_corr=0.6, **CLEAN)
    kp, size, wh = _scene(F=4000, sizes=(200.0,))
    e = (detect_keypoints(kp, size, wh, det, np.random.default_rng(3)).keypoints[..., 0] - kp[..., 0])[:, 0]
    r = np.mean([np.corrcoef(e[1:, j], e[:-1, j])[0, 1] for j in range(25)])
    assert abs(r - 0.6) < 0.05


def test_temporal_correlation_of_a_recording_that_keeps_every_fifth_frame():
    # AR(1) over video frames: five video frames apart the correlation is 0.8 ** 5 = 0.328
    det = dataclasses.replace(OPENPOSE, temporal_corr=0.8, **CLEAN)
    kp, size, wh = _scene(F=4000, sizes=(200.0,))
    e = (detect_keypoints(kp, size, wh, det, np.random.default_rng(3), frame_step=5).keypoints[..., 0]
         - kp[..., 0])[:, 0]
    r = np.mean([np.corrcoef(e[1:, j], e[:-1, j])[0, 1] for j in range(25)])
    assert abs(r - 0.8 ** 5) < 0.05
    one = detect_keypoints(kp, size, wh, det, np.random.default_rng(3), frame_step=1)
    np.testing.assert_array_equal(one.keypoints, detect_keypoints(kp, size, wh, det, np.random.default_rng(3)).keypoints)


def test_swap_and_miss_rates():
    det = dataclasses.replace(OPENPOSE, swap_rate=0.1, limb_swap_rate=0.1, miss_rate=0.05,
                              miss_size_ref=200.0, frame_miss_rate=0.05, outlier_rate=0.0,
                              background_limb_rate=0.0, sigma_px=0.5, sigma_rel=0.0)
    F = 4000
    kp, size, wh = _scene(F=F, sizes=(200.0, 100.0))
    out = detect_keypoints(kp, size, wh, det, np.random.default_rng(4))
    n = F * 2
    tol = 4 * np.sqrt(0.1 * 0.9 / n)
    assert abs((out.swap == 1).mean() - 0.1) < tol
    assert abs((out.swap >= 2).mean() - 0.1) < tol
    assert abs(out.frame_missed.mean() - 0.05) < 4 * np.sqrt(0.05 * 0.95 / n)
    # a whole-body swap puts the left wrist label on the right wrist
    lw, rw = BODY_25_NAMES.index("LWrist"), BODY_25_NAMES.index("RWrist")
    m = (out.swap == 1) & ~out.missed[..., lw]
    d = np.linalg.norm(out.keypoints[..., lw, :2] - kp[..., rw, :], axis=-1)[m]
    assert np.all(d < 5)
    # per-keypoint misses (frames with a detection) follow miss_probability, larger when smaller
    ok = ~out.frame_missed
    for v in range(2):
        measured = out.missed[:, v][ok[:, v]].mean(0)
        expect = det.miss_probability(size[0, v])
        np.testing.assert_allclose(measured, expect, atol=4 * np.sqrt(expect.max() / ok[:, v].sum()) + 0.01)
    assert out.missed[:, 1].mean() > out.missed[:, 0].mean()
    # missed keypoints are exactly (0, 0, 0), never NaN
    assert np.all(out.keypoints[out.missed] == 0) and np.isfinite(out.keypoints).all()
    assert np.all(out.keypoints[out.frame_missed] == 0)


def test_confidence_falls_with_error():
    det = dataclasses.replace(OPENPOSE, outlier_rate=0.1, swap_rate=0.0, limb_swap_rate=0.0,
                              background_limb_rate=0.0, miss_rate=0.0, frame_miss_rate=0.0)
    kp, size, wh = _scene(F=1000, sizes=(150.0, 300.0))
    out = detect_keypoints(kp, size, wh, det, np.random.default_rng(5))
    err = np.linalg.norm(out.keypoints[..., :2] - kp, axis=-1).ravel()
    conf = out.keypoints[..., 2].ravel()
    assert np.corrcoef(err, conf)[0, 1] < -0.4
    assert conf[out.outlier.ravel()].mean() < 0.5 < conf[~out.outlier.ravel()].mean()
    assert conf.min() >= 0.05 and conf.max() <= 1.0


def test_out_of_frame_behind_camera_and_nan_are_missed():
    kp, size, wh = _scene(F=10, sizes=(200.0,))
    kp = kp.copy()
    kp[:, 0, 0] = [-50.0, 100.0]  # left of the image
    kp[:, 0, 1] = [100.0, 2000.0]  # below
    kp[:, 0, 2] = np.nan
    depth = np.ones(kp.shape[:3])
    depth[:, 0, 3] = -1.0  # behind the camera
    det = dataclasses.replace(OPENPOSE, **CLEAN)
    out = detect_keypoints(kp, size, wh, det, np.random.default_rng(0), depth=depth)
    assert out.missed[:, 0, :4].all() and not out.missed[:, 0, 4:].any()
    assert np.all(out.keypoints[:, 0, :4] == 0) and np.isfinite(out.keypoints).all()
    size_nan = size.copy()
    size_nan[0] = np.nan
    assert np.isfinite(detect_keypoints(kp, size_nan, wh, det, np.random.default_rng(0)).keypoints).all()


def test_determinism_and_independent_detectors():
    gt = {"kp2d_body25": _scene(F=50)[0], "kp2d_coco18": _scene(F=50, J=18)[0],
          "person_size_px": np.full((50, 2), 250.0), "image_size": np.array([[1920, 1080]] * 2)}
    a = simulate_detections(gt, OPENPOSE, seed=7)
    b = simulate_detections(gt, OPENPOSE, seed=7)
    c = simulate_detections(gt, OPENPOSE, seed=8)
    np.testing.assert_array_equal(a.keypoints, b.keypoints)
    assert not np.array_equal(a.keypoints, c.keypoints)
    ap = simulate_detections(gt, ALPHAPOSE, seed=7)
    assert ap.keypoints.shape == (50, 2, 18, 3) and ap.names == COCO18_NAMES
    assert ALPHAPOSE.sigma_rel != OPENPOSE.sigma_rel
    with pytest.raises(ValueError, match="keypoints"):
        detect_keypoints(gt["kp2d_coco18"], gt["person_size_px"], gt["image_size"], OPENPOSE,
                         np.random.default_rng(0))
    with pytest.raises(ValueError):
        DetectorModel("x", "body25", swap_rate=1.5)


def test_detections_on_a_simulated_sequence(open_model_files):
    from airpose_lib.data.sequences import SequenceConfig, simulate_sequence

    sim = simulate_sequence(SequenceConfig(person="person1", n_frames=20, seed=1))
    op = simulate_detections(sim.gt, OPENPOSE, seed=0)
    ok = ~op.missed & (op.swap == 0)[..., None] & ~op.outlier & ~op.background
    err = np.linalg.norm(op.keypoints[..., :2] - sim.gt["kp2d_body25"], axis=-1)
    # typical error of a person ~100-200 px tall in a 960x540 frame: a few pixels
    assert 0.5 < np.median(err[ok]) < 10
    assert (op.keypoints[..., 2] > 0).mean() > 0.8


def test_a_limb_on_a_background_object():
    det = dataclasses.replace(OPENPOSE, **{**CLEAN, "background_limb_rate": 0.2, "sigma_px": 0.0, "sigma_rel": 0.0})
    kp, size, wh = _scene(F=4000, sizes=(150.0, 300.0))
    out = detect_keypoints(kp, size, wh, det, np.random.default_rng(6))
    hit = out.background.any(-1)
    tol = 4 * np.sqrt(0.2 * 0.8 / hit.size)
    assert abs(hit.mean() - 0.2) < tol + 0.01  # a few limbs leave the frame and are missed
    names = np.array(BODY_25_NAMES)
    for f, v in zip(*np.nonzero(hit[:50])):
        moved = names[out.background[f, v]]
        side = {n[0] for n in moved}
        assert len(side) == 1 and all(n[1:] in ("Shoulder", "Elbow", "Wrist", "Hip", "Knee", "Ankle", "BigToe",
                                                "SmallToe", "Heel") for n in moved)
        shift = out.keypoints[f, v, out.background[f, v], :2] - kp[f, v, out.background[f, v]]
        assert np.allclose(shift, shift[0], atol=1e-9)  # moved rigidly
        d = np.linalg.norm(shift[0]) / size[f, v]
        assert 0.45 < d < 1.55
    assert out.keypoints[out.background][:, 2].min() >= 0.6 * det.conf_max - 1e-9  # confidently wrong


def _spread_person(F: int, size: float = 600.0, W: int = 1920, H: int = 1080):
    """BODY_25 / COCO-18 keypoints of one upright person with arms and legs spread, ``size`` px tall."""
    from airpose_lib.finetune import BODY25_FROM_COCO18

    x = {"Nose": (0, -0.45), "Neck": (0, -0.35), "MidHip": (0, 0.05), "REye": (-0.03, -0.47), "LEye": (0.03, -0.47),
         "REar": (-0.06, -0.46), "LEar": (0.06, -0.46), "RShoulder": (-0.12, -0.33), "LShoulder": (0.12, -0.33),
         "RElbow": (-0.35, -0.33), "LElbow": (0.35, -0.33), "RWrist": (-0.55, -0.33), "LWrist": (0.55, -0.33),
         "RHip": (-0.1, 0.05), "LHip": (0.1, 0.05), "RKnee": (-0.2, 0.28), "LKnee": (0.2, 0.28),
         "RAnkle": (-0.3, 0.5), "LAnkle": (0.3, 0.5)}
    for side, sx in (("R", -1), ("L", 1)):
        x.update({f"{side}BigToe": (sx * 0.33, 0.53), f"{side}SmallToe": (sx * 0.36, 0.53),
                  f"{side}Heel": (sx * 0.29, 0.52)})
    b25 = np.array([x[n] for n in BODY_25_NAMES]) * size + [W / 2, H / 2]
    idx = np.asarray(BODY25_FROM_COCO18)
    coco = np.array([b25[list(idx).index(k)] for k in range(18)])
    rep = lambda a: np.broadcast_to(a, (F, 1, *a.shape)).copy()  # noqa: E731
    return rep(b25), rep(coco), np.full((F, 1), size), np.array([[W, H]])


def test_the_agreement_filter_drops_a_swapped_limb_and_a_background_limb():
    from airpose_lib.finetune import agreement_masks

    F = 200
    b25, coco, size, wh = _spread_person(F)
    exact = dict(CLEAN, sigma_px=0.0, sigma_rel=0.0)
    ap = detect_keypoints(coco, size, wh, dataclasses.replace(ALPHAPOSE, **exact, keypoints="coco18"),
                          np.random.default_rng(0))
    op = detect_keypoints(b25, size, wh, dataclasses.replace(OPENPOSE, **{**exact, "limb_swap_rate": 0.5,
                                                                          "background_limb_rate": 0.3}),
                          np.random.default_rng(1))
    m = agreement_masks(op.keypoints, ap.keypoints, threshold_px=100.0)
    names = BODY_25_NAMES
    arm = [names.index(n) for n in ("RElbow", "RWrist", "LElbow", "LWrist")]  # 410-1320 px from their mirror
    legs = [names.index(n) for n in ("RKnee", "RAnkle", "LKnee", "LAnkle")]
    intact = ~op.background[:, 0].any(-1) & ~op.missed[:, 0].any(-1)  # (a limb moved out of the image is missed)
    arms_swapped = (op.swap[:, 0] == 2) & intact
    legs_swapped = (op.swap[:, 0] == 3) & intact
    assert arms_swapped.sum() > 10 and legs_swapped.sum() > 10
    assert m.disagree[arms_swapped][:, :, arm].all() and m.kept[arms_swapped][:, :, legs].all()
    assert m.disagree[legs_swapped][:, :, legs].all() and m.kept[legs_swapped][:, :, arm].all()
    # a limb on the background (shifted >= 300 px) is dropped wherever both detectors see it
    bg = op.background[:, 0] & ~m.unconfirmed[:, 0] & ~m.missing[:, 0]
    assert bg.sum() > 50 and m.disagree[:, 0][bg].all()
    clean = (op.swap[:, 0] == 0) & intact
    assert clean.sum() > 20 and not m.disagree[clean].any()
