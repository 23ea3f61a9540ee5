"""The detector files of a recording (``machine_k/openpose_res.pkl``,
``machine_k/alphapose_res.json``): one reader per format, the kit's writer.

Two formats per detector; :func:`detections_format` tells them apart on the parsed file:

========= ========== ========================================================== ============================
detector  format     content                                                    reader
========= ========== ========================================================== ============================
OpenPose  ``kit``    pickle: dict ``frame_index -> (persons, 25, 3)`` array      ``_read_openpose``
OpenPose  official   pickle: dict ``"%06d" -> {"pose": (persons, 25, 3)}``       :func:`read_official_openpose`
AlphaPose ``kit``    JSON list ``[{"image_id", "keypoints", "score"}, ...]``       ``_read_alphapose``
AlphaPose official   JSON dict ``"%06d" -> {"people": [{"pose_keypoints_2d"}]}``  :func:`read_official_alphapose`
========= ========== ========================================================== ============================

The kit's generator writes the ``kit`` formats (:func:`write_detector_file`): the detectors'
own outputs, in which a file shorter than the images is seen (an OpenPose file has an entry per
processed frame, an AlphaPose list ends early) and refused unless ``missing_detections="zero"``;
the release's dicts cannot tell a truncated file from undetected frames, and its readers count
absent frames as undetected, as the official loader does.
"""
from __future__ import annotations

import json
import math
import pickle
from collections.abc import Iterable, Mapping
from collections.abc import Sequence as SequenceABC
from pathlib import Path

import numpy as np

from airpose_lib import safe_pickle
from airpose_lib.atomic import atomic_path

from .layout import _FRAME_RE, DETECTOR_FILES, SequenceFormatError, _frame_key, _frame_name, _lookup

__all__ = ["detections_format", "detector_file_format", "read_detections", "read_official_openpose",
           "read_official_alphapose", "write_detector_file"]

_DETECTIONS_FIX = ("copy the recording's file again, or regenerate a kit recording with "
                   "`airpose data sequence --force`")
_MISSING_FIX = ("to treat them as undetected pass --allow-missing-detections (`airpose predict`; "
                "missing_detections='zero' in Python)")


def _load_detector_file(path: Path):
    """The parsed content of a detector file (JSON for ``.json``, else a pickle), read once."""
    try:
        if path.suffix == ".json":
            return json.loads(path.read_text())
        return safe_pickle.load(path)  # read-only; plain data only: a detector file never runs code
    except FileNotFoundError:
        raise SequenceFormatError(f"missing detector file {path}; {_DETECTIONS_FIX}") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise SequenceFormatError(f"cannot parse {path} (damaged or not a detector file: {e}); "
                                  f"{_DETECTIONS_FIX}") from None
    except Exception as e:  # noqa: BLE001 - a broken pickle
        raise SequenceFormatError(f"cannot read {path} (damaged or not a detector file: {type(e).__name__}: "
                                  f"{e}); {_DETECTIONS_FIX}") from None


def detections_format(data, json_file: bool = False) -> str:
    """``"official"`` (the release's per-frame dicts) or ``"kit"`` (the generator's formats) of a
    parsed detection file: the release keys both files by frame with a dict per frame; the kit
    writes frame -> array (OpenPose pickle) and a list of detections (AlphaPose JSON)."""
    if isinstance(data, Mapping):
        if json_file:
            return "official"
        first = next(iter(data.values()), None)
        if isinstance(first, Mapping):
            return "official"
    return "kit"


def detector_file_format(path: Path | str) -> str:
    """:func:`detections_format` of a file. Raises :class:`SequenceFormatError` if unreadable."""
    path = Path(path)
    return detections_format(_load_detector_file(path), json_file=path.suffix == ".json")


def _zero_bad(out: np.ndarray) -> int:
    bad = ~np.isfinite(out).all(-1)
    out[bad] = 0.0
    return int(bad.sum())


def _release_entries(path: Path, frames: Iterable[int], data, layout: str) -> list[tuple[int, object]]:
    """``(frame, entry or None)`` per frame of a release detection file (a dict ``"%06d" -> layout``)."""
    res = _load_detector_file(path) if data is None else data
    if not isinstance(res, Mapping):
        raise SequenceFormatError(f"{path}: expected a dict '%06d' -> {layout}")
    return [(int(i), _lookup(res, int(i))) for i in frames]


