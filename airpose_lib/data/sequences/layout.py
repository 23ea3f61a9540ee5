"""The official AirPose real-data layout: write generated sequences into it, read any sequence.

One loader serves the paper's real recordings and the kit's generated ones. Layout under a
sequence root (``machine_k`` = drone k, k = 1, 2, ...):

=================================== ===============================================================
``machine_k/images/%06d.jpg``       frames; the number is the frame index (shared by the machines)
``machine_k/openpose_res.pkl``      pickle: dict ``frame_index -> (num_persons, 25, 3)`` float
                                    array ``[x, y, conf]`` (BODY_25); person 0 is the subject; an
                                    empty ``(0, 25, 3)`` array = nobody detected
``machine_k/alphapose_res.json``    AlphaPose JSON list ``[{"image_id": "000123.jpg", "keypoints":
                                    [x, y, c] * 18, "score": s, "category_id": 1}, ...]`` (COCO-18);
                                    frames without a detection have no entry
``machine_k/camera_calib.yml``      OpenCV FileStorage with the 3x3 matrix ``K``
``machine_k/timestamps.csv``        kit addition: ``frame,timestamp`` (seconds) per frame
``ground_truth.npz``                kit addition: everything per frame (see
                                    :func:`airpose_lib.data.sequences.simulate_sequence`)
``sequence.json``                   kit addition: kit version, settings, motion script
=================================== ===============================================================

Reading (:func:`load_sequence`) conventions:

* Keypoints come back as ``(F, V, J, 3)`` float64 per detector; a missing keypoint, a frame
  without a detection and a NaN/inf value are all ``(0, 0, 0)`` (OpenPose's convention), so the
  arrays never contain NaN. ``Sequence.info`` counts what was zero-filled.
* AlphaPose: several entries for one image -> the one with the highest ``score``. OpenPose:
  person 0.
* Detector files come in the kit's formats (above) or the real-data release's per-frame dicts
  (:mod:`airpose_lib.data.official.real`); this module reads both (:func:`detections_format`).
* The machines must have the same frame indices (else :class:`SequenceFormatError`, naming both
  folders; ``strict=False`` keeps the common frames). An OpenPose file must have an entry for
  every frame read (it has one per processed frame); an AlphaPose file whose last entry is more
  than ``tail_tolerance`` frames before the last image is considered truncated. Both raise naming
  the file unless ``missing_detections="zero"``.
"""
from __future__ import annotations

import csv
import json
import math
import pickle
import re
import warnings
from collections.abc import Iterable, Mapping
from collections.abc import Sequence as SequenceABC
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from airpose_lib import (
    __version__,  # the package root holds only the version
    safe_pickle,
)
from airpose_lib.atomic import atomic_path
from airpose_lib.errors import UserError

__all__ = [
    "SequenceFormatError",
    "OfficialLayoutWriter",
    "LazyImages",
    "Sequence",
    "load_sequence",
    "read_camera_calib",
    "write_camera_calib",
    "DETECTOR_FILES",
    "detector_file_format",
    "detections_format",
    "read_official_openpose",
    "read_official_alphapose",
]

DETECTOR_FILES: dict[str, tuple[str, int]] = {"openpose": ("openpose_res.pkl", 25),
                                              "alphapose": ("alphapose_res.json", 18)}
"""Detector name -> (file name in ``machine_k/``, keypoints per person)."""

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
# Writer

