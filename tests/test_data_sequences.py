"""Sequences: motion continuity, drone cameras, time stamps, ground-truth consistency, rendering
geometry, and the official real-data layout (write -> read round trip, bad input)."""
from __future__ import annotations

import json
import pickle
import shutil
import warnings

import cv2
import numpy as np
import pytest

from airpose_lib.data.sequences import (
    PAPER_CAMERAS,
    PERSONS,
    SequenceConfig,
    scale_intrinsics,
    simulate_sequence,
)
from airpose_lib.data.sequences.layout import SequenceFormatError, read_camera_calib
from airpose_lib.data.sequences.motions import MotionScript, Segment, evaluate_motion, sample_script
from airpose_lib.data.sequences.reader import load_sequence
from airpose_lib.data.sequences.writer import OfficialLayoutWriter
from airpose_lib.reproduce.configs import kit_configs

N_FRAMES = 75  # 2.5 s at 30 fps


@pytest.fixture(scope="module")
def sim2(open_model_files):
    return simulate_sequence(SequenceConfig(person="person2", n_frames=N_FRAMES, seed=4))


@pytest.fixture(scope="module")
def sim1(open_model_files):
    return simulate_sequence(SequenceConfig(person="person1", n_frames=30, seed=9))


# -- motion ---------------------------------------------------------------------------------------
def test_motion_is_continuous_across_segment_boundaries():
    script = MotionScript((Segment("walk", 1.0, {"speed": 1.2, "turn_rate": 0.3}),
                           Segment("squat", 2.0, {"freq": 0.5, "depth": 1.0}),
                           Segment("twist", 1.5, {"amplitude": 60.0}),
                           Segment("wave", 1.0)))
    for tb in np.cumsum([1.0, 2.0, 1.5]):
        a, b = evaluate_motion(script, [tb - 1e-4, tb + 1e-4]).theta
        assert np.abs(a - b).max() < 1e-2  # no jump at the boundary
    t = np.arange(0, 5.5, 1 / 120)
    st = evaluate_motion(script, t)
    rate = np.abs(np.diff(st.theta, axis=0)).max() * 120  # rad/s of any component
    assert rate < np.deg2rad(900)
    step = np.linalg.norm(np.diff(st.pelvis_xz, axis=0), axis=1).max() * 120
    assert step < 1.5  # m/s: walking speed, never a teleport
    np.testing.assert_allclose(st.weights.sum(1), 1.0, atol=1e-12)


def test_motion_samples_at_any_times_consistently():
    script = sample_script(np.random.default_rng(0), 6.0, "twisting")
    t = np.array([0.5, 1.007, 3.2, 5.9])
    whole = evaluate_motion(script, np.linspace(0, 6, 13).tolist() + t.tolist())
    part = evaluate_motion(script, t)
    np.testing.assert_allclose(whole.theta[-4:], part.theta, atol=1e-12)
    np.testing.assert_allclose(whole.pelvis_xz[-4:], part.pelvis_xz, atol=1e-9)
    with pytest.raises(ValueError):
        evaluate_motion(script, [-1.0])
    with pytest.raises(ValueError, match="unknown activity"):
        Segment("fly", 1.0)


def test_walker_stays_in_area():
    script = MotionScript((Segment("walk", 60.0, {"speed": 1.4, "turn_rate": 0.0}),), area_radius=2.75)
    st = evaluate_motion(script, np.arange(0, 60, 0.1))
    assert np.linalg.norm(st.pelvis_xz, axis=1).max() < 2.75 + 1.0


def test_sequence_ground_truth_is_continuous(sim2):
    gt = sim2.gt
    J = gt["j3d_world"][:, 0]  # (F, 22, 3) view 0
    assert np.linalg.norm(np.diff(J, axis=0), axis=-1).max() < 0.2  # m per frame
    pel = gt["pelvis_world"][:, 0]
    assert np.linalg.norm(np.diff(pel, axis=0), axis=-1).max() < 0.08
    cams = gt["camera_center"]
    assert np.linalg.norm(np.diff(cams, axis=0), axis=-1).max() < 0.1
    # feet on the ground: the lowest joint is a few centimetres above y = 0, never below
    low = gt["j3d_world"][..., 1].min(-1)
    assert low.min() > -0.02 and low.max() < 0.3


