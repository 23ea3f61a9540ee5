"""A real 2D detector beside the simulated ones: MediaPipe Pose's 33 landmarks as BODY_25 keypoints.

The detector itself runs in its own environment (``scripts/mediapipe_detect.py``; MediaPipe's
wheel pins ``protobuf<5``, which conflicts with onnx's, see ``environment.md``). This module is
the part both environments share and the kit tests without MediaPipe: numpy only at import (the
detector's environment has no torch), OpenCV inside the crop function.

Landmarks -> BODY_25 (:data:`BODY_25_FROM_MEDIAPIPE`; MediaPipe's left/right are the person's,
as OpenPose's):

==================  =======================================================================
BODY_25 keypoint    MediaPipe landmark
==================  =======================================================================
Nose, eyes, ears    ``nose``, ``left_eye`` / ``right_eye`` (the pupils), ``left_ear`` / ``right_ear``
shoulders ... ankles  the landmark of the same name
Neck                midpoint of ``left_shoulder`` and ``right_shoulder``
MidHip              midpoint of ``left_hip`` and ``right_hip``
LBigToe / RBigToe   ``left_foot_index`` / ``right_foot_index`` (the tip of the foot)
LHeel / RHeel       ``left_heel`` / ``right_heel``
LSmallToe, RSmallToe  none: confidence 0 (MediaPipe has one foot tip)
==================  =======================================================================

Confidence: the landmark's ``visibility``; a midpoint gets the smaller of its two. MediaPipe's
joints are its own definitions (its hips sit on the skin's outline, the kit's true keypoints at
SMPL-X's hip joints), so part of its error against the truth is a definition offset, not noise
(:func:`airpose_lib.experiments.detector_report.detector_report` breaks the error down by joint
group to show it).

Input: MediaPipe's person detector expects a person that fills a good part of its 224 px input;
in the kit's half-resolution recordings a person is 70-130 px tall in a 960x540 frame and the
full frame finds nobody. So the detector sees a square crop around a person box
(:data:`CROP_SOURCES`: the simulated OpenPose's box with the drones' previous-box rule, the
simulated AlphaPose's, the true box of a generated recording, or the whole frame), enlarged by
``scale`` and resized to ``size`` px; MediaPipe's own pipeline also detects, then crops.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from airpose_lib.body.joint_sets import BODY_25_NAMES
from airpose_lib.errors import ConfigError

from ..network_input import hold_boxes, person_box
from .detector_files import write_detector_file
from .layout import DETECTOR_FILES

__all__ = [
    "search_crops",
    "box_from_landmarks",
    "track_person",
    "MEDIAPIPE_NAMES",
    "BODY_25_FROM_MEDIAPIPE",
    "CROP_SOURCES",
    "body25_from_landmarks",
    "crop_boxes",
    "square_crop",
    "crop_image",
    "from_crop",
    "write_body25",
]

MEDIAPIPE_NAMES: tuple[str, ...] = (
    "nose", "left_eye_inner", "left_eye", "left_eye_outer", "right_eye_inner", "right_eye",
    "right_eye_outer", "left_ear", "right_ear", "mouth_left", "mouth_right", "left_shoulder",
    "right_shoulder", "left_elbow", "right_elbow", "left_wrist", "right_wrist", "left_pinky",
    "right_pinky", "left_index", "right_index", "left_thumb", "right_thumb", "left_hip", "right_hip",
    "left_knee", "right_knee", "left_ankle", "right_ankle", "left_heel", "right_heel",
    "left_foot_index", "right_foot_index",
)
"""MediaPipe Pose's 33 landmarks, in its order (``mediapipe.solutions.pose.PoseLandmark``)."""

_LANDMARKS_OF: dict[str, tuple[str, ...]] = {
    "Nose": ("nose",), "Neck": ("left_shoulder", "right_shoulder"),
    "RShoulder": ("right_shoulder",), "RElbow": ("right_elbow",), "RWrist": ("right_wrist",),
    "LShoulder": ("left_shoulder",), "LElbow": ("left_elbow",), "LWrist": ("left_wrist",),
    "MidHip": ("left_hip", "right_hip"),
    "RHip": ("right_hip",), "RKnee": ("right_knee",), "RAnkle": ("right_ankle",),
    "LHip": ("left_hip",), "LKnee": ("left_knee",), "LAnkle": ("left_ankle",),
    "REye": ("right_eye",), "LEye": ("left_eye",), "REar": ("right_ear",), "LEar": ("left_ear",),
    "LBigToe": ("left_foot_index",), "LSmallToe": (), "LHeel": ("left_heel",),
    "RBigToe": ("right_foot_index",), "RSmallToe": (), "RHeel": ("right_heel",),
}

