"""The 3D scene of a recording (:class:`airpose_lib.viz.scene3d.RecordingScene`) from its ground
truth and one method's per-view estimates; notebook 07 shows it."""
from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import torch

from airpose_lib.body import load_body_model
from airpose_lib.body.genders import GENDER_NAMES
from airpose_lib.experiments.recording_estimates import body_vertices
from airpose_lib.geometry import axis_angle_to_matrix
from airpose_lib.viz.scene3d import RecordingScene

__all__ = ["recording_scene"]


def _ground_truth_params(gt: Mapping) -> dict[str, np.ndarray]:
    """Per-view parameters of the true body from a recording's ``ground_truth.npz`` arrays."""
    theta = np.asarray(gt["theta_view"] if "theta_view" in gt else gt["theta"], dtype=np.float64)
    if theta.shape[-1] == 3 and theta.shape[-2] != 3:  # axis-angle (..., 21, 3)
        theta = axis_angle_to_matrix(torch.from_numpy(theta)).numpy()
    return {"phi": np.asarray(gt["phi"]), "tau": np.asarray(gt["tau"]), "theta": theta,
            "beta": np.asarray(gt["betas"])}


def recording_scene(sequence, estimate: Mapping | None = None, method: str | None = None,
                    frames: Sequence[int] | None = None, stride: int = 1) -> RecordingScene:
    """The 3D scene of a recording with ground truth.

    Args:
        sequence: a loaded :class:`~airpose_lib.data.sequences.reader.Sequence` whose
            ``ground_truth`` is set (the kit's generated recordings).
        estimate: per-view parameters of one method over the sequence's F frames (``phi (F, V,
            3, 3)``, ``tau (F, V, 3)``, ``theta``, ``beta``; :class:`RecordingExperiment.estimates`
            entries), or None.
        method: its name, for labels.
        frames: positions (0..F-1) to keep; default every ``stride``-th.
        stride: step between kept frames when ``frames`` is None.
    """
    gt = sequence.ground_truth
    if gt is None:
        raise ValueError(f"{sequence.root}: no ground_truth.npz; the 3D view needs the true cameras")
    F = len(sequence.frames)
    idx = np.asarray(frames if frames is not None else np.arange(0, F, max(1, int(stride))), dtype=np.int64)
    gender = GENDER_NAMES.get(int(gt.get("gender", 0)), "neutral")
    true_body = load_body_model("open", gender)
    R_cw, t_cw = np.asarray(gt["R_cw"], np.float64)[idx], np.asarray(gt["t_cw"], np.float64)[idx]
    gt_cam = body_vertices(_ground_truth_params(gt), true_body, idx, 0)  # (n, N, 3) camera 1
    est = None
    if estimate is not None:
        body = load_body_model("open", "neutral")
        est = np.stack([body_vertices(estimate, body, idx, v) for v in range(R_cw.shape[1])], axis=1)
    t = np.asarray(sequence.timestamps[:, 0] if sequence.timestamps is not None
                   else np.asarray(sequence.frames) / float(gt.get("fps", 30.0)), np.float64)
    image_size = np.asarray(gt["image_size"]) if "image_size" in gt else \
        np.stack([2 * np.asarray(sequence.K)[:, 0, 2], 2 * np.asarray(sequence.K)[:, 1, 2]], -1)
    scene = RecordingScene(frames=np.asarray(sequence.frames)[idx], time_s=t[idx] - t[0],
                           faces=np.asarray(true_body.faces, np.int64), ground_truth=gt_cam, estimates=None,
                           method=method, R_cw=R_cw, t_cw=t_cw, K=np.asarray(sequence.K, np.float64),
                           image_size=image_size.astype(np.int64),
                           person_path=np.asarray(gt["pelvis_world"], np.float64)[idx, 0]
                           if np.asarray(gt["pelvis_world"]).ndim == 3 else np.asarray(gt["pelvis_world"])[idx])
    scene.ground_truth = scene.to_world(gt_cam, 0).astype(np.float32)  # float32: a long recording stays small
    if est is not None:
        scene.estimates = np.stack([scene.to_world(est[:, v], v) for v in range(scene.num_views)], axis=1).astype(np.float32)
    return scene
