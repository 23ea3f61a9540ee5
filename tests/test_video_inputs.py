"""The video route's inputs (:mod:`airpose_lib.data.video`): intrinsics in the formats users have,
checked against the frames; video files and frame folders decoded frame by frame; keypoint files;
the time offset; two videos paired at it."""
from __future__ import annotations

import json
import math
import pickle

import numpy as np
import pytest

from airpose_lib.data.sequences.layout import write_camera_calib
from airpose_lib.data.video.assemble import paired_frames
from airpose_lib.data.video.frames import VideoError, decode_frames, frame_numbers, iter_frames, video_info
from airpose_lib.data.video.intrinsics import (
    IntrinsicsError,
    check_intrinsics,
    default_intrinsics,
    read_intrinsics,
)
from airpose_lib.data.video.keypoints import KeypointsError, keypoint_fraction, read_keypoints
from airpose_lib.data.video.offset import estimate_offset, pose_signal

K1 = np.array([[768.9, 0.0, 509.0], [0.0, 758.8, 288.5], [0.0, 0.0, 1.0]])


# -- intrinsics -----------------------------------------------------------------------------------
def test_the_authors_filestorage_calibration_is_read(tmp_path):
    write_camera_calib(tmp_path / "camera_calib.yml", K1, (960, 540))
    cam = read_intrinsics(tmp_path / "camera_calib.yml", 0)
    np.testing.assert_allclose(cam.K, K1)
    assert cam.size == (960, 540) and not cam.distorted


def test_yaml_and_json_give_fx_fy_cx_cy_per_video(tmp_path):
    (tmp_path / "both.yaml").write_text("fx: 768.9\nfy: 758.8\ncx: 509.0\ncy: 288.5\ndist: [0.1, -0.02]\n")
    cam = read_intrinsics(tmp_path / "both.yaml", 1)
    np.testing.assert_allclose(cam.K, K1)
    np.testing.assert_allclose(cam.dist, [0.1, -0.02, 0, 0, 0])
    assert cam.distorted and cam.size is None
    (tmp_path / "two.json").write_text(json.dumps({"uav1": {"K": K1.tolist()}, "uav2": {"fx": 1, "fy": 2, "cx": 3,
                                                                                       "cy": 4}}))
    assert read_intrinsics(tmp_path / "two.json", 1).K[1, 1] == 2
    np.testing.assert_allclose(read_intrinsics(tmp_path / "two.json", 0).K, K1)
    (tmp_path / "list.yaml").write_text("cameras:\n  - {fx: 5, fy: 5, cx: 1, cy: 1}\n")
    with pytest.raises(IntrinsicsError, match="no entry 2"):
        read_intrinsics(tmp_path / "list.yaml", 1)
    (tmp_path / "bad.yaml").write_text("focal: 5\n")
    with pytest.raises(IntrinsicsError, match="bad.yaml.*fx, fy, cx, cy"):
        read_intrinsics(tmp_path / "bad.yaml", 0)


def test_the_default_camera_has_the_stated_field_of_view():
    cam = default_intrinsics(200, 100, fov_y_deg=90.0)
    assert cam.K[1, 1] == pytest.approx(50.0)  # (H / 2) / tan(45 deg)
    assert (cam.K[0, 2], cam.K[1, 2]) == (99.5, 49.5)
    assert math.degrees(2 * math.atan(50 / cam.K[1, 1])) == pytest.approx(90.0)


def test_intrinsics_that_do_not_fit_the_frames_are_named():
    cam = read_intrinsics_from(K1, (1920, 1080))
    with pytest.raises(IntrinsicsError, match="1920x1080 but v.mp4 is 960x540"):
        check_intrinsics(cam, 960, 540, "v.mp4")
    full_res = read_intrinsics_from(np.array([[1537.8, 0, 1018.5], [0, 1517.7, 577.5], [0, 0, 1]]), None)
    with pytest.raises(IntrinsicsError, match="outside v.mp4"):
        check_intrinsics(full_res, 960, 540, "v.mp4")
    off = read_intrinsics_from(np.array([[800, 0, 800], [0, 700, 270], [0, 0, 1]]), None)
    warnings = check_intrinsics(off, 960, 540, "v.mp4")
    assert len(warnings) == 2 and "away from the centre" in warnings[0] and "differ by 12 %" in warnings[1]
    assert check_intrinsics(read_intrinsics_from(K1, None), 960, 540, "v.mp4") == []