BODY_25_FROM_MEDIAPIPE: tuple[tuple[int, ...], ...] = tuple(
    tuple(MEDIAPIPE_NAMES.index(n) for n in _LANDMARKS_OF[name]) for name in BODY_25_NAMES)
"""Per BODY_25 keypoint, the MediaPipe landmarks it is the mean of (empty: MediaPipe lacks it)."""

CROP_SOURCES = ("openpose", "alphapose", "truth", "none", "track")
"""Where the detector's crop comes from: a simulated detector's person box (the drones' rule:
``data.network_input.person_box`` and the previous box when it misses), the generated
recording's true box (``ground_truth.npz`` ``bbox``), ``none`` (the whole frame), or ``track``
(no box given: :func:`track_person` finds the person in tiles of the frame and follows it)."""


def body25_from_landmarks(landmarks: np.ndarray) -> np.ndarray:
    """BODY_25 keypoints from MediaPipe landmarks.

    Args:
        landmarks: ``(..., 33, 3)`` ``[x, y, visibility]``, pixels; NaN rows = not detected.

    Returns:
        ``(..., 25, 3)`` float64 ``[x, y, confidence]``; a keypoint MediaPipe lacks, a NaN input
        or a confidence <= 0 is ``(0, 0, 0)`` (OpenPose's convention).
    """
    lm = np.asarray(landmarks, np.float64)
    if lm.shape[-2:] != (33, 3):
        raise ValueError(f"landmarks must be (..., 33, 3), got {lm.shape}")
    out = np.zeros(lm.shape[:-2] + (25, 3))
    for j, idx in enumerate(BODY_25_FROM_MEDIAPIPE):
        if idx:
            sel = lm[..., list(idx), :]
            out[..., j, :2] = sel[..., :2].mean(-2)
            out[..., j, 2] = sel[..., 2].min(-1)
    bad = ~np.isfinite(out).all(-1) | (out[..., 2] <= 0)
    out[bad] = 0.0
    return out


def crop_boxes(sequence, source: str, *, margin_px: float = 20.0, min_confidence: float = 0.2) -> np.ndarray:
    """The person box each frame's crop is built around.

    Args:
        sequence: a :class:`~airpose_lib.data.sequences.reader.Sequence` holding the ``source``
            detector's keypoints, or its ground truth for ``truth``.
        source: one of :data:`CROP_SOURCES`.
        margin_px, min_confidence: :func:`~airpose_lib.data.network_input.person_box`'s.

    Returns:
        ``(F, V, 4)`` ``[x0, y0, x1, y1]`` full-frame pixels; NaN where there is no box (a view
        whose detector never finds the person).
    """
    if source not in CROP_SOURCES or source == "track":
        raise ConfigError(f"crop source must be one of {CROP_SOURCES[:-1]} (track: track_person), got {source!r}")
    F, V = sequence.num_frames, sequence.num_views
    sizes = [sequence.image(0, v).shape[1::-1] for v in range(V)]  # (W, H) per view
    if source == "none":
        whole = np.array([[0.0, 0.0, w - 1.0, h - 1.0] for w, h in sizes])  # (V, 4)
        return np.broadcast_to(whole, (F, V, 4)).copy()
    if source == "truth":
        if not sequence.ground_truth or "bbox" not in sequence.ground_truth:
            raise ConfigError(f"{sequence.root}: crop source 'truth' needs a generated recording's "
                              "ground_truth.npz (bbox); give another crop source")
        return np.asarray(sequence.ground_truth["bbox"], np.float64).reshape(F, V, 4)
    kp = sequence.keypoints[source]
    out = np.empty((F, V, 4))
    for v in range(V):
        found = [person_box(kp[f, v], sizes[v], min_confidence, margin_px) for f in range(F)]
        out[:, v] = hold_boxes(found, leading="first")[0]
    return out


def square_crop(box: np.ndarray, scale: float = 1.5) -> tuple[float, float, float]:
    """``(x0, y0, side)``: the square of side ``scale x`` the box's longer side, centred on it.

    ``box``: ``(4,)`` ``[x0, y0, x1, y1]``. The square may leave the image (padded black)."""
    x0, y0, x1, y1 = np.asarray(box, np.float64)
    side = scale * max(x1 - x0, y1 - y0, 1.0)
    return (x0 + x1 - side) / 2, (y0 + y1 - side) / 2, side