# -- cameras and time -----------------------------------------------------------------------------
def test_cameras_look_at_the_person(sim2):
    gt = sim2.gt
    W, H = gt["image_size"][:, 0], gt["image_size"][:, 1]
    uv, z = gt["j2d"], gt["j3d_cam"][..., 2]
    assert (z > 3.0).all()
    inside = (uv[..., 0] >= 0) & (uv[..., 0] < W[None, :, None]) & (uv[..., 1] >= 0) & (uv[..., 1] < H[None, :, None])
    assert inside.all()
    # circling drone: the person stays near the image centre
    c = np.array([W[1], H[1]]) / 2
    assert np.abs(gt["j2d"][:, 1, 0] - c).max() < 0.3 * W[1]
    # pitch of the line of sight and distance to the person (FlightConfig: 15-45 deg, 8-12 m;
    # the hovering drone does not follow the person, who roams +-2.75 m)
    d = gt["pelvis_world"] - gt["camera_center"]
    horiz = np.hypot(d[..., 0], d[..., 2])
    pitch = np.rad2deg(np.arctan2(-d[..., 1], horiz))
    assert (pitch > 10).all() and (pitch < 50).all()
    dist = np.linalg.norm(d, axis=-1)
    assert (dist[:, 1] > 7.5).all() and (dist[:, 1] < 12.5).all()
    assert (dist[:, 0] > 5.0).all() and (dist[:, 0] < 15.5).all()


def test_hovering_and_circling(sim2):
    cams = sim2.gt["camera_center"]
    hover = np.linalg.norm(cams[:, 0] - cams[0, 0], axis=-1).max()
    orbit = np.linalg.norm(cams[:, 1] - cams[0, 1], axis=-1).max()
    assert hover < 0.3 and orbit > 0.5


def test_timestamps_and_per_view_times(sim2):
    ts = sim2.gt["timestamps"]
    np.testing.assert_allclose(ts[:, 1] - ts[:, 0], 0.007, atol=1e-12)
    np.testing.assert_allclose(np.diff(ts[:, 0]), 1 / 30, atol=1e-12)
    # each view sees the body at its own time: the poses differ, a little
    dv = np.abs(sim2.gt["theta_view"][:, 0] - sim2.gt["theta_view"][:, 1]).max()
    assert 0 < dv < np.deg2rad(10)
    np.testing.assert_array_equal(sim2.gt["theta"], sim2.gt["theta_view"][:, 0])


def test_intrinsics_default_to_the_papers_cameras(sim2):
    K = sim2.gt["K_full"]
    np.testing.assert_allclose(K[0], [[1537.83, 0, 1018.55], [0, 1517.66, 577.52], [0, 0, 1]])
    np.testing.assert_allclose(K[1], [[1361.11, 0, 978.02], [0, 1378.80, 667.23], [0, 0, 1]])
    np.testing.assert_array_equal(sim2.gt["image_size"], [[960, 540], [960, 540]])
    np.testing.assert_allclose(sim2.gt["K"], scale_intrinsics(K, 0.5))


def test_scale_intrinsics_matches_cv2_resize():
    """A blob at (u, v) in a full frame lands at K-scaled coordinates after cv2.resize."""
    W, H, s = 400, 240, 0.5
    u, v = 137.3, 88.6
    yy, xx = np.mgrid[0:H, 0:W]
    img = np.exp(-((xx - u) ** 2 + (yy - v) ** 2) / (2 * 3.0 ** 2))
    small = cv2.resize(img, (int(W * s), int(H * s)), interpolation=cv2.INTER_AREA)
    ys, xs = np.mgrid[0:small.shape[0], 0:small.shape[1]]
    cu, cv_ = (small * xs).sum() / small.sum(), (small * ys).sum() / small.sum()
    K = np.array([[500.0, 0, u], [0, 480.0, v], [0, 0, 1]])  # principal point at the blob
    Ks = scale_intrinsics(K, s)
    assert abs(Ks[0, 2] - cu) < 0.02 and abs(Ks[1, 2] - cv_) < 0.02
    assert Ks[0, 0] == 250.0 and Ks[1, 1] == 240.0


