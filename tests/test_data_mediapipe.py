"""MediaPipe Pose as a BODY_25 detector, without MediaPipe: the landmark
mapping on hand-made landmarks, the crop geometry, the crop boxes and the file the kit reads.
The detector run itself needs the detector's own environment (test at the end, skipped here)."""
from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from airpose_lib.data.sequences.mediapipe_pose import (
    body25_from_landmarks,
    crop_boxes,
    crop_image,
    from_crop,
    square_crop,
    write_body25,
)
from airpose_lib.data.sequences.reader import load_sequence
from airpose_lib.data.sequences.writer import OfficialLayoutWriter


def _landmarks():
    """(33, 3): landmark i at (10 i, 1000 + 10 i), visibility 0.5 + i / 100."""
    i = np.arange(33.0)
    return np.stack([10 * i, 1000 + 10 * i, 0.5 + i / 100], -1)


def test_body25_from_landmarks_by_hand():
    kp = body25_from_landmarks(_landmarks())
    assert kp.shape == (25, 3)
    lm = _landmarks()
    # BODY_25 index: landmark (MediaPipe index, written out from its documentation)
    single = {0: 0, 2: 12, 3: 14, 4: 16, 5: 11, 6: 13, 7: 15, 9: 24, 10: 26, 11: 28, 12: 23, 13: 25,
              14: 27, 15: 5, 16: 2, 17: 8, 18: 7, 19: 31, 21: 29, 22: 32, 24: 30}
    for j, m in single.items():
        np.testing.assert_array_equal(kp[j], lm[m], err_msg=f"BODY_25 {j}")
    # Neck: shoulders 11, 12 -> (115, 1115), visibility min(0.61, 0.62); MidHip: hips 23, 24
    np.testing.assert_allclose(kp[1], [115.0, 1115.0, 0.61])
    np.testing.assert_allclose(kp[8], [235.0, 1235.0, 0.73])
    # small toes: MediaPipe has none
    np.testing.assert_array_equal(kp[[20, 23]], 0.0)


def test_body25_from_landmarks_missing_is_zero_and_batches():
    lm = np.stack([_landmarks(), np.full((33, 3), np.nan)])
    lm[0, 11, 2] = 0.0  # left shoulder invisible: it and the neck (a midpoint with it) drop
    kp = body25_from_landmarks(lm)
    assert kp.shape == (2, 25, 3) and np.isfinite(kp).all()
    np.testing.assert_array_equal(kp[1], 0.0)
    np.testing.assert_array_equal(kp[0, [1, 5]], 0.0)
    assert kp[0, 2, 2] > 0
    with pytest.raises(ValueError, match="33, 3"):
        body25_from_landmarks(np.zeros((25, 3)))


def test_crop_round_trip_finds_a_pixel():
    img = np.zeros((540, 960, 3), np.uint8)
    img[300:302, 500:502] = 255  # a 2x2 spot centred at (501, 301) (pixel centres 500.5 ... )
    crop = square_crop(np.array([480.0, 250.0, 530.0, 350.0]), scale=1.5)
    assert crop == pytest.approx((430.0, 225.0, 150.0))  # side 1.5 x 100, centred on (505, 300)
    out = crop_image(img, crop, 300)  # x2
    ys, xs = np.nonzero(out[..., 0] > 100)
    centre = from_crop(np.array([xs.mean(), ys.mean()]), crop, 300)
    np.testing.assert_allclose(centre, [500.5, 300.5], atol=0.5)
    # outside the image: black
    edge = crop_image(img, (-100.0, -100.0, 200.0), 50)
    assert edge.shape == (50, 50, 3) and edge[:20, :20].max() == 0


def _sequence(kp, gt_bbox=None):
    F, V = kp.shape[:2]
    img = np.zeros((100, 200, 3), np.uint8)
    return SimpleNamespace(num_frames=F, num_views=V, root=Path("fixture"), keypoints={"openpose": kp},
                           ground_truth=None if gt_bbox is None else {"bbox": gt_bbox},
                           image=lambda f, v: img)