def read_official_openpose(path: Path | str, frames: Iterable[int], data=None) -> tuple[np.ndarray, dict]:
    """BODY_25 keypoints of person 0 from a release ``openpose_res.pkl``.

    Args:
        path: the file (dict ``"%06d" -> {"pose": (persons, 25, 3)}``).
        frames: frame numbers to read.
        data: the file's parsed content, if already read (``path`` then only names it in errors).

    Returns:
        ``(F, 25, 3)`` float64 ``[x, y, conf]`` (zeros: not detected) and
        ``{"missing_frames": n, "nan_keypoints": n}``.
    """
    path = Path(path)
    entries = _release_entries(path, frames, data, "{'pose': (persons, 25, 3)}")
    out = np.zeros((len(entries), 25, 3))
    missing = 0
    for n, (i, e) in enumerate(entries):
        pose = e.get("pose") if isinstance(e, Mapping) else e
        if pose is None:
            missing += 1
            continue
        arr = np.asarray(pose, dtype=np.float64)
        if arr.size == 0:
            missing += 1
            continue
        arr = arr[None] if arr.ndim == 2 else arr
        if arr.ndim != 3 or arr.shape[1:] != (25, 3):
            raise SequenceFormatError(f"{path}: frame {_frame_name(i)} has 'pose' of shape {arr.shape}, "
                                      f"expected (persons, 25, 3)")
        out[n] = arr[0]
    return out, {"missing_frames": missing, "nan_keypoints": _zero_bad(out)}


def read_official_alphapose(path: Path | str, frames: Iterable[int], data=None) -> tuple[np.ndarray, dict]:
    """COCO-18 keypoints of person 0 from a release ``alphapose_res.json``.

    Args:
        path: the file (dict ``"%06d" -> {"people": [{"pose_keypoints_2d": 54 numbers}, ...]}``).
        frames: frame numbers to read.
        data: the file's parsed content, if already read.

    Returns:
        ``(F, 18, 3)`` float64 (zeros: not detected) and the counts as
        :func:`read_official_openpose`.
    """
    path = Path(path)
    # Same loop as read_official_openpose over a different per-frame entry (people[0]'s flat
    # list, not a (persons, 25, 3) array): the two release formats share only their frame table.
    entries = _release_entries(path, frames, data, "{'people': [...]}")
    out = np.zeros((len(entries), 18, 3))
    missing = 0
    for n, (i, e) in enumerate(entries):
        people = e.get("people") if isinstance(e, Mapping) else None
        if not people:
            missing += 1
            continue
        try:
            kp = np.asarray(people[0]["pose_keypoints_2d"], dtype=np.float64)
        except (KeyError, TypeError, ValueError):
            raise SequenceFormatError(f"{path}: frame {_frame_name(i)} has no numeric "
                                      f"people[0]['pose_keypoints_2d']") from None
        if kp.size != 18 * 3:
            raise SequenceFormatError(f"{path}: frame {_frame_name(i)} has {kp.size} keypoint values, "
                                      f"expected 54 (COCO-18)")
        out[n] = kp.reshape(18, 3)
    return out, {"missing_frames": missing, "nan_keypoints": _zero_bad(out)}


def _read_openpose(path: Path, res, frames: np.ndarray, missing: str) -> tuple[np.ndarray, dict]:
    """The kit's ``openpose_res.pkl`` (parsed ``res``: frame -> (persons, 25, 3))."""
    if not isinstance(res, Mapping):
        raise SequenceFormatError(f"{path}: expected a dict frame_index -> (persons, 25, 3) array")
    try:
        res = {_frame_key(k): v for k, v in res.items()}
    except ValueError as e:
        raise SequenceFormatError(f"{path}: {e}") from None
    absent = [int(i) for i in frames if int(i) not in res]
    if absent and missing != "zero":
        have = sorted(res)
        span = f"frames {have[0]}..{have[-1]}" if have else "no frames"
        raise SequenceFormatError(
            f"{path} lacks {len(absent)} of the {len(frames)} frames read (first missing: {absent[0]}; "
            f"file has {span}); the detector file is shorter than the image sequence; {_MISSING_FIX}")
    out = np.zeros((len(frames), 25, 3))
    for n, i in enumerate(frames):
        arr = res.get(int(i))
        if arr is None or (isinstance(arr, (list, tuple)) and len(arr) == 0):
            continue
        arr = np.asarray(arr, dtype=np.float64)
        if arr.size == 0:
            continue
        if arr.ndim == 2:
            arr = arr[None]
        if arr.shape[1:] != (25, 3):
            raise SequenceFormatError(f"{path}: frame {i} has shape {arr.shape}, expected (persons, 25, 3)")
        out[n] = arr[0]
    return out, {"missing_frames": len(absent), "nan_keypoints": _zero_bad(out)}


def _read_alphapose(path: Path, entries, frames: np.ndarray, last_image: int, missing: str,
                    tail_tolerance: int) -> tuple[np.ndarray, dict]:
    """The kit's ``alphapose_res.json`` (parsed ``entries``: a list of detections)."""
    if not isinstance(entries, list):
        raise SequenceFormatError(f"{path}: expected a JSON list of detections")
    best: dict[int, tuple[float, list]] = {}
    for n, e in enumerate(entries):
        try:
            m = _FRAME_RE.match(Path(str(e["image_id"])).name)
            kp = e["keypoints"]
        except (KeyError, TypeError):
            raise SequenceFormatError(f"{path}: entry {n} lacks image_id/keypoints") from None
        if not m:
            raise SequenceFormatError(f"{path}: entry {n} has image_id {e['image_id']!r}, expected %06d.jpg")
        if len(kp) != 18 * 3:
            raise SequenceFormatError(f"{path}: entry {n} has {len(kp)} keypoint values, expected 54 (COCO-18)")
        score = e.get("score", 0.0)
        score = float(score) if score is not None and math.isfinite(float(score)) else -math.inf
        i = int(m.group(1))
        if i not in best or score > best[i][0]:
            best[i] = (score, kp)
    last = max(best) if best else -1
    if last < last_image - tail_tolerance and missing != "zero":
        raise SequenceFormatError(
            f"{path} ends at frame {last} but the images go to {last_image}: the detector file is "
            f"shorter than the image sequence; {_MISSING_FIX}")
    out = np.zeros((len(frames), 18, 3))
    absent = 0
    for n, i in enumerate(frames):
        hit = best.get(int(i))
        if hit is None:
            absent += 1
            continue
        out[n] = np.asarray(hit[1], dtype=np.float64).reshape(18, 3)
    return out, {"missing_frames": absent, "nan_keypoints": _zero_bad(out)}


