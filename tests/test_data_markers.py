"""ArUco markers on the ground as the drones' ground truth (``data.sequences.markers``): synthetic views by
homography, detection with ``cv2.aruco``, camera poses against the known ones."""
from __future__ import annotations

import dataclasses
import json

import cv2
import numpy as np
import pytest
import torch

from airpose_lib.data.sequences import PAPER_CAMERAS, look_at_rotation, scale_intrinsics
from airpose_lib.data.sequences.field import FieldConfig, field_frame, field_rng
from airpose_lib.data.sequences.markers import (
    R_WORLD_MARKER,
    MarkerLayout,
    camera_pose_from_markers,
    detect_markers,
    ground_board,
    ground_homography,
    marker_corners_world,
    marker_image,
    marker_pose,
    marker_relative_cameras,
    recording_lens_distortion,
    relative_camera_from_markers,
    sequence_marker_poses,
)
from airpose_lib.geometry import geodesic_angle

LAYOUT = MarkerLayout()
EXTENT = (-3.0, -3.0, 3.0, 3.0)
PPM = 300  # board pixels per metre: a 0.6 m marker is 180 px


@pytest.fixture(scope="module")
def board() -> np.ndarray:
    return ground_board(LAYOUT, PPM, EXTENT)


def _camera(cam: int, eye, target=(0.0, 1.0, 0.0)):
    """K (3, 3), (W, H), R_cw, t_cw of a paper camera at half size looking from ``eye``."""
    K, size = PAPER_CAMERAS[cam].scaled(0.5)
    R, t = look_at_rotation(np.array([eye], float), np.array([target], float))
    return K, size, R[0], t[0]


def _view(board: np.ndarray, K, size, R, t, ss: int = 2) -> np.ndarray:
    """The board seen by the camera: warped at ``ss`` times the size, then area-averaged down
    (anti-aliased, as a lens and a sensor pixel integrate)."""
    H = ground_homography(scale_intrinsics(K, ss), R, t, PPM, EXTENT[:2])
    big = cv2.warpPerspective(board, H, (size[0] * ss, size[1] * ss), flags=cv2.INTER_LINEAR, borderValue=110)
    return cv2.resize(big, size, interpolation=cv2.INTER_AREA)


def _deg(Ra, Rb) -> float:
    return float(np.degrees(geodesic_angle(torch.as_tensor(Ra), torch.as_tensor(Rb)).item()))


# Hovering-like and orbit-like views from 8-12 m, 20-40 degrees down (the recordings' range).
VIEWS = [(0, (0.5, 6.0, -8.0)), (1, (7.0, 4.0, 4.0)), (1, (-9.0, 7.0, 1.0)), (0, (2.0, 3.0, -10.0))]