class OfficialLayoutWriter:
    """Streams a sequence into the official layout.

    Example::

        w = OfficialLayoutWriter(root, num_views=2)
        for i, images in frames:            # images: [(H, W, 3) uint8 RGB per view]
            w.write_frame(i, images)
        w.finish(K, {"openpose": kp25, "alphapose": kp18}, timestamps, ground_truth, meta)

    Args:
        root: the sequence folder (created).
        num_views: number of machines.
        jpeg_quality: JPEG quality of the frames.
    """

    def __init__(self, root: str | Path, num_views: int, jpeg_quality: int = 92) -> None:
        self.root = Path(root)
        self.num_views = int(num_views)
        self.jpeg_quality = int(jpeg_quality)
        self.frames: list[int] = []
        self.image_sizes: list[tuple[int, int] | None] = [None] * self.num_views
        for v in range(self.num_views):
            (self.machine(v) / "images").mkdir(parents=True, exist_ok=True)

    def machine(self, view: int) -> Path:
        """Folder of view ``view`` (0-based): ``machine_{view + 1}``."""
        return self.root / f"machine_{view + 1}"

    def write_frame(self, index: int, images: SequenceABC[np.ndarray]) -> None:
        """Write one frame's images (RGB uint8 (H, W, 3), one per view)."""
        import cv2

        if len(images) != self.num_views:
            raise ValueError(f"frame {index}: {len(images)} images for {self.num_views} views")
        for v, img in enumerate(images):
            img = np.asarray(img)
            if img.dtype != np.uint8 or img.ndim != 3 or img.shape[2] != 3:
                raise ValueError(f"frame {index} view {v}: expected (H, W, 3) uint8 RGB, got {img.shape} {img.dtype}")
            ok, buf = cv2.imencode(".jpg", np.ascontiguousarray(img[..., ::-1]),
                                   [cv2.IMWRITE_JPEG_QUALITY, self.jpeg_quality])
            if not ok:
                raise RuntimeError(f"JPEG encoding failed for frame {index} view {v}")
            with atomic_path(self.machine(v) / "images" / f"{int(index):06d}.jpg") as tmp:
                tmp.write_bytes(buf.tobytes())
            self.image_sizes[v] = (img.shape[1], img.shape[0])
        self.frames.append(int(index))

    def finish(self, K: np.ndarray, keypoints: Mapping[str, np.ndarray], timestamps: np.ndarray | None = None,
               ground_truth: Mapping[str, np.ndarray] | None = None, meta: Mapping | None = None,
               frames: SequenceABC[int] | None = None) -> None:
        """Write calibration, detector files, time stamps, ground truth and metadata.

        Args:
            K: (V, 3, 3) intrinsics of the stored images.
            keypoints: detector name (``openpose`` / ``alphapose``) -> (F, V, J, 3) ``[x, y, c]``;
                a frame whose keypoints are all zero is written as "nobody detected".
            timestamps: (F, V) seconds, or None.
            ground_truth: arrays for ``ground_truth.npz``, or None.
            meta: JSON-able settings for ``sequence.json``.
            frames: the F frame indices (default: the frames written, in order).
        """
        frames = list(self.frames if frames is None else frames)
        F = len(frames)
        K = np.asarray(K, dtype=np.float64)
        if K.shape != (self.num_views, 3, 3):
            raise ValueError(f"K must be ({self.num_views}, 3, 3), got {K.shape}")
        for v in range(self.num_views):
            write_camera_calib(self.machine(v) / "camera_calib.yml", K[v], self.image_sizes[v])
        for name, kp in keypoints.items():
            if name not in DETECTOR_FILES:
                raise ValueError(f"unknown detector {name!r}; known: {tuple(DETECTOR_FILES)}")
            kp = np.asarray(kp, dtype=np.float64)
            J = DETECTOR_FILES[name][1]
            if kp.shape != (F, self.num_views, J, 3):
                raise ValueError(f"{name} keypoints must be ({F}, {self.num_views}, {J}, 3), got {kp.shape}")
            for v in range(self.num_views):
                if name == "openpose":
                    self._write_openpose(self.machine(v) / DETECTOR_FILES[name][0], frames, kp[:, v])
                else:
                    self._write_alphapose(self.machine(v) / DETECTOR_FILES[name][0], frames, kp[:, v])
        if timestamps is not None:
            ts = np.asarray(timestamps, dtype=np.float64)
            if ts.shape != (F, self.num_views):
                raise ValueError(f"timestamps must be ({F}, {self.num_views}), got {ts.shape}")
            for v in range(self.num_views):
                lines = ["frame,timestamp"] + [f"{i},{t:.9f}" for i, t in zip(frames, ts[:, v])]
                with atomic_path(self.machine(v) / "timestamps.csv") as tmp:
                    tmp.write_bytes(("\n".join(lines) + "\n").encode())
        if ground_truth is not None:
            tmp = self.root / "ground_truth.tmp.npz"
            np.savez_compressed(tmp, **{k: np.asarray(v) for k, v in ground_truth.items()})
            tmp.replace(self.root / "ground_truth.npz")
        info = {"kit_version": __version__, "num_frames": F, "num_views": self.num_views,
                "frames": [frames[0], frames[-1]] if frames else [], **(dict(meta) if meta else {})}
        with atomic_path(self.root / "sequence.json") as tmp:
            tmp.write_bytes(json.dumps(info, indent=1, default=_json_default).encode())

    @staticmethod
    def _write_openpose(path: Path, frames: list[int], kp: np.ndarray) -> None:
        res = {}
        for i, k in zip(frames, kp):
            res[int(i)] = k[None].astype(np.float32) if np.any(k[:, 2] > 0) else np.zeros((0, 25, 3), np.float32)
        with atomic_path(path) as tmp:
            tmp.write_bytes(pickle.dumps(res, protocol=4))

    @staticmethod
    def _write_alphapose(path: Path, frames: list[int], kp: np.ndarray) -> None:
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


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON serialisable: {type(o)}")