def read_detections(root: Path, machines: SequenceABC[Path], name: str, sel: np.ndarray, last_image: int,
                    missing_detections: str, tail_tolerance: int) -> tuple[np.ndarray, dict]:
    """Keypoints of detector ``name`` on frames ``sel`` of every machine, whatever the files'
    format (all machines' files must be in one format).

    Args:
        root: the sequence folder (named in errors).
        machines: the V ``machine_k`` folders.
        name: ``openpose`` or ``alphapose``.
        sel: (F,) frame numbers to read.
        last_image: the last frame number of the images (a kit AlphaPose file that ends more than
            ``tail_tolerance`` frames before it is truncated).
        missing_detections: ``"error"`` or ``"zero"`` (see :func:`~.reader.load_sequence`).
        tail_tolerance: see ``last_image``.

    Returns:
        ``(F, V, J, 3)`` float64 ``[x, y, conf]`` (zeros: not detected) and
        ``{"missing_frames": n, "nan_keypoints": n, "format": "kit" | "official"}``.
    """
    if name not in DETECTOR_FILES:
        raise ValueError(f"unknown detector {name!r}; known: {tuple(DETECTOR_FILES)}")
    body25 = DETECTOR_FILES[name][1] == 25  # BODY_25 detectors share OpenPose's formats
    # The real-data release stores per-frame dicts; the kit's generator writes arrays.
    per_view, stats, formats = [], {"missing_frames": 0, "nan_keypoints": 0}, set()
    for m in machines:
        path = m / DETECTOR_FILES[name][0]
        data = _load_detector_file(path)
        formats.add(detections_format(data, json_file=path.suffix == ".json"))
        if len(formats) > 1:
            raise SequenceFormatError(f"{root}: the {DETECTOR_FILES[name][0]} files of the machines are in "
                                      "different formats (the release's and the kit's)")
        if formats == {"official"}:
            kp, st = (read_official_openpose if body25 else read_official_alphapose)(path, sel, data)
        elif body25:
            kp, st = _read_openpose(path, data, sel, missing_detections)
        else:
            kp, st = _read_alphapose(path, data, sel, last_image, missing_detections, tail_tolerance)
        per_view.append(kp)
        for k in stats:
            stats[k] += st[k]
    keypoints = np.stack(per_view, axis=1)
    info = {**stats, "format": formats.pop()}
    return keypoints, info


# ------------------------------------------------------------------------------------------
# The kit's formats, written

def write_detector_file(name: str, path: Path, frames: SequenceABC[int], kp: np.ndarray) -> None:
    """Write one machine's ``name`` file (a name of :data:`DETECTOR_FILES`) in the kit's format.

    Args:
        path: the file.
        frames: the F frame numbers.
        kp: (F, J, 3) ``[x, y, c]``; a frame whose confidences are all zero is "nobody detected".
    """
    body25 = DETECTOR_FILES[name][1] == 25  # BODY_25 detectors share OpenPose's pickle
    (_write_openpose if body25 else _write_alphapose)(path, list(frames), kp)


def _write_openpose(path: Path, frames: list[int], kp: np.ndarray) -> None:
    """The kit's ``openpose_res.pkl``: frame -> (1, 25, 3) float32, (0, 25, 3) if nobody was seen."""
    res = {}
    for i, k in zip(frames, kp):
        res[int(i)] = k[None].astype(np.float32) if np.any(k[:, 2] > 0) else np.zeros((0, 25, 3), np.float32)
    with atomic_path(path) as tmp:
        tmp.write_bytes(pickle.dumps(res, protocol=4))


def _write_alphapose(path: Path, frames: list[int], kp: np.ndarray) -> None:
    """The kit's ``alphapose_res.json``: AlphaPose's list, one entry per frame with a detection."""
    out = []
    for i, k in zip(frames, kp):
        c = k[:, 2]
        if not np.any(c > 0):
            continue
        out.append({"image_id": f"{int(i):06d}.jpg", "category_id": 1,
                    "keypoints": [round(float(x), 3) for x in k.reshape(-1)],
                    "score": round(float(c[c > 0].mean() * (c > 0).mean()), 4)})
    with atomic_path(path) as tmp:
        tmp.write_bytes(json.dumps(out).encode())