# -- ground truth consistency --------------------------------------------------------------------
def test_ground_truth_is_consistent(sim2):
    gt = sim2.gt
    F, V = gt["phi"].shape[:2]
    # phi/tau: the camera-frame root pose equals extrinsics composed with the world pose
    np.testing.assert_allclose(gt["phi"], gt["R_cw"] @ gt["R_wb"], atol=1e-12)
    np.testing.assert_allclose(gt["tau"], np.einsum("fvij,fvj->fvi", gt["R_cw"], gt["t_wb"]) + gt["t_cw"], atol=1e-12)
    # extrinsics are rotations, cameras at their centres
    RtR = np.einsum("fvji,fvjk->fvik", gt["R_cw"], gt["R_cw"])
    np.testing.assert_allclose(RtR, np.broadcast_to(np.eye(3), RtR.shape), atol=1e-12)
    c = -np.einsum("fvji,fvj->fvi", gt["R_cw"], gt["t_cw"])
    np.testing.assert_allclose(c, gt["camera_center"], atol=1e-9)
    # 2D joints = OpenCV projection of the camera-frame joints
    for f, v in ((0, 0), (F - 1, 1)):
        uv, _ = cv2.projectPoints(gt["j3d_cam"][f, v], np.zeros(3), np.zeros(3), gt["K"][v], None)
        np.testing.assert_allclose(uv[:, 0], gt["j2d"][f, v], atol=1e-6)
    # the camera frames agree on the body: j3d_cam of view 1 mapped back to the world
    w = np.einsum("fvji,fvkj->fvki", gt["R_cw"], gt["j3d_cam"] - gt["t_cw"][:, :, None])
    np.testing.assert_allclose(w, gt["j3d_world"], atol=1e-9)


def test_root_convention_matches_the_body_model(sim2, open_model_files):
    """V = R_wb V0 + t_wb about the model origin: the pelvis joint of the posed female model."""
    import torch

    from airpose_lib.body import load_body_model

    gt = sim2.gt
    model = load_body_model("open", "female", dtype=torch.float64)
    f, v = 17, 1
    R = torch.as_tensor(gt["R_wb"][f, v])
    out = model(betas=torch.as_tensor(gt["betas"])[None], body_pose=torch.as_tensor(gt["theta_view"][f, v]).reshape(1, 63))
    J0 = out.joints[0, :22].detach().double().numpy()
    J = J0 @ R.numpy().T + gt["t_wb"][f, v]
    np.testing.assert_allclose(J, gt["j3d_world"][f, v], atol=1e-6)


def test_two_persons_differ(sim1, sim2):
    assert int(sim1.gt["gender"]) == 1 and int(sim2.gt["gender"]) == 2
    assert not np.allclose(sim1.gt["betas"], sim2.gt["betas"])
    assert PERSONS["person1"].style != PERSONS["person2"].style


def test_simulation_is_deterministic(sim1, open_model_files):
    again = simulate_sequence(SequenceConfig(person="person1", n_frames=30, seed=9))
    for k in sim1.gt:
        np.testing.assert_array_equal(sim1.gt[k], again.gt[k])
    other = simulate_sequence(SequenceConfig(person="person1", n_frames=30, seed=10))
    assert not np.allclose(other.gt["j3d_world"], sim1.gt["j3d_world"])


def test_config_round_trip_and_profiles():
    cfg = SequenceConfig(person="person2", n_frames=10, render_scale=0.25, seed=3)
    back = SequenceConfig.from_dict(json.loads(json.dumps(cfg.to_dict())))
    assert back == SequenceConfig.from_dict(cfg.to_dict())
    assert back.person_spec == PERSONS["person2"] and back.cameras == PAPER_CAMERAS
    for prof in ("smoke", "cpu", "paper"):
        recs = kit_configs(prof).sequences
        assert set(recs) == {"person1", "person2"}
        assert recs["person1"].person_spec.gender != recs["person2"].person_spec.gender
    assert 60 <= kit_configs("smoke").sequences["person1"].n_frames <= 120
    with pytest.raises(ValueError):
        SequenceConfig(time_offsets=(0.0,))
    with pytest.raises(ValueError, match="unknown sequence setting"):
        SequenceConfig.from_dict({"frames": 3})
    with pytest.raises(ValueError, match="unknown person"):
        _ = SequenceConfig(person="person3").person_spec


