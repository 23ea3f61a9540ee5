"""A recording in the official layout written as two video files and their keypoint files: the
known truth the video route (``airpose video``) is tested and demonstrated on.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from airpose_lib.atomic import atomic_path
from airpose_lib.data.sequences.detector_files import write_detector_file
from airpose_lib.data.sequences.reader import load_sequence
from airpose_lib.viz.video import write_mp4

__all__ = ["export_videos"]


def export_videos(recording: str | Path, out_dir: str | Path, *, shift: int = 0, detector: str = "openpose",
                  fps: float | None = None, frames: slice | None = None) -> dict[str, Path]:
    """Write ``uav1.mp4``, ``uav2.mp4`` and ``uav{1,2}_keypoints.pkl`` (BODY_25, the videos' own frame
    numbers) from a recording.

    Args:
        recording: a recording folder (two machines).
        shift: UAV2's video starts ``shift`` frames late (> 0) or early (< 0: UAV1 starts late);
            the true offset (:mod:`.offset`'s sign) is then ``-shift``.
        detector: the keypoint file the pickles come from.
        fps: the videos' rate (default: the recording's time stamps', else 30).
        frames: the recording's frames to use (a slice over them).

    Returns:
        ``{"uav1": path, "uav2": path, "uav1_keypoints": path, "uav2_keypoints": path, "export": path}``;
        ``export.json`` names the recording, the shift and the recording frame of each video's
        first frame.
    """
    seq = load_sequence(recording, frames=frames, detectors=(detector,), ground_truth=False)
    F = seq.num_frames
    if fps is None:
        ts = seq.timestamps
        fps = float(round(1.0 / np.median(np.diff(ts[:, 0])), 3)) if ts is not None and F > 1 else 30.0
    starts = (max(-shift, 0), max(shift, 0))  # the first recording frame of each video
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {}
    for v in range(2):
        rows = range(starts[v], F)
        name = f"uav{v + 1}"
        h, w = seq.image(0, v).shape[:2]
        target = write_mp4((seq.image(i, v) for i in rows), (w, h), fps, out / f"{name}.mp4")
        kp_path = out / f"{name}_keypoints.pkl"  # renumbered from the video's first frame
        write_detector_file("openpose", kp_path, list(range(len(rows))), seq.keypoints[detector][starts[v]:, v])
        paths[name], paths[f"{name}_keypoints"] = target, kp_path
    record = {"recording": str(Path(recording).resolve()), "shift": int(shift), "fps": fps, "detector": detector,
              "first_frame": [int(seq.frames[starts[0]]), int(seq.frames[starts[1]])],
              "true_offset_frames": int(-shift)}
    paths["export"] = out / "export.json"
    with atomic_path(paths["export"]) as tmp:
        tmp.write_text(json.dumps(record, indent=1))
    return paths