# ------------------------------------------------------------------------------------------
# Reader

class LazyImages(SequenceABC):
    """The frames of one view, read from disk on access (RGB uint8 (H, W, 3)).

    ``images[i]`` reads frame position ``i``; slices give a list. ``paths`` are the files.
    """

    def __init__(self, paths: SequenceABC[Path]) -> None:
        self.paths = list(paths)

    def __len__(self) -> int:
        return len(self.paths)

    def __getitem__(self, i):
        if isinstance(i, slice):
            return [self[k] for k in range(*i.indices(len(self)))]
        import cv2

        path = self.paths[i]
        img = cv2.imread(str(path), cv2.IMREAD_COLOR)
        if img is None:
            raise SequenceFormatError(f"cannot read image {path}")
        return img[..., ::-1].copy()

    def __repr__(self) -> str:
        return f"LazyImages({len(self)} frames)"


@dataclass
class Sequence:
    """A two-drone recording in memory (images stay on disk).

    Attributes:
        root: the sequence folder.
        frames: (F,) frame indices (the numbers in the image names).
        images: per view, a :class:`LazyImages` over the F frames.
        K: (V, 3, 3) intrinsics of the stored images.
        keypoints: detector name -> (F, V, J, 3) float64 ``[x, y, conf]``, missing = 0.
        timestamps: (F, V) seconds, or None (no ``timestamps.csv``).
        ground_truth: arrays of ``ground_truth.npz`` restricted to the F frames, or None.
        meta: ``sequence.json`` contents (empty for real data).
        info: per detector, what was zero-filled and the file format:
            ``{detector: {"missing_frames": n, "nan_keypoints": n, "format": "kit" | "official"}}``.
    """

    root: Path
    frames: np.ndarray
    images: list[LazyImages]
    K: np.ndarray
    keypoints: dict[str, np.ndarray]
    timestamps: np.ndarray | None = None
    ground_truth: dict[str, np.ndarray] | None = None
    meta: dict = field(default_factory=dict)
    info: dict = field(default_factory=dict)

    @property
    def num_frames(self) -> int:
        return int(len(self.frames))

    @property
    def num_views(self) -> int:
        return len(self.images)

    def image(self, i: int, view: int) -> np.ndarray:
        """RGB image (H, W, 3) of frame position ``i`` in ``view``."""
        return self.images[view][i]


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


def _frame_name(i: int) -> str:
    return f"{int(i):06d}"


def _lookup(table: Mapping, i: int):
    """Entry of frame ``i`` keyed ``"000123"``, ``"000123.jpg"`` or ``123``; None if absent."""
    for key in (_frame_name(i), f"{_frame_name(i)}.jpg", int(i), str(int(i))):
        if key in table:
            return table[key]
    return None


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


def _read_timestamps(path: Path, frames: np.ndarray) -> np.ndarray | None:
    if not path.is_file():
        return None
    table = {}
    with open(path, newline="") as fh:
        for n, row in enumerate(csv.reader(fh)):
            if n == 0 and row and not row[0].strip().lstrip("-").isdigit():
                continue  # header
            if len(row) < 2:
                continue
            try:
                table[int(row[0])] = float(row[1])
            except ValueError:
                raise SequenceFormatError(f"{path}: line {n + 1} is not `frame,timestamp`: {row}") from None
    absent = [int(i) for i in frames if int(i) not in table]
    if absent:
        raise SequenceFormatError(f"{path} has no time stamp for {len(absent)} frames (first: {absent[0]})")
    return np.array([table[int(i)] for i in frames])


