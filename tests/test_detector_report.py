"""The detector report on a hand-made recording with known errors."""
from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from airpose_lib.body.joint_sets import BODY_25_NAMES, COCO18_NAMES
from airpose_lib.experiments.detector_report import as_body25, detector_report, write_report


def test_as_body25_places_coco_joints_by_name():
    coco = np.zeros((1, 1, 18, 3))
    coco[0, 0, :, 0] = np.arange(18) + 1.0
    coco[..., 2] = 1.0
    body = as_body25(coco)
    assert body.shape == (1, 1, 25, 3)
    for n, name in enumerate(COCO18_NAMES):
        assert body[0, 0, BODY_25_NAMES.index(name), 0] == n + 1
    for name in ("MidHip", "LBigToe", "RHeel"):
        np.testing.assert_array_equal(body[0, 0, BODY_25_NAMES.index(name)], 0.0)
    with pytest.raises(ValueError):
        as_body25(np.zeros((1, 1, 17, 3)))


def _recording():
    """2 frames, 1 view, 100x100 image, person size 50 px. Truth: joint j at (10 + j, 20 + j),
    RWrist (index 4) outside the image in frame 1. Detector `a` (BODY_25): truth + 3 px in x in
    frame 0, nobody in frame 1. Detector `b` (COCO-18): the truth exactly in both frames."""
    j = np.arange(25.0)
    kp2d = np.broadcast_to(np.stack([10 + j, 20 + j], -1), (2, 1, 25, 2)).copy()
    kp2d[1, 0, 4] = [150.0, 50.0]
    a = np.zeros((2, 1, 25, 3))
    a[0, 0, :, :2] = kp2d[0, 0] + [3.0, 0.0]
    a[0, 0, :, 2] = 0.9
    coco = [BODY_25_NAMES.index(n) for n in COCO18_NAMES]
    b = np.concatenate([kp2d[:, :, coco], np.full((2, 1, 18, 1), 0.8)], -1)
    gt = {"kp2d_body25": kp2d, "kp_depth_body25": np.ones((2, 1, 25)), "image_size": np.array([[100, 100]]),
          "person_size_px": np.full((2, 1), 50.0)}
    return SimpleNamespace(root=Path("/x/rec"), num_views=1, ground_truth=gt, keypoints={"a": a, "b": b})


def test_report_by_hand(tmp_path):
    rows = pd.DataFrame(detector_report(_recording(), ("a", "b")))
    assert set(rows.reference[rows.detector == "a"]) == {"truth", "b"}
    r = rows.set_index(["detector", "reference", "group"])
    at = r.loc[("a", "truth", "all")]
    assert at.recording == "rec" and at.frames == 2 and at.detection_rate == 0.5
    # truth sees 25 + 24 joints; `a` reports the 25 of frame 0
    assert at.keypoint_rate == pytest.approx(25 / 49) and at.pairs == 25
    assert at.median_px == pytest.approx(3.0) and at.p90_px == pytest.approx(3.0)
    # 3 px = 0.06 x the 50 px person: outside 0.05, inside 0.1
    assert at["pck_0.05"] == 0.0 and at["pck_0.1"] == 1.0 and at["pck_0.2"] == 1.0
    bt = r.loc[("b", "truth", "all")]
    assert bt.detection_rate == 1.0 and bt.pairs == 18 + 17 and bt.median_px == 0.0 and bt["pck_0.05"] == 1.0
    assert bt.keypoint_rate == pytest.approx(35 / 49)
    assert r.loc[("b", "truth", "feet")].keypoint_rate == 0.0  # COCO-18 has no feet
    assert np.isnan(r.loc[("b", "truth", "feet")].median_px)
    # disagreement: frame 0's 18 common joints, 3 px apart, the same both ways
    ab, ba = r.loc[("a", "b", "all")], r.loc[("b", "a", "all")]
    assert ab.pairs == ba.pairs == 18 and ab.median_px == ba.median_px == pytest.approx(3.0)
    assert r.loc[("a", "truth", "head")].pairs == 5
    path = write_report(detector_report(_recording(), ("a", "b")), tmp_path / "t" / "report.csv")
    assert len(pd.read_csv(path)) == len(rows) == 2 * 2 * 6


def test_report_needs_ground_truth_and_the_detections():
    rec = _recording()
    with pytest.raises(ValueError, match="not loaded"):
        detector_report(rec, ("a", "mediapipe"))
    rec.ground_truth = None
    with pytest.raises(ValueError, match="ground truth"):
        detector_report(rec, ("a",))


def test_the_script_names_the_recordings_and_writes_the_summary_it_printed(tmp_path, monkeypatch):
    import importlib.util

    script = Path(__file__).resolve().parents[1] / "scripts" / "detector_report.py"
    spec = importlib.util.spec_from_file_location("detector_report_script", script)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    monkeypatch.setattr(mod, "load_sequence", lambda root, detectors: _recording())
    out, md = tmp_path / "r.csv", tmp_path / "summary.md"
    assert mod.main(["/x/one", "/x/two", "--detectors", "a", "b", "--labels", "p1", "p2",
                     "--out", str(out), "--markdown", str(md)]) == 0
    rows = pd.read_csv(out)
    assert list(dict.fromkeys(rows.recording)) == ["p1", "p2"]
    table = md.read_text().splitlines()
    assert table[0].startswith("| recording | view | detector | detection_rate")
    # one line per recording and detector, all joints against the truth, values as in the CSV
    assert len(table) == 2 + 2 * 2
    truth = rows[(rows.group == "all") & (rows.reference == "truth")]
    assert f"| p1 | 0 | a | {truth.detection_rate.iloc[0]:.3f} |" in table[2]
    with pytest.raises(SystemExit):
        mod.main(["/x/one", "/x/two", "--labels", "p1", "--out", str(out)])
    # without labels, the recordings' paths without this machine's folders
    assert mod.main(["/work/mp/one", "/work/mp/two", "--detectors", "a", "b", "--out", str(out)]) == 0
    assert list(dict.fromkeys(pd.read_csv(out).recording)) == ["<abs>/mp/one", "<abs>/mp/two"]