# -- rendering ------------------------------------------------------------------------------------
def test_rendered_body_lands_where_K_projects_it(sim2):
    """Non-square pixels and an off-centre principal point (the DJI calibrations) render exactly."""
    from airpose_lib.body.forward import rest_body
    from airpose_lib.data.sequences import SequenceRenderer

    gt = sim2.gt
    f = 40
    with SequenceRenderer(sim2, anti_aliasing=False) as r:
        v0, _ = rest_body(r.model, gt["betas"][None].repeat(2, 0), gt["theta_view"][f])
        for v in range(2):
            Vw = v0[v] @ gt["R_wb"][f, v].T + gt["t_wb"][f, v]
            rr = r._renderers[tuple(int(x) for x in gt["image_size"][v])]
            rr.set_body(Vw, r.faces, r.colors)
            sil = rr.render(gt["K"][v], gt["R_cw"][f, v], gt["t_cw"][f, v], body_only=True).max(-1) > 0
            ys, xs = np.nonzero(sil)
            uv, _ = cv2.projectPoints(Vw, cv2.Rodrigues(gt["R_cw"][f, v])[0], gt["t_cw"][f, v], gt["K"][v], None)
            uv = uv[:, 0]
            assert abs(xs.min() - uv[:, 0].min()) < 1.5 and abs(xs.max() - uv[:, 0].max()) < 1.5
            assert abs(ys.min() - uv[:, 1].min()) < 1.5 and abs(ys.max() - uv[:, 1].max()) < 1.5
        _, images = next(r.render_frames([f]))
    assert images[0].shape == (540, 960, 3) and images[0].std() > 5


def test_generate_and_load_end_to_end(tmp_path, open_model_files):
    from airpose_lib.data.sequences import ensure_sequences

    cfg = SequenceConfig(person="person1", n_frames=3, render_scale=0.25, seed=2, anti_aliasing=False)
    paths = ensure_sequences(configs={"p1": cfg}, root=tmp_path)
    seq = load_sequence(paths["p1"])
    assert seq.num_frames == 3 and seq.num_views == 2
    assert seq.images[0][0].shape == (270, 480, 3)
    np.testing.assert_allclose(seq.K, seq.ground_truth["K"])
    np.testing.assert_allclose(seq.timestamps, seq.ground_truth["timestamps"], atol=1e-9)
    assert seq.keypoints["openpose"].shape == (3, 2, 25, 3)
    assert seq.meta["config"]["person"]["name"] == "person1"
    mtime = (paths["p1"] / "sequence.json").stat().st_mtime_ns
    ensure_sequences(configs={"p1": cfg}, root=tmp_path)  # complete and identical: kept
    assert (paths["p1"] / "sequence.json").stat().st_mtime_ns == mtime
    # a new detector model: the detector files are re-simulated from the stored ground truth, the
    # images stay (no re-rendering), and the detections equal a fresh simulation's
    import json

    from airpose_lib.data.sequences import recording_detections, simulate_sequence
    from airpose_lib.data.sequences.detections import DETECTOR_VERSION

    meta_path = paths["p1"] / "sequence.json"
    meta = json.loads(meta_path.read_text())
    assert meta["detector_version"] == DETECTOR_VERSION and meta["detections"]["openpose"]["views"] == 6
    meta["detector_version"] = -1
    meta_path.write_text(json.dumps(meta))
    op_file = paths["p1"] / "machine_1" / "openpose_res.pkl"
    op_file.write_bytes(b"stale")
    image = sorted((paths["p1"] / "machine_1" / "images").glob("*.jpg"))[0]
    image_mtime = image.stat().st_mtime_ns
    ensure_sequences(configs={"p1": cfg}, root=tmp_path)
    assert image.stat().st_mtime_ns == image_mtime
    assert json.loads(meta_path.read_text())["detector_version"] == DETECTOR_VERSION
    fresh = recording_detections(simulate_sequence(cfg).gt, cfg)
    again = load_sequence(paths["p1"])
    np.testing.assert_allclose(again.keypoints["openpose"], fresh["openpose"].keypoints, atol=1e-4)
    np.testing.assert_allclose(again.keypoints["alphapose"], seq.keypoints["alphapose"], atol=1e-4)


