"""How a 2D detector does on a generated recording: detection rate, error against the true
keypoints and disagreement with the other detectors, per view and joint group.

Every detector is compared in BODY_25 (AlphaPose's COCO-18 through
:data:`~airpose_lib.finetune.keypoints.BODY25_FROM_COCO18`; a joint a layout lacks is missing).
The truth is the recording's projected BODY_25 keypoints where a perfect detector sees them
(:func:`~airpose_lib.finetune.keypoints.true_targets`: in front of the camera, inside the image).

One row per (recording, view, detector, reference, group), ``reference`` being ``truth`` or another
detector, ``group`` one of :data:`JOINT_GROUPS` or ``all``:

==================  ==========================================================================
column              meaning
==================  ==========================================================================
frames              frames of the view in which the truth sees the person (any joint)
detection_rate      of those, the fraction in which the detector reports any joint
keypoint_rate       truth-visible joints of the group the detector reports (confidence > 0)
pairs               joints both the detector and the reference report (the distances below)
median_px, p90_px   median / 90th percentile of their distance, pixels of the view's image
pck_<a>             fraction of the pairs closer than ``a x`` the person's size (the larger side
                    of the true keypoints' box, ``person_size_px``)
==================  ==========================================================================
"""
from __future__ import annotations

from collections.abc import Sequence as SequenceABC
from pathlib import Path

import numpy as np

from airpose_lib.body.joint_sets import BODY_25_NAMES
from airpose_lib.finetune.keypoints import BODY25_FROM_COCO18, true_targets

__all__ = ["JOINT_GROUPS", "as_body25", "truth_body25", "detector_report", "write_report"]

JOINT_GROUPS: dict[str, tuple[str, ...]] = {
    "head": ("Nose", "REye", "LEye", "REar", "LEar"),
    "torso": ("Neck", "RShoulder", "LShoulder", "MidHip", "RHip", "LHip"),
    "arms": ("RElbow", "RWrist", "LElbow", "LWrist"),
    "legs": ("RKnee", "RAnkle", "LKnee", "LAnkle"),
    "feet": ("LBigToe", "LSmallToe", "LHeel", "RBigToe", "RSmallToe", "RHeel"),
}
"""BODY_25 joints of each group of the report (every BODY_25 joint in one group)."""

_COLUMNS = ("recording", "view", "detector", "reference", "group", "frames", "detection_rate",
            "keypoint_rate", "pairs", "median_px", "p90_px")


def as_body25(keypoints: np.ndarray) -> np.ndarray:
    """``(F, V, 25 | 18, 3)`` BODY_25 or COCO-18 -> ``(F, V, 25, 3)`` BODY_25 (COCO-18 lacks the
    mid-hip and the feet: zeros)."""
    kp = np.asarray(keypoints, np.float64)
    if kp.shape[-2] == 25:
        return kp
    if kp.shape[-2] != 18:
        raise ValueError(f"keypoints must be (..., 25 or 18, 3), got {kp.shape}")
    idx = np.asarray(BODY25_FROM_COCO18)
    out = kp[..., np.maximum(idx, 0), :].copy()
    out[..., idx < 0, :] = 0.0
    return out


def truth_body25(ground_truth) -> np.ndarray:
    """``(F, V, 25, 3)`` the true keypoints with weight 1 where a detector could see them
    (``ground_truth.npz``'s ``kp2d_body25``, ``kp_depth_body25``, ``image_size``)."""
    return true_targets(ground_truth["kp2d_body25"], ground_truth["kp_depth_body25"],
                        ground_truth["image_size"]).astype(np.float64)


def _rows_for(recording, v, name, ref_name, det, ref, truth, size, pck) -> list[dict]:
    """Rows of one view, detector and reference. ``det``, ``ref``, ``truth``: ``(F, 25, 3)``;
    ``size``: ``(F,)`` person size in pixels."""
    seen = truth[..., 2] > 0  # (F, 25)
    has_person = seen.any(-1)
    found = det[..., 2] > 0
    both = found & (ref[..., 2] > 0)
    dist = np.linalg.norm(det[..., :2] - ref[..., :2], axis=-1)  # (F, 25)
    detected = found.any(-1) & has_person
    rows = []
    for group, names in {"all": BODY_25_NAMES, **JOINT_GROUPS}.items():
        cols = [BODY_25_NAMES.index(n) for n in names]
        d = dist[:, cols][both[:, cols]]
        rel = (dist / size[:, None])[:, cols][both[:, cols]]
        row = {"recording": recording, "view": v, "detector": name, "reference": ref_name, "group": group,
               "frames": int(has_person.sum()),
               "detection_rate": float(detected.sum() / max(has_person.sum(), 1)),
               "keypoint_rate": float((found & seen)[:, cols].sum() / max(seen[:, cols].sum(), 1)),
               "pairs": int(d.size),
               "median_px": float(np.median(d)) if d.size else float("nan"),
               "p90_px": float(np.percentile(d, 90)) if d.size else float("nan")}
        for a in pck:
            row[f"pck_{a:g}"] = float((rel <= a).mean()) if d.size else float("nan")
        rows.append(row)
    return rows


def detector_report(sequence, detectors: SequenceABC[str], *, pck: SequenceABC[float] = (0.05, 0.1, 0.2),
                    recording: str | None = None) -> list[dict]:
    """The report's rows (module doc) of a generated recording.

    Args:
        sequence: a :class:`~airpose_lib.data.sequences.reader.Sequence` with ground truth and the
            keypoints of every name in ``detectors``.
        detectors: the detectors to report; each is compared with the truth and with the others.
        pck: thresholds as fractions of the person's size (``1 - pck_0.2``: the gross errors, a
            limb on the wrong side or on the background).
        recording: the ``recording`` column (default: the sequence folder's name).

    Returns:
        one dict per row, columns in the order of the module doc.
    """
    gt = sequence.ground_truth
    if not gt or "kp2d_body25" not in gt:
        raise ValueError(f"{sequence.root}: no ground truth (kp2d_body25); the report needs a generated recording")
    missing = [d for d in detectors if d not in sequence.keypoints]
    if missing:
        raise ValueError(f"{sequence.root}: detections {missing} not loaded (have {sorted(sequence.keypoints)})")
    recording = recording or Path(sequence.root).name
    truth = truth_body25(gt)
    size = np.asarray(gt["person_size_px"], np.float64)  # (F, V)
    kp = {d: as_body25(sequence.keypoints[d]) for d in detectors}
    rows = []
    for v in range(sequence.num_views):
        for d in detectors:
            refs = {"truth": truth, **{o: kp[o] for o in detectors if o != d}}
            for ref_name, ref in refs.items():
                rows += _rows_for(recording, v, d, ref_name, kp[d][:, v], ref[:, v], truth[:, v], size[:, v], pck)
    return rows


def write_report(rows: SequenceABC[dict], path: str | Path) -> Path:
    """Write the rows as a CSV table (a tidy table: one row per observation); returns the path."""
    import pandas as pd  # only the writer needs pandas

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    pd.DataFrame(list(rows)).to_csv(path, index=False, float_format="%.4g")
    return path
