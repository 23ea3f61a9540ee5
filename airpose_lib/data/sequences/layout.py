"""The folder layout of every recording, the kit's and the paper's (the official AirPose
real-data layout): which file holds what, the frame names, the camera calibration.

Layout under a sequence root (``machine_k`` = drone k, k = 1, 2, ...):

=================================== ===============================================================
``machine_k/images/%06d.jpg``       frames; the number is the frame index (shared by the machines)
``machine_k/openpose_res.pkl``      pickle: dict ``frame_index -> (num_persons, 25, 3)`` float
                                    array ``[x, y, conf]`` (BODY_25); person 0 is the subject; an
                                    empty ``(0, 25, 3)`` array = nobody detected
``machine_k/alphapose_res.json``    AlphaPose JSON list ``[{"image_id": "000123.jpg", "keypoints":
                                    [x, y, c] * 18, "score": s, "category_id": 1}, ...]`` (COCO-18);
                                    frames without a detection have no entry
``machine_k/mediapipe_res.pkl``     optional, kit addition: MediaPipe Pose as BODY_25, in the
                                    ``openpose_res.pkl`` format (``scripts/mediapipe_detect.py``)
``machine_k/camera_calib.yml``      OpenCV FileStorage with the 3x3 matrix ``K``
``machine_k/timestamps.csv``        kit addition: ``frame,timestamp`` (seconds) per frame
``ground_truth.npz``                kit addition: everything per frame (see
                                    :func:`airpose_lib.data.sequences.simulate_sequence`)
``sequence.json``                   kit addition: kit version, settings, motion script
=================================== ===============================================================

The detector files are also accepted in the real-data release's per-frame dicts
(:mod:`.detector_files`, one reader per format). :mod:`.writer` writes a recording
(:class:`~.writer.OfficialLayoutWriter`); :mod:`.reader` reads one, kit or real
(:func:`~.reader.load_sequence`).
"""
from __future__ import annotations

import re
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from airpose_lib.errors import UserError

__all__ = ["SequenceFormatError", "DETECTOR_FILES", "read_camera_calib", "write_camera_calib"]

DETECTOR_FILES: dict[str, tuple[str, int]] = {"openpose": ("openpose_res.pkl", 25),
                                              "alphapose": ("alphapose_res.json", 18),
                                              "mediapipe": ("mediapipe_res.pkl", 25)}
"""Detector name -> (file name in ``machine_k/``, keypoints per person). A 25-keypoint file is
in the OpenPose pickle format; ``mediapipe`` is MediaPipe Pose mapped onto BODY_25
(:mod:`airpose_lib.data.sequences.mediapipe_pose`, written by ``scripts/mediapipe_detect.py``)."""

_FRAME_RE = re.compile(r"^(\d+)\.(jpg|jpeg|png)$", re.IGNORECASE)


class SequenceFormatError(UserError, ValueError):
    """A sequence folder does not follow the layout; the message names the offending file."""


# ------------------------------------------------------------------------------------------
# Camera calibration (OpenCV FileStorage)

def write_camera_calib(path: str | Path, K: np.ndarray, image_size: tuple[int, int] | None = None) -> None:
    """Write ``K`` (3, 3) (and optionally ``image_width``/``image_height``) as OpenCV YAML."""
    import cv2

    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    try:
        fs.write("K", np.asarray(K, dtype=np.float64))
        if image_size is not None:
            fs.write("image_width", int(image_size[0]))
            fs.write("image_height", int(image_size[1]))
    finally:
        fs.release()


def read_camera_calib(path: str | Path) -> np.ndarray:
    """``K`` (3, 3) float64 from an OpenCV FileStorage file."""
    import cv2

    path = Path(path)
    if not path.is_file():
        raise SequenceFormatError(f"missing camera calibration {path}")
    try:
        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    except cv2.error as e:
        raise SequenceFormatError(f"cannot parse camera calibration {path}: {e}") from None
    try:
        node = fs.getNode("K")
        K = None if node.empty() else node.mat()
    finally:
        fs.release()
    if K is None or np.shape(K) != (3, 3) or not np.isfinite(K).all():
        raise SequenceFormatError(f"{path}: no finite 3x3 matrix `K`")
    return np.asarray(K, dtype=np.float64)

# ------------------------------------------------------------------------------------------
# Machine folders and frame names

def _machines(root: Path) -> list[Path]:
    if not root.is_dir():
        raise SequenceFormatError(f"sequence folder {root} does not exist")
    found = []
    for p in root.iterdir():
        m = re.fullmatch(r"machine_(\d+)", p.name)
        if m and p.is_dir():
            found.append((int(m.group(1)), p))
    if not found:
        raise SequenceFormatError(f"{root}: no machine_1, machine_2, ... folders")
    found.sort()
    numbers = [n for n, _ in found]
    if numbers != list(range(1, len(numbers) + 1)):
        raise SequenceFormatError(f"{root}: machine folders must be machine_1..machine_N, found {numbers}")
    return [p for _, p in found]


def _image_index(machine: Path) -> dict[int, Path]:
    folder = machine / "images"
    if not folder.is_dir():
        raise SequenceFormatError(f"missing image folder {folder}")
    out = {}
    for p in folder.iterdir():
        m = _FRAME_RE.match(p.name)
        if m:
            out[int(m.group(1))] = p
    if not out:
        raise SequenceFormatError(f"empty sequence: no %06d.jpg images in {folder}")
    return out


def _frame_key(key) -> int:
    """A detector file's frame key -> frame index: 123, "123", "000123" or "000123.jpg"."""
    if isinstance(key, (int, np.integer)):
        return int(key)
    name = Path(str(key)).name
    m = re.fullmatch(r"(\d+)(\.(jpg|jpeg|png))?", name, flags=re.IGNORECASE)
    if not m:
        raise ValueError(f"frame key {key!r} is neither a number nor a %06d.jpg name")
    return int(m.group(1))


def _frame_name(i: int) -> str:
    return f"{int(i):06d}"


def _lookup(table: Mapping, i: int):
    """Entry of frame ``i`` keyed ``"000123"``, ``"000123.jpg"`` or ``123``; None if absent."""
    for key in (_frame_name(i), f"{_frame_name(i)}.jpg", int(i), str(int(i))):
        if key in table:
            return table[key]
    return None