def crop_image(image: np.ndarray, crop: tuple[float, float, float], size: int) -> np.ndarray:
    """The ``(size, size, 3)`` uint8 crop of ``image`` (H, W, 3) over the square ``crop``
    (:func:`square_crop`), black outside the image; bilinear."""
    import cv2  # only the detector's script crops; importing this module needs no OpenCV

    x0, y0, side = crop
    s = size / side
    M = np.array([[s, 0.0, -s * x0], [0.0, s, -s * y0]])
    return cv2.warpAffine(np.ascontiguousarray(image), M, (size, size), flags=cv2.INTER_LINEAR,
                          borderMode=cv2.BORDER_CONSTANT, borderValue=0)


def from_crop(xy: np.ndarray, crop: tuple[float, float, float], size: int) -> np.ndarray:
    """Crop pixels ``(..., 2)`` (of :func:`crop_image`'s output) -> full-frame pixels."""
    x0, y0, side = crop
    return np.asarray(xy, np.float64) * (side / size) + np.array([x0, y0])


def write_body25(path: str | Path, frames, keypoints: np.ndarray) -> None:
    """Write one view's ``(F, 25, 3)`` keypoints as the kit's BODY_25 pickle
    (``machine_k/mediapipe_res.pkl``, the ``openpose_res.pkl`` format that
    :func:`~airpose_lib.data.sequences.reader.load_sequence` reads as detector ``mediapipe``)."""
    kp = np.asarray(keypoints, np.float64)
    if kp.shape != (len(frames), DETECTOR_FILES["mediapipe"][1], 3):
        raise ValueError(f"keypoints must be ({len(frames)}, 25, 3), got {kp.shape}")
    write_detector_file("mediapipe", Path(path), list(frames), kp)  # the one BODY_25 pickle writer


def search_crops(width: int, height: int, side_share: float = 0.5, overlap: float = 0.5) -> list[tuple[float, float, float]]:
    """Square tiles ``(x0, y0, side)`` covering a ``width`` x ``height`` frame, each ``side_share``
    of its height, overlapping by at least ``overlap``: where a person a few per cent of the frame tall
    fills enough of the detector's input to be found."""
    side = max(1.0, side_share * height)
    step = side * (1 - overlap)

    def starts(length: float) -> np.ndarray:  # evenly spread, the last tile flush with the far edge
        span = max(length - side, 0.0)
        return np.linspace(0.0, span, int(np.ceil(span / step)) + 1)

    xs, ys = starts(width), starts(height)
    return [(float(x), float(y), float(side)) for y in ys for x in xs]


def box_from_landmarks(landmarks: np.ndarray, min_visibility: float = 0.5) -> np.ndarray | None:
    """``[x0, y0, x1, y1]`` around the landmarks seen with ``visibility >= min_visibility``
    (``(33, 3)`` full-frame pixels); None with fewer than 4."""
    lm = np.asarray(landmarks, np.float64)
    seen = np.isfinite(lm[:, 0]) & (np.nan_to_num(lm[:, 2]) >= min_visibility)
    if seen.sum() < 4:
        return None
    xy = lm[seen, :2]
    return np.concatenate([xy.min(0), xy.max(0)])


def track_person(images, detect, image_size: tuple[int, int], *, crop_scale: float = 1.5,
                 min_visibility: float = 0.5) -> tuple[np.ndarray, dict]:
    """Find a person without a given box and follow it: each frame is cropped around the previous
    frame's landmarks; where there are none (the first frame, or the person was lost) the frame's
    :func:`search_crops` are tried and the detection seen best is kept.

    Args:
        images: the frames, ``(H, W, 3)`` uint8, in order.
        detect: ``detect(image, crop) -> (33, 3)`` landmarks ``[x, y, visibility]`` in full-frame
            pixels of the square ``crop`` (:func:`square_crop`), NaN where nobody was found.
        image_size: ``(W, H)`` of the frames.

    Returns:
        ``(F, 33, 3)`` landmarks (NaN: not found) and counts: ``followed``, ``searched`` (frames
        that needed the tiles), ``found``.
    """
    W, H = image_size
    tiles = search_crops(W, H)
    out, prev = [], None
    counts = {"followed": 0, "searched": 0, "found": 0}
    for image in images:
        lm = np.full((33, 3), np.nan)
        if prev is not None:
            lm = detect(image, square_crop(prev, crop_scale))
            counts["followed"] += 1
        if box_from_landmarks(lm, min_visibility) is None:
            counts["searched"] += 1
            best, best_score = np.full((33, 3), np.nan), -1.0
            for crop in tiles:
                cand = detect(image, crop)
                if box_from_landmarks(cand, min_visibility) is not None:
                    score = float(np.nanmean(cand[:, 2]))
                    if score > best_score:
                        best, best_score = cand, score
            lm = best
        prev = box_from_landmarks(lm, min_visibility)
        counts["found"] += prev is not None
        out.append(lm)
    return (np.stack(out) if out else np.zeros((0, 33, 3))), counts