def read_intrinsics_from(K, size):
    from airpose_lib.data.video.intrinsics import Intrinsics

    return Intrinsics(np.asarray(K, dtype=float), np.zeros(5), size, "cams.yaml")


# -- frames ---------------------------------------------------------------------------------------
def _write_video(path, n=20, size=(64, 48)):
    """Frame i is a flat grey of 10 * i mod 250 (compression keeps flat images close)."""
    import cv2

    w = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), 25.0, size)
    for i in range(n):
        w.write(np.full((size[1], size[0], 3), (10 * i) % 250, np.uint8))
    w.release()
    return path


def test_a_video_is_read_frame_by_frame_with_its_numbers(tmp_path):
    info = video_info(_write_video(tmp_path / "v.mp4"))
    assert (info.width, info.height, info.fps, info.n_frames) == (64, 48, 25.0, 20)
    numbers = frame_numbers(info, start=3, end=15, every=4)
    assert numbers.tolist() == [3, 7, 11]
    got = {i: float(img.mean()) for i, img in iter_frames(info, numbers)}
    assert list(got) == [3, 7, 11]
    for i, mean in got.items():
        assert abs(mean - 10 * i) < 3


def test_decoding_resumes_and_a_replaced_video_is_decoded_again(tmp_path):
    video = _write_video(tmp_path / "v.mp4")
    info = video_info(video)
    out = decode_frames(info, frame_numbers(info), tmp_path / "frames")
    assert len(list(out.glob("*.jpg"))) == 20 and (out / "frames.json").is_file()
    (out / "000005.jpg").unlink()
    (out / "frames.json").unlink()  # a killed run: no record, one frame missing
    kept = (out / "000006.jpg").stat().st_mtime_ns
    decode_frames(info, frame_numbers(info), out)
    assert (out / "000005.jpg").is_file() and (out / "000006.jpg").stat().st_mtime_ns == kept