def load_sequence(root: str | Path, frames: Iterable[int] | slice | None = None, *,
                  detectors: SequenceABC[str] = ("openpose", "alphapose"),
                  missing_detections: str = "error", strict: bool = True,
                  tail_tolerance: int = 30, ground_truth: bool = True) -> Sequence:
    """Read a sequence in the official layout (real or generated).

    Args:
        root: the sequence folder (holding ``machine_1``, ``machine_2``, ...).
        frames: frame indices to read (an iterable of image numbers), a slice over the sorted
            frame list, or None (all).
        detectors: which keypoint files to read (``openpose``, ``alphapose``); each must exist.
        missing_detections: ``"error"`` (default) or ``"zero"``: what to do with a detector file
            that is shorter than the image sequence (see the module doc).
        strict: the machines must hold the same frames; False keeps their common frames (warns).
        tail_tolerance: frames an AlphaPose file may end before the images (undetected tail).
        ground_truth: read ``ground_truth.npz`` when present.
    Returns:
        :class:`Sequence`.
    Raises:
        SequenceFormatError: naming the file at fault.
    """
    root = Path(root)
    if missing_detections not in ("error", "zero"):
        raise ValueError("missing_detections must be 'error' or 'zero'")
    machines = _machines(root)
    indices = [_image_index(m) for m in machines]
    common = set(indices[0])
    for m, idx in zip(machines[1:], indices[1:]):
        if set(idx) != set(indices[0]):
            msg = (f"{machines[0] / 'images'} has {len(indices[0])} frames and {m / 'images'} has "
                   f"{len(idx)}; {len(set(indices[0]) ^ set(idx))} frame numbers differ")
            if strict:
                raise SequenceFormatError(msg + " (strict=False keeps the common frames)")
            warnings.warn(msg + "; keeping the common frames", stacklevel=2)
        common &= set(idx)
    available = np.array(sorted(common), dtype=np.int64)
    if available.size == 0:
        raise SequenceFormatError(f"{root}: the machines have no frame in common")
    if frames is None:
        sel = available
    elif isinstance(frames, slice):
        sel = available[frames]
    else:
        sel = np.asarray(list(frames), dtype=np.int64).reshape(-1)
        unknown = np.setdiff1d(sel, available)
        if unknown.size:
            raise SequenceFormatError(f"{root}: requested frames not present in every machine, e.g. {unknown[:5].tolist()}")
    if sel.size == 0:
        raise SequenceFormatError(f"{root}: empty frame selection")

    images = [LazyImages([idx[int(i)] for i in sel]) for idx in indices]
    K = np.stack([read_camera_calib(m / "camera_calib.yml") for m in machines])
    keypoints, info = {}, {}
    last_image = int(available[-1])
    for name in detectors:
        if name not in DETECTOR_FILES:
            raise ValueError(f"unknown detector {name!r}; known: {tuple(DETECTOR_FILES)}")
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
                kp, st = (read_official_openpose if name == "openpose" else read_official_alphapose)(path, sel, data)
            elif name == "openpose":
                kp, st = _read_openpose(path, data, sel, missing_detections)
            else:
                kp, st = _read_alphapose(path, data, sel, last_image, missing_detections, tail_tolerance)
            per_view.append(kp)
            for k in stats:
                stats[k] += st[k]
        keypoints[name] = np.stack(per_view, axis=1)
        info[name] = {**stats, "format": formats.pop()}
    ts = [_read_timestamps(m / "timestamps.csv", sel) for m in machines]
    timestamps = np.stack(ts, axis=1) if all(t is not None for t in ts) else None

    gt = None
    gt_path = root / "ground_truth.npz"
    if ground_truth and gt_path.is_file():
        gt = _slice_ground_truth(gt_path, sel)
    meta = {}
    if (root / "sequence.json").is_file():
        try:
            meta = json.loads((root / "sequence.json").read_text())
        except json.JSONDecodeError as e:
            raise SequenceFormatError(f"cannot parse {root / 'sequence.json'}: {e}") from None
    return Sequence(root, sel, images, K, keypoints, timestamps, gt, meta, info)


def _slice_ground_truth(path: Path, sel: np.ndarray) -> dict[str, np.ndarray]:
    try:
        with np.load(path) as data:
            arrays = {k: data[k] for k in data.files}
    except Exception as e:
        raise SequenceFormatError(f"cannot read {path}: {e}") from None
    if "frame_index" not in arrays:
        raise SequenceFormatError(f"{path}: no `frame_index` array")
    fi = arrays["frame_index"]
    pos = {int(f): n for n, f in enumerate(fi)}
    missing = [int(i) for i in sel if int(i) not in pos]
    if missing:
        raise SequenceFormatError(f"{path} has no ground truth for {len(missing)} frames (first: {missing[0]})")
    rows = np.array([pos[int(i)] for i in sel])
    F = len(fi)
    # per-frame arrays have the frame count as their first dimension; the rest are constants
    return {k: (v[rows] if v.ndim >= 1 and v.shape[0] == F and k not in _CONSTANT_KEYS else v)
            for k, v in arrays.items()}


# Arrays of ground_truth.npz that are not per frame even if their first dimension happens to
# equal the frame count (e.g. a 2-frame sequence with 2 views).
_CONSTANT_KEYS = frozenset({"K", "K_full", "image_size", "time_offsets", "betas", "fps", "gender",
                            "render_scale"})