def test_marker_corners_lie_on_the_ground_in_arucos_order():
    c = marker_corners_world(MarkerLayout(ids=(7,), centres_xz=((2.0, -1.0),), side_m=0.5))
    np.testing.assert_allclose(c[0], [[1.75, 0, -1.25], [2.25, 0, -1.25], [2.25, 0, -0.75], [1.75, 0, -0.75]])
    x_m, y_m = c[0, 1] - c[0, 0], c[0, 0] - c[0, 3]  # TL -> TR is the marker's x, BL -> TL its y
    np.testing.assert_allclose(np.cross(x_m, y_m) / 0.25, [0, 1, 0])  # its z is world up
    np.testing.assert_allclose(R_WORLD_MARKER @ R_WORLD_MARKER.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(R_WORLD_MARKER) == pytest.approx(1.0)


def test_marker_image_decodes_to_its_id():
    img = marker_image(LAYOUT, 3, 120)
    assert img.shape == (120, 120) and set(np.unique(img)) <= {0, 255}
    assert img[:10].max() == 0 and img[:, :10].max() == 0  # the black border bit
    page = np.pad(img, 40, constant_values=255)
    det = detect_markers(page, LAYOUT)
    assert list(det) == [3]
    np.testing.assert_allclose(det[3], [[39.5, 39.5], [159.5, 39.5], [159.5, 159.5], [39.5, 159.5]], atol=0.6)
    assert detect_markers(np.full((100, 100), 128, np.uint8), LAYOUT) == {}
    assert camera_pose_from_markers({}, LAYOUT, np.eye(3)) is None


def test_ground_homography_projects_like_the_camera():
    K, size, R, t = _camera(1, (7.0, 4.0, 4.0))
    H = ground_homography(K, R, t, PPM, EXTENT[:2])
    cols_rows = np.array([[0.0, 0.0], [1799.0, 0.0], [900.0, 1234.0]])
    xz = EXTENT[:2] + (cols_rows + 0.5) / PPM
    world = np.column_stack([xz[:, 0], np.zeros(3), xz[:, 1]])
    expected = cv2.projectPoints(world, cv2.Rodrigues(R)[0], t, K, None)[0].reshape(-1, 2)
    got = cv2.perspectiveTransform(cols_rows[None], H)[0]
    np.testing.assert_allclose(got, expected, atol=1e-6)


def test_camera_poses_from_the_markers_match_the_known_ones(board):
    poses = []
    for cam, eye in VIEWS:
        K, size, R, t = _camera(cam, eye)
        det = detect_markers(_view(board, K, size, R, t), LAYOUT)
        assert sorted(det) == list(LAYOUT.ids)
        R_p, t_p, rms = camera_pose_from_markers(det, LAYOUT, K)
        # measured: <= 0.13 deg, <= 2.2 cm camera centre, rms <= 0.8 px
        assert _deg(R_p, R) < 0.3
        assert np.linalg.norm(-R_p.T @ t_p + R.T @ t) < 0.05
        assert rms < 1.0
        poses.append((R, t, R_p, t_p))
    # UAV 2 in UAV 1 from the markers against the truth (target: 0.10 m and 1 degree)
    (R1, t1, P1, p1), (R2, t2, P2, p2) = poses[:2]
    R_true, t_true = relative_camera_from_markers(R1, t1, R2, t2)
    R_mark, t_mark = relative_camera_from_markers(P1, p1, P2, p2)
    assert _deg(R_mark, R_true) < 0.2 and np.linalg.norm(t_mark - t_true) < 0.03
    # a partial view: two markers are still enough
    K, size, R, t = _camera(*VIEWS[0])
    det = detect_markers(_view(board, K, size, R, t), LAYOUT)
    R_p, t_p, _ = camera_pose_from_markers({i: det[i] for i in (0, 1)}, LAYOUT, K)
    assert _deg(R_p, R) < 0.5 and np.linalg.norm(-R_p.T @ t_p + R.T @ t) < 0.10


def test_single_marker_pose_from_close_by(board):
    """IPPE_SQUARE on one marker (what the official scripts stored), from 3-4 m."""
    K, size, R, t = _camera(0, (-1.0, 3.5, -4.0), target=(-1.5, 0.0, -1.5))
    det = detect_markers(_view(board, K, size, R, t), LAYOUT)
    R_m, t_m = marker_pose(det[0], LAYOUT.side_m, K)
    centre = np.array([-1.5, 0.0, -1.5])
    np.testing.assert_allclose(R_m, R @ R_WORLD_MARKER, atol=0.02)  # marker -> camera
    assert _deg(R_m, R @ R_WORLD_MARKER) < 1.0
    assert np.linalg.norm(t_m - (R @ centre + t)) < 0.03


def test_relative_camera_from_markers_hand_values():
    # UAV 1 at the world origin looking along +z; UAV 2 at (2, 0, 5), turned 90 deg about y.
    R1, t1 = np.eye(3), np.zeros(3)
    Ry = np.array([[0.0, 0, 1], [0, 1, 0], [-1, 0, 0]])  # camera 2's axes in the world (columns)
    c2 = np.array([2.0, 0.0, 5.0])
    R2, t2 = Ry.T, -Ry.T @ c2
    R12, t12 = relative_camera_from_markers(R1, t1, R2, t2)
    np.testing.assert_allclose(R12, Ry, atol=1e-12)  # camera 2's axes in camera 1
    np.testing.assert_allclose(t12, c2, atol=1e-12)  # UAV 2's position in camera 1
    Rb, tb = relative_camera_from_markers(np.stack([R1, R1]), np.stack([t1, t1]), np.stack([R2, R1]),
                                          np.stack([t2, t1]))
    assert Rb.shape == (2, 3, 3) and tb.shape == (2, 3)
    np.testing.assert_allclose(Rb[0], Ry, atol=1e-12)
    np.testing.assert_allclose(Rb[1], np.eye(3))
    np.testing.assert_allclose(tb[1], 0)


def test_markers_survive_the_field_camera(board):
    """Noise, blur, a colour cast and heavy compression: still detected, the pose still close."""
    K, size, R, t = _camera(*VIEWS[1])
    rgb = np.repeat(_view(board, K, size, R, t)[..., None], 3, -1)
    cfg = FieldConfig(enabled=True, exposure_ev=-0.5, white_balance=(1.1, 1.0, 0.9), shot_noise=2e-3,
                      read_noise=4e-3, shutter=0.5, jpeg_quality=40)
    field = field_frame(rgb, cfg, field_rng(0, 0, 0), K=K, velocity_px=(3.0, 1.0))
    det = detect_markers(field, LAYOUT)
    assert sorted(det) == list(LAYOUT.ids)
    R_p, t_p, _ = camera_pose_from_markers(det, LAYOUT, K)
    assert _deg(R_p, R) < 0.5 and np.linalg.norm(-R_p.T @ t_p + R.T @ t) < 0.10


def test_marker_poses_undo_the_recordings_lens_distortion(board):
    """A field recording's barrel distortion (its ``field: distortion``) is read from its settings
    and undone by the pose; ignoring it moves the camera."""
    from airpose_lib.data.sequences.reader import Sequence

    K, size, R, t = _camera(*VIEWS[2])
    rgb = np.repeat(_view(board, K, size, R, t)[..., None], 3, -1)
    k = (-0.1, 0.05)  # the `dji` preset's
    img = field_frame(rgb, FieldConfig(enabled=True, distortion=k), field_rng(0, 0, 0), K=K)
    meta = {"config": {"field": {"enabled": True, "distortion": list(k)}}}
    seq = Sequence(root=None, frames=np.array([0]), images=[[img], [img]], K=np.stack([K, K]), keypoints={},
                   meta=meta)
    np.testing.assert_array_equal(recording_lens_distortion(seq), [-0.1, 0.05, 0.0, 0.0])
    for off in ({"enabled": False, "distortion": list(k)}, {"enabled": True, "distortion": [0.0, 0.0]}, None):
        assert recording_lens_distortion(Sequence(None, np.array([0]), [], K[None], {},
                                                  meta={"config": {"field": off}})) is None

    def centre_error(poses):
        R_p, t_p = poses.R_cm[0, 0], poses.t_cm[0, 0]
        return np.linalg.norm(-R_p.T @ t_p + R.T @ t), _deg(R_p, R)

    undone = centre_error(sequence_marker_poses(seq, LAYOUT)[0])  # the recording's own distortion
    ignored = centre_error(sequence_marker_poses(seq, LAYOUT, dist=np.zeros(4))[0])
    # measured: camera centre 1.7 cm off with the distortion undone, 5.9 cm ignoring it
    assert undone[0] < 0.10 and undone[1] < 0.5
    assert ignored[0] > 2 * undone[0]


# -- markers in the recordings --------------------------------------------------------------------
def test_marker_option_in_the_recordings_settings():
    from airpose_lib.data.sequences import SequenceConfig, sequence_configs_from_profile
    from airpose_lib.errors import ProfileSettingError

    assert "markers" not in SequenceConfig().to_dict()  # off: the settings (cache key) as before
    recs = sequence_configs_from_profile({"markers": {}, "recordings": {"person1": {}}})
    assert recs["person1"].markers == MarkerLayout()
    custom = sequence_configs_from_profile({"recordings": {"person2": {"markers": {
        "ids": [5, 9], "centres_xz": [[0, 2], [2.5, -1]], "side_m": 0.5}}}})["person2"]
    assert custom.markers.centres_xz == ((0.0, 2.0), (2.5, -1.0)) and custom.markers.ids == (5, 9)
    back = SequenceConfig.from_dict(json.loads(json.dumps(custom.to_dict())))
    assert back.markers == custom.markers
    for bad, match in (({"side": 0.5}, "did you mean 'side_m'"), ({"dictionary": "DICT_9X9"}, "dictionary"),
                       ({"ids": [0, 60], "centres_xz": [[0, 0], [1, 1]]}, "ids must be in")):
        with pytest.raises(ProfileSettingError, match=match):
            sequence_configs_from_profile({"markers": bad, "recordings": {"person1": {}}})


def test_rendered_recording_markers_give_the_cameras(tmp_path, open_model_files):
    """Markers pasted into a recording's ground, written and read back in the official layout:
    detected in both drones' frames, each camera's pose and UAV 2 in UAV 1 recovered against the
    generated truth."""
    from airpose_lib.data.sequences import SequenceConfig, SequenceRenderer, generate_sequence, simulate_sequence
    from airpose_lib.data.sequences.reader import load_sequence
    from airpose_lib.errors import ConfigError

    cfg = SequenceConfig(person="person2", n_frames=2, seed=5, markers=LAYOUT, anti_aliasing=False)
    generate_sequence(cfg, tmp_path / "rec")
    seq = load_sequence(tmp_path / "rec")
    gt = seq.ground_truth
    poses, count, rms = sequence_marker_poses(seq)  # the layout from the recording's settings
    # measured on these two frames: 3 of the 4 markers each, <= 0.25 deg, <= 4.6 cm,
    # rms <= 0.47 px
    assert (count >= 3).all() and poses.valid.all() and (rms < 1.0).all()
    for i in range(2):
        for v in range(2):
            R, t = poses.R_cm[i, v], poses.t_cm[i, v]
            assert _deg(R, gt["R_cw"][i, v]) < 0.5
            assert np.linalg.norm(-R.T @ t - gt["camera_center"][i, v]) < 0.10
    R12, t12, valid = marker_relative_cameras(poses)
    R_true, t_true = relative_camera_from_markers(gt["R_cw"][:, 0], gt["t_cw"][:, 0], gt["R_cw"][:, 1],
                                                  gt["t_cw"][:, 1])
    assert valid.all()
    assert max(_deg(R12[i], R_true[i]) for i in range(2)) < 1.0  # the markers' target: 1 degree
    assert np.linalg.norm(t12 - t_true, axis=-1).max() < 0.10
    # the same recording without the option: no marker to find, and no layout to read
    plain = simulate_sequence(dataclasses.replace(cfg, markers=None, n_frames=1))
    with SequenceRenderer(plain) as r:
        _, images = next(r.render_frames())
    assert detect_markers(images[0], LAYOUT) == {} and detect_markers(images[1], LAYOUT) == {}
    seq.meta["config"].pop("markers")
    with pytest.raises(ConfigError, match="no markers"):
        sequence_marker_poses(seq)


def test_sequence_marker_poses_over_a_recording(board):
    """Frames of a recording in the official layout's shape (synthetic board views)."""
    from airpose_lib.data.sequences.reader import Sequence

    cams = [_camera(*VIEWS[0]), _camera(*VIEWS[1])]
    Ks = np.stack([c[0] for c in cams])
    images = [[np.repeat(_view(board, K, size, R, t)[..., None], 3, -1),
               np.full((size[1], size[0], 3), 110, np.uint8)] for K, size, R, t in cams]  # frame 1: no markers
    seq = Sequence(root=None, frames=np.array([10, 11]), images=images, K=Ks, keypoints={})
    poses, count, rms = sequence_marker_poses(seq, LAYOUT)
    assert poses.frames.tolist() == [10, 11]
    assert count.tolist() == [[4, 4], [0, 0]] and poses.valid.tolist() == [[True, True], [False, False]]
    assert np.isnan(rms[1]).all() and (rms[0] < 1.0).all()
    for v, cam in enumerate(cams):
        assert _deg(poses.R_cm[0, v], cam[2]) < 0.3
    R12, t12, valid = marker_relative_cameras(poses)
    assert valid.tolist() == [True, False]
    R_true, t_true = relative_camera_from_markers(cams[0][2], cams[0][3], cams[1][2], cams[1][3])
    assert _deg(R12[0], R_true) < 0.2 and np.linalg.norm(t12[0] - t_true) < 0.03
    # min_markers: a view with fewer markers is left out
    assert not sequence_marker_poses(seq, LAYOUT, min_markers=5)[0].valid.any()


def test_relative_cameras_from_the_official_marker_file(tmp_path):
    """The release's ``markerposes_corrected_all.pkl`` (a fixture in its layout): UAV 2 in UAV 1
    from marker 0's pose in both drones, against the poses written."""
    from official_fixtures import write_official_real_fixture

    from airpose_lib.data.official.real import load_marker_poses

    truth = write_official_real_fixture(tmp_path, frames=[8000, 8001, 8002], missing={"marker": [(1, 8001)]})
    R12, t12, valid = marker_relative_cameras(load_marker_poses(tmp_path, [8000, 8001, 8002]))
    assert valid.tolist() == [True, False, True]
    for n in (0, 2):
        R1, R2 = (cv2.Rodrigues(truth["rvec"][n, v])[0] for v in (0, 1))
        t1, t2 = truth["tvec"][n]
        # a marker point seen by both: x_c1 = R_12 x_c2 + t_12
        x_m = np.array([0.3, -0.2, 0.0])
        np.testing.assert_allclose(R12[n] @ (R2 @ x_m + t2) + t12[n], R1 @ x_m + t1, atol=1e-9)
        np.testing.assert_allclose(R12[n], R1 @ R2.T, atol=1e-12)