# -- official layout --------------------------------------------------------------------------------
def _write_fake(root, F=6, V=2, seed=0, gt=True):
    rng = np.random.default_rng(seed)
    w = OfficialLayoutWriter(root, V, jpeg_quality=95)
    # smooth random images (JPEG keeps them close): a colour gradient per frame and view
    yy, xx = np.mgrid[0:24, 0:32] / 32.0
    coef = rng.uniform(0, 1, (F, V, 3, 3))
    images = (255 * np.clip(coef[..., 0, None, None] * xx + coef[..., 1, None, None] * yy
                            + 0.3 * coef[..., 2, None, None], 0, 1)).astype(np.uint8)
    images = np.moveaxis(images, 2, -1)  # (F, V, 24, 32, 3)
    for i in range(F):
        w.write_frame(i + 100, list(images[i]))
    K = np.stack([np.array([[40.0 + v, 0, 15.5], [0, 41.0, 11.5], [0, 0, 1]]) for v in range(V)])
    op = np.concatenate([rng.uniform(0, 30, (F, V, 25, 2)), rng.uniform(0.1, 1, (F, V, 25, 1))], -1)
    ap = np.concatenate([rng.uniform(0, 30, (F, V, 18, 2)), rng.uniform(0.1, 1, (F, V, 18, 1))], -1)
    op[2, 1] = 0.0  # nobody detected in frame 102 of view 2
    op[3, 0, 4] = 0.0  # one missed keypoint
    ap[1, 0] = 0.0
    ts = (np.arange(F)[:, None] / 30 + np.array([0.0, 0.007])[None, :V])
    truth = {"frame_index": np.arange(100, 100 + F), "K": K, "betas": np.arange(10.0),
             "j2d": rng.normal(size=(F, V, 22, 2))} if gt else None
    w.finish(K, {"openpose": op, "alphapose": ap}, ts, truth, meta={"note": "test"})
    return images, K, op, ap, ts


def test_official_layout_round_trip(tmp_path):
    images, K, op, ap, ts = _write_fake(tmp_path)
    for v in (1, 2):
        assert (tmp_path / f"machine_{v}" / "images" / "000100.jpg").is_file()
    seq = load_sequence(tmp_path)
    assert seq.num_frames == 6 and list(seq.frames) == list(range(100, 106))
    np.testing.assert_allclose(seq.K, K)
    fs = cv2.FileStorage(str(tmp_path / "machine_2" / "camera_calib.yml"), cv2.FILE_STORAGE_READ)
    np.testing.assert_allclose(fs.getNode("K").mat(), K[1])
    fs.release()
    np.testing.assert_allclose(seq.keypoints["openpose"], op.astype(np.float32), atol=1e-5)
    np.testing.assert_allclose(seq.keypoints["alphapose"], ap, atol=1e-3)
    np.testing.assert_allclose(seq.timestamps, ts, atol=1e-9)
    assert np.abs(seq.images[1][3].astype(float) - images[3, 1]).mean() < 4  # JPEG
    assert seq.ground_truth["j2d"].shape == (6, 2, 22, 2)
    np.testing.assert_array_equal(seq.ground_truth["betas"], np.arange(10.0))
    # the official files look like the tools' outputs
    with open(tmp_path / "machine_2" / "openpose_res.pkl", "rb") as fh:
        res = pickle.load(fh)
    assert res[102].shape == (0, 25, 3) and res[100].shape == (1, 25, 3)
    entries = json.loads((tmp_path / "machine_1" / "alphapose_res.json").read_text())
    assert {e["image_id"] for e in entries} == {f"{i:06d}.jpg" for i in (100, 102, 103, 104, 105)}
    assert all(len(e["keypoints"]) == 54 and e["category_id"] == 1 for e in entries)
    # selections
    sub = load_sequence(tmp_path, frames=[103, 101])
    np.testing.assert_allclose(sub.keypoints["openpose"][0], op[3].astype(np.float32), atol=1e-5)
    np.testing.assert_allclose(sub.ground_truth["j2d"], seq.ground_truth["j2d"][[3, 1]])
    assert load_sequence(tmp_path, frames=slice(0, 2)).num_frames == 2
    with pytest.raises(SequenceFormatError, match="requested frames"):
        load_sequence(tmp_path, frames=[7])


