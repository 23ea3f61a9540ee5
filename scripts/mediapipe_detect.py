#!/usr/bin/env python
"""MediaPipe Pose over a recording: ``machine_k/mediapipe_res.pkl`` (BODY_25) for the kit to read.

Runs in MediaPipe's own environment, not the kit's (MediaPipe pins ``protobuf<5``, onnx needs a
newer one; ``environment.md``, "The MediaPipe detector"). It imports only the kit's torch-free
modules (``data.sequences.layout``, ``.reader``, ``.writer``, ``data.network_input``, ``data.sequences.mediapipe_pose``: numpy and
OpenCV; ``paths``) from this checkout.

Per frame and view: a square crop around a person box (``--crop``, see
``airpose_lib.data.sequences.mediapipe_pose.CROP_SOURCES``), ``--crop-scale`` times the box's longer side,
resized to ``--input-size`` px, goes through ``mediapipe.solutions.pose.Pose`` (static images:
every frame on its own, so a frame's result never depends on the previous one's); its 33
landmarks become BODY_25 keypoints in full-frame pixels.

Output: ``--out`` (default: the recording itself) gets ``machine_k/mediapipe_res.pkl`` and
``mediapipe_detect.json`` (settings, versions, per-view counts; the recording's path
:func:`~airpose_lib.paths.portable`). An ``--out`` other than the recording becomes a copy made
of links: every other file of the recording is linked, so
``load_sequence(out, detectors=("openpose", "alphapose", "mediapipe"))`` reads it as the
recording plus the new detector, and the recording is left untouched.

    .venv-mediapipe/bin/python scripts/mediapipe_detect.py RECORDING --out OUT --crop openpose
    .venv-mediapipe/bin/python scripts/mediapipe_detect.py RECORDING --crop track   # no detector at hand
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the kit's torch-free modules

import numpy as np  # noqa: E402

from airpose_lib.data.sequences.layout import DETECTOR_FILES  # noqa: E402
from airpose_lib.data.sequences.mediapipe_pose import (  # noqa: E402
    CROP_SOURCES,
    body25_from_landmarks,
    crop_boxes,
    crop_image,
    from_crop,
    square_crop,
    track_person,
    write_body25,
)
from airpose_lib.data.sequences.reader import load_sequence  # noqa: E402
from airpose_lib.errors import UserError  # noqa: E402
from airpose_lib.paths import portable  # noqa: E402

OUTPUT = DETECTOR_FILES["mediapipe"][0]


def link_recording(src: Path, out: Path) -> None:
    """``out`` mirrors ``src`` through links (all but the MediaPipe files), machine folders made."""
    out.mkdir(parents=True, exist_ok=True)
    for item in src.iterdir():
        if item.name == "mediapipe_detect.json":
            continue
        if item.is_dir() and item.name.startswith("machine_"):
            link_recording(item, out / item.name)
            continue
        if item.name == OUTPUT:
            continue
        dst = out / item.name
        if dst.is_symlink():
            dst.unlink()
        if not dst.exists():
            dst.symlink_to(item.resolve())


def landmarks_px(result, crop, size: int) -> np.ndarray:
    """``(33, 3)`` ``[x, y, visibility]`` full-frame pixels of one result; NaN: nobody found."""
    if result.pose_landmarks is None:
        return np.full((33, 3), np.nan)
    lm = np.array([[p.x, p.y, p.visibility] for p in result.pose_landmarks.landmark])
    # MediaPipe's coordinates are fractions of the input's width/height (0: its left edge);
    # the kit's pixels are indices of pixel centres, hence the half pixel.
    lm[:, :2] = from_crop(lm[:, :2] * size - 0.5, crop, size)
    return lm


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("sequence", type=Path, help="recording folder (official layout)")
    ap.add_argument("--out", type=Path, default=None, help="where to write (default: the recording)")
    ap.add_argument("--crop", choices=CROP_SOURCES, default="openpose",
                    help="person box the crop is built around (default: openpose, the drones' box)")
    ap.add_argument("--crop-scale", type=float, default=1.5, help="crop side / box's longer side")
    ap.add_argument("--input-size", type=int, default=256, help="crop side in pixels given to MediaPipe")
    ap.add_argument("--model-complexity", type=int, choices=(1,), default=1,
                    help="1: pose_landmark_full, the landmark model the wheel bundles")
    ap.add_argument("--min-detection-confidence", type=float, default=0.5)
    args = ap.parse_args(argv)

    import mediapipe
    from mediapipe.python.solutions import pose as mp_pose

    src = args.sequence.resolve()
    out = (args.out or args.sequence).resolve()
    try:
        seq = load_sequence(src, detectors=(args.crop,) if args.crop in DETECTOR_FILES else (),
                            ground_truth=args.crop == "truth", missing_detections="zero")
        boxes = None if args.crop == "track" else crop_boxes(seq, args.crop)
    except UserError as e:
        print(f"mediapipe_detect: error: {e}", file=sys.stderr)
        return 2
    if out != src:
        link_recording(src, out)
    F, V = seq.num_frames, seq.num_views
    landmarks = np.full((F, V, 33, 3), np.nan)
    t0 = time.perf_counter()
    for v in range(V):
        with mp_pose.Pose(static_image_mode=True, model_complexity=args.model_complexity,
                          min_detection_confidence=args.min_detection_confidence) as det:
            if boxes is None:  # no box to start from: find the person in tiles, then follow it
                def detect(image, crop, det=det):
                    return landmarks_px(det.process(crop_image(image, crop, args.input_size)), crop, args.input_size)

                h, w = seq.image(0, v).shape[:2]
                landmarks[:, v], counts = track_person((seq.image(f, v) for f in range(F)), detect, (w, h),
                                                       crop_scale=args.crop_scale)
                print(f"view {v + 1}: {counts}")
                continue
            for f in range(F):
                if not np.isfinite(boxes[f, v]).all():
                    continue  # no box in this view at all: nothing to crop
                crop = square_crop(boxes[f, v], args.crop_scale)
                result = det.process(crop_image(seq.image(f, v), crop, args.input_size))
                landmarks[f, v] = landmarks_px(result, crop, args.input_size)
    seconds = time.perf_counter() - t0
    kp = body25_from_landmarks(landmarks)
    for v in range(V):
        write_body25(out / f"machine_{v + 1}" / OUTPUT, seq.frames.tolist(), kp[:, v])
    found = np.isfinite(landmarks[..., 0, 0])
    # the record is committed beside the tables (results/<profile>/detectors/): no folder of this machine
    info = {"sequence": portable(str(src)), "mediapipe_version": mediapipe.__version__, "crop": args.crop,
            "crop_scale": args.crop_scale, "input_size": args.input_size,
            "model_complexity": args.model_complexity,
            "min_detection_confidence": args.min_detection_confidence,
            "frames": F, "found_per_view": found.sum(0).tolist(),
            "seconds_per_image": round(seconds / max(F * V, 1), 4)}
    (out / "mediapipe_detect.json").write_text(json.dumps(info, indent=1))
    print(f"{out}: person found in {found.sum(0).tolist()} of {F} frames per view "
          f"({info['seconds_per_image'] * 1000:.0f} ms per image)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