def test_a_truncated_video_and_an_empty_folder_are_named(tmp_path):
    video = _write_video(tmp_path / "v.mp4", n=60)
    data = video.read_bytes()
    cut = tmp_path / "cut.mp4"
    cut.write_bytes(data[: len(data) // 3])
    with pytest.raises(VideoError) as e:
        info = video_info(cut)
        list(iter_frames(info, frame_numbers(info)))
    assert "cut.mp4" in str(e.value)
    (tmp_path / "empty").mkdir()
    with pytest.raises(VideoError, match="empty holds no"):
        video_info(tmp_path / "empty")
    (tmp_path / "junk.mp4").write_bytes(b"not a video")
    with pytest.raises(VideoError, match="junk.mp4"):
        video_info(tmp_path / "junk.mp4")


def test_a_folder_of_frames_needs_its_rate_and_keeps_numeric_order(tmp_path):
    import cv2

    folder = tmp_path / "frames"
    folder.mkdir()
    for i in (1, 2, 10):
        cv2.imwrite(str(folder / f"{i}.png"), np.full((8, 6, 3), i, np.uint8))
    with pytest.raises(VideoError, match="--fps"):
        video_info(folder)
    info = video_info(folder, fps=30)
    assert (info.n_frames, info.width, info.height) == (3, 6, 8)
    assert [int(img[0, 0, 0]) for _, img in iter_frames(info, [0, 1, 2])] == [1, 2, 10]


# -- keypoints ------------------------------------------------------------------------------------
def test_keypoints_come_from_the_kit_pickle_or_an_openpose_json_folder(tmp_path):
    kp = np.random.default_rng(0).uniform(1, 100, (25, 3))
    (tmp_path / "kp.pkl").write_bytes(pickle.dumps({0: kp[None], 2: np.zeros((0, 25, 3))}))
    out = read_keypoints(tmp_path / "kp.pkl", np.array([0, 1, 2]))
    np.testing.assert_allclose(out[0], kp)
    assert not out[1:].any()
    folder = tmp_path / "json"
    folder.mkdir()
    (folder / "clip_000000000007_keypoints.json").write_text(json.dumps({"people": [{"pose_keypoints_2d":
                                                                                     kp.reshape(-1).tolist()}]}))
    np.testing.assert_allclose(read_keypoints(folder, np.array([7]))[0], kp)
    assert keypoint_fraction(out) == pytest.approx(1 / 3)
    (tmp_path / "bad.pkl").write_bytes(b"\x80\x04junk")
    with pytest.raises(KeypointsError, match="bad.pkl"):
        read_keypoints(tmp_path / "bad.pkl", np.array([0]))


# -- the offset -----------------------------------------------------------------------------------
def _pose_track(n, seed):
    """``(n, 21, 3, 3)`` smooth random rotations (a slowly varying axis-angle per joint)."""
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(seed)
    t = np.arange(n)[:, None, None]
    freq, phase = rng.uniform(0.02, 0.15, (1, 21, 3)), rng.uniform(0, 6.3, (1, 21, 3))
    aa = 0.6 * np.sin(2 * np.pi * freq * t + phase)
    return Rotation.from_rotvec(aa.reshape(-1, 3)).as_matrix().reshape(n, 21, 3, 3)


@pytest.mark.parametrize("shift", [-17, 0, 9])
def test_the_offset_lines_up_two_views_of_one_pose_track(shift):
    track = _pose_track(260, seed=3)
    noise = np.random.default_rng(4)
    a = track[30:230] + noise.normal(0, 0.05, (200, 21, 3, 3))  # UAV1 sees frames 30..229
    b = track[30 + shift:230 + shift] + noise.normal(0, 0.05, (200, 21, 3, 3))
    # UAV1's frame i shows the instant of UAV2's frame i - shift
    est = estimate_offset(pose_signal(a), pose_signal(b), lag_range=(-40, 40))
    assert est.frames == -shift and est.confident
    assert est.correlation > 0.7 and est.runner_up < est.correlation - 0.5


def test_frames_missing_in_one_view_do_not_move_the_offset():
    track = _pose_track(200, seed=5)
    valid = np.ones(200, bool)
    valid[50:90] = False
    est = estimate_offset(pose_signal(track[:180], valid[:180]), pose_signal(track[5:185]), lag_range=(-20, 20))
    assert est.frames == -5


def test_paired_frames_follow_the_offset_sign():
    f1, f2 = paired_frames([0, 1, 2, 3, 4], [0, 1, 2, 3, 4, 5, 6], offset=2)
    assert f1.tolist() == [0, 1, 2, 3, 4] and f2.tolist() == [2, 3, 4, 5, 6]
    f1, f2 = paired_frames([0, 2, 4, 6], [0, 1, 2, 3], offset=-3)
    assert f1.tolist() == [4, 6] and f2.tolist() == [1, 3]


# -- a person found without a given box (MediaPipe's --crop track) -------------------------------
def test_the_tracker_searches_tiles_then_follows_the_person():
    from airpose_lib.data.sequences.mediapipe_pose import search_crops, track_person

    tiles = search_crops(960, 540)
    assert all(side == 270 for _, _, side in tiles) and len(tiles) == 7 * 3  # half-overlapping, covering
    assert max(x for x, _, _ in tiles) + 270 >= 960 - 1e-9 and max(y for _, y, _ in tiles) + 270 >= 540 - 1e-9
    centres = [(100.0 + 20 * i, 300.0) for i in range(6)]
    centres[3] = None  # the person leaves for one frame

    def detect(image, crop):
        """A detector that sees a 100 px tall person only in a crop holding all of it."""
        c = centres[int(image)]
        x0, y0, side = crop
        if c is None or not (x0 <= c[0] - 20 and c[0] + 20 <= x0 + side and y0 <= c[1] - 50 and c[1] + 50 <= y0 + side):
            return np.full((33, 3), np.nan)
        lm = np.zeros((33, 3))
        lm[:, 0] = c[0] + np.linspace(-20, 20, 33)
        lm[:, 1] = c[1] + np.linspace(-50, 50, 33)
        lm[:, 2] = 0.9
        return lm

    landmarks, counts = track_person(range(6), detect, (960, 540))
    found = np.isfinite(landmarks[:, 0, 0])
    assert found.tolist() == [True, True, True, False, True, True]
    assert counts == {"followed": 4, "searched": 3, "found": 5}  # frames 0, 3 (lost), 4 (after the loss)
    np.testing.assert_allclose(np.nanmean(landmarks[[0, 5], :, 0], axis=1), [100, 200])