def test_official_layout_bad_input(tmp_path):
    _write_fake(tmp_path / "a")
    # missing calibration -> the file is named
    (tmp_path / "a" / "machine_2" / "camera_calib.yml").unlink()
    with pytest.raises(SequenceFormatError, match=r"machine_2.camera_calib\.yml"):
        load_sequence(tmp_path / "a")
    with pytest.raises(SequenceFormatError, match="missing camera calibration"):
        read_camera_calib(tmp_path / "nothing.yml")

    # an OpenPose file shorter than the image sequence
    _write_fake(tmp_path / "b")
    path = tmp_path / "b" / "machine_1" / "openpose_res.pkl"
    res = pickle.loads(path.read_bytes())
    path.write_bytes(pickle.dumps({k: v for k, v in res.items() if k < 103}))
    with pytest.raises(SequenceFormatError, match=r"machine_1.openpose_res\.pkl.*shorter"):
        load_sequence(tmp_path / "b")
    seq = load_sequence(tmp_path / "b", missing_detections="zero")
    assert seq.info["openpose"]["missing_frames"] == 3
    assert np.all(seq.keypoints["openpose"][3:, 0] == 0)

    # an AlphaPose file that stops early
    _write_fake(tmp_path / "c")
    path = tmp_path / "c" / "machine_2" / "alphapose_res.json"
    entries = json.loads(path.read_text())
    path.write_text(json.dumps([e for e in entries if e["image_id"] < "000102.jpg"]))
    with pytest.raises(SequenceFormatError, match=r"machine_2.alphapose_res\.json.*shorter"):
        load_sequence(tmp_path / "c", tail_tolerance=1)
    assert load_sequence(tmp_path / "c", tail_tolerance=10).keypoints["alphapose"].shape == (6, 2, 18, 3)

    # mismatched frame counts between the machines
    _write_fake(tmp_path / "d")
    (tmp_path / "d" / "machine_2" / "images" / "000105.jpg").unlink()
    with pytest.raises(SequenceFormatError, match=r"machine_1.images has 6 frames and .*machine_2.images has 5"):
        load_sequence(tmp_path / "d")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        seq = load_sequence(tmp_path / "d", strict=False)
    assert seq.num_frames == 5 and caught

    # NaN keypoints are zero-filled and counted
    _write_fake(tmp_path / "e")
    path = tmp_path / "e" / "machine_1" / "openpose_res.pkl"
    res = pickle.loads(path.read_bytes())
    res[101][0, 3, :] = np.nan
    path.write_bytes(pickle.dumps(res))
    seq = load_sequence(tmp_path / "e")
    assert np.isfinite(seq.keypoints["openpose"]).all()
    assert np.all(seq.keypoints["openpose"][1, 0, 3] == 0) and seq.info["openpose"]["nan_keypoints"] == 1

    # frame keys as image names (another common way of storing OpenPose results)
    path.write_bytes(pickle.dumps({f"{k:06d}.jpg": v for k, v in res.items()}))
    assert load_sequence(tmp_path / "e").keypoints["openpose"].shape == (6, 2, 25, 3)
    path.write_bytes(pickle.dumps({"frame_a": res[101]}))
    with pytest.raises(SequenceFormatError, match=r"openpose_res\.pkl: frame key"):
        load_sequence(tmp_path / "e")

    # empty sequence, missing folders, missing detector file
    (tmp_path / "f" / "machine_1" / "images").mkdir(parents=True)
    with pytest.raises(SequenceFormatError, match=r"empty sequence.*machine_1.images"):
        load_sequence(tmp_path / "f")
    with pytest.raises(SequenceFormatError, match="no machine_1"):
        load_sequence(tmp_path / "a" / "machine_1")
    with pytest.raises(SequenceFormatError, match="does not exist"):
        load_sequence(tmp_path / "missing")
    _write_fake(tmp_path / "g", gt=False)
    (tmp_path / "g" / "machine_1" / "alphapose_res.json").unlink()
    with pytest.raises(SequenceFormatError, match=r"missing detector file .*alphapose_res\.json"):
        load_sequence(tmp_path / "g")
    seq = load_sequence(tmp_path / "g", detectors=("openpose",))
    assert seq.ground_truth is None and set(seq.keypoints) == {"openpose"}
    shutil.rmtree(tmp_path / "g" / "machine_2" / "images")
    with pytest.raises(SequenceFormatError, match=r"missing image folder .*machine_2.images"):
        load_sequence(tmp_path / "g")
