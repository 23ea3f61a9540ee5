"""A person's 2D keypoints per frame of a user's video, from a file: the kit's BODY_25 pickle
(``openpose_res.pkl``: ``{frame: (persons, 25, 3)}``, as in the official layout) or OpenPose's
``--write_json`` folder (one ``*_keypoints.json`` per frame, ``people[k].pose_keypoints_2d``).
Frame numbers are the video's own (0 = its first frame); person 0 is the subject.
"""
from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np

from airpose_lib import safe_pickle
from airpose_lib.errors import UserError

__all__ = ["KeypointsError", "read_keypoints", "keypoint_fraction"]

_FIX = ("give the kit's BODY_25 pickle {frame: (persons, 25, 3)} or OpenPose's --write_json folder, "
        "numbered by the video's own frames")


class KeypointsError(UserError, ValueError):
    """A keypoint file that cannot be read; the message names it."""


def _openpose_json_folder(folder: Path) -> dict[int, np.ndarray]:
    out = {}
    for p in folder.glob("*.json"):
        m = re.search(r"(\d+)(?:_keypoints)?\.json$", p.name)
        if not m:
            continue
        try:
            people = json.loads(p.read_text()).get("people", [])
        except (json.JSONDecodeError, UnicodeDecodeError, AttributeError) as e:
            raise KeypointsError(f"cannot parse {p} ({e}); {_FIX}") from None
        arr = [np.asarray(q.get("pose_keypoints_2d", []), dtype=np.float64).reshape(-1, 3) for q in people]
        arr = [a for a in arr if a.shape == (25, 3)]
        out[int(m.group(1))] = np.stack(arr) if arr else np.zeros((0, 25, 3))
    if not out:
        raise KeypointsError(f"{folder} holds no OpenPose *_keypoints.json files; {_FIX}")
    return out


def read_keypoints(path: str | Path, frames: np.ndarray) -> np.ndarray:
    """``(F, 25, 3)`` ``[x, y, confidence]`` of person 0 at the video frames ``frames``; zeros where
    the file has nobody or no entry.

    Raises:
        KeypointsError: unreadable or of another format (the message names the file).
    """
    path = Path(path)
    if path.is_dir():
        res = _openpose_json_folder(path)
    elif path.is_file():
        try:
            res = safe_pickle.load(path)
        except Exception as e:  # noqa: BLE001 - any broken pickle is the file's fault
            raise KeypointsError(f"cannot read {path} ({type(e).__name__}); {_FIX}") from None
        if not isinstance(res, dict):
            raise KeypointsError(f"{path}: expected a dict frame -> (persons, 25, 3); {_FIX}")
    else:
        raise KeypointsError(f"keypoints {path} do not exist; {_FIX}")
    out = np.zeros((len(frames), 25, 3))
    for n, i in enumerate(np.asarray(frames)):
        arr = res.get(int(i), res.get(str(int(i))))
        if arr is None:
            continue
        arr = np.asarray(arr, dtype=np.float64)
        if arr.size == 0:
            continue
        arr = arr[None] if arr.ndim == 2 else arr
        if arr.shape[1:] != (25, 3):
            raise KeypointsError(f"{path}: frame {int(i)} has shape {arr.shape}, expected (persons, 25, 3); {_FIX}")
        out[n] = np.nan_to_num(arr[0])
    return out


def keypoint_fraction(kp: np.ndarray, min_confidence: float = 0.2, min_joints: int = 6) -> float:
    """Share of frames with at least ``min_joints`` keypoints of confidence ``>= min_confidence``."""
    if len(kp) == 0:
        return 0.0
    return float(((kp[..., 2] >= min_confidence).sum(-1) >= min_joints).mean())