def test_crop_boxes_sources():
    kp = np.zeros((3, 1, 25, 3))
    kp[1, 0, :4] = [[50, 20, 0.9], [60, 30, 0.9], [70, 40, 0.9], [80, 50, 0.9]]
    seq = _sequence(kp, gt_bbox=np.arange(12.0).reshape(3, 1, 4))
    boxes = crop_boxes(seq, "openpose", margin_px=5.0)
    # frame 1 has the box, frame 0 takes it ahead (offline rule), frame 2 keeps it
    np.testing.assert_array_equal(boxes[:, 0], [[45, 15, 85, 55]] * 3)
    np.testing.assert_array_equal(crop_boxes(seq, "truth"), np.arange(12.0).reshape(3, 1, 4))
    np.testing.assert_array_equal(crop_boxes(seq, "none")[:, 0], [[0, 0, 199, 99]] * 3)
    with pytest.raises(ValueError, match="ground_truth"):
        crop_boxes(_sequence(kp), "truth")
    with pytest.raises(ValueError, match="crop source"):
        crop_boxes(seq, "yolo")


def _write_recording(root: Path, F=3, V=2):
    w = OfficialLayoutWriter(root, num_views=V)
    for f in range(F):
        w.write_frame(f, [np.zeros((40, 60, 3), np.uint8)] * V)
    rng = np.random.default_rng(0)
    op = np.concatenate([rng.uniform(0, 50, (F, V, 25, 2)), rng.uniform(0.1, 1, (F, V, 25, 1))], -1)
    w.finish(np.stack([np.eye(3)] * V), {"openpose": op})
    return op


def test_mediapipe_file_is_read_as_a_detector(tmp_path):
    _write_recording(tmp_path)
    kp = body25_from_landmarks(np.stack([_landmarks()] * 3))
    kp[2] = 0.0  # nobody found in frame 2
    for v in range(2):
        shifted = np.where(kp[..., 2:] > 0, kp + [v, 0, 0], 0.0)  # view 1: x + 1 where detected
        write_body25(tmp_path / f"machine_{v + 1}" / "mediapipe_res.pkl", [0, 1, 2], shifted)
    seq = load_sequence(tmp_path, detectors=("openpose", "mediapipe"))
    got = seq.keypoints["mediapipe"]
    assert got.shape == (3, 2, 25, 3) and seq.info["mediapipe"]["format"] == "kit"
    np.testing.assert_allclose(got[:2, 0], kp[:2], atol=1e-4)  # float32 on disk
    np.testing.assert_allclose(got[:2, 1, :, 0], np.where(kp[:2, :, 2] > 0, kp[:2, :, 0] + 1, 0), atol=1e-4)
    np.testing.assert_array_equal(got[2], 0.0)
    with pytest.raises(ValueError, match=r"\(3, 25, 3\)"):
        write_body25(tmp_path / "x.pkl", [0, 1, 2], kp[:, :18])


def test_writer_writes_a_mediapipe_file_in_the_body25_format(tmp_path):
    w = OfficialLayoutWriter(tmp_path, num_views=1)
    w.write_frame(0, [np.zeros((40, 60, 3), np.uint8)])
    kp = np.zeros((1, 1, 25, 3))
    kp[0, 0, 0] = [1.5, 2.5, 0.5]
    w.finish(np.eye(3)[None], {"mediapipe": kp})
    np.testing.assert_allclose(load_sequence(tmp_path, detectors=("mediapipe",)).keypoints["mediapipe"], kp)


_MP_PYTHON = os.environ.get("AIRPOSE_MEDIAPIPE_PYTHON",
                            str(Path(__file__).resolve().parents[1] / ".venv-mediapipe" / "bin" / "python"))


@pytest.mark.slow
@pytest.mark.skipif(not Path(_MP_PYTHON).is_file(), reason="MediaPipe's environment is missing "
                    "(scripts/setup_mediapipe.sh; AIRPOSE_MEDIAPIPE_PYTHON names its python)")
def test_detector_script_runs_on_a_rendered_recording(tmp_path):
    """The script in MediaPipe's environment over a written recording: it runs, writes a file
    the kit reads, and finds nobody on black frames."""
    _write_recording(tmp_path / "rec")
    script = Path(__file__).resolve().parents[1] / "scripts" / "mediapipe_detect.py"
    subprocess.run([_MP_PYTHON, str(script), str(tmp_path / "rec"), "--out", str(tmp_path / "out"),
                    "--crop", "openpose"], check=True, timeout=300)
    seq = load_sequence(tmp_path / "out", detectors=("openpose", "mediapipe"))
    assert seq.keypoints["mediapipe"].shape == (3, 2, 25, 3)
    np.testing.assert_array_equal(seq.keypoints["mediapipe"], 0.0)
    record = json.loads((tmp_path / "out" / "mediapipe_detect.json").read_text())
    assert str(tmp_path) not in record["sequence"] and record["sequence"].endswith("/rec")  # no machine's folders
