"""Reads a recording in the folder layout (:mod:`.layout`), kit or real: :func:`load_sequence`.
One reader serves the paper's real recordings and the kit's generated ones.

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
import hashlib
import json
import warnings
from collections.abc import Iterable
from collections.abc import Sequence as SequenceABC
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .detector_files import read_detections
from .layout import SequenceFormatError, _image_index, _machines, read_camera_calib

__all__ = ["LazyImages", "Sequence", "load_sequence", "recording_fingerprint"]


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
        detectors: which keypoint files to read (names of :data:`DETECTOR_FILES`); each must exist.
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
        keypoints[name], info[name] = read_detections(root, machines, name, sel, last_image, missing_detections,
                                                      tail_tolerance)
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


def recording_fingerprint(seq: Sequence) -> str:
    """SHA-256 of what a recording gives a method: its frame numbers, the bytes of every image of
    those frames, the intrinsics, each detector's keypoints and the ground truth (when present).

    Content, not file dates: a re-rendered recording with other pixels (e.g. markers added on
    the ground) changes it, a copied one does not. About 1 s per GB of images.
    """
    h = hashlib.sha256(json.dumps({"frames": np.asarray(seq.frames).tolist(),
                                   "views": [len(v) for v in seq.images]}).encode())
    for view in seq.images:
        for path in view.paths:
            h.update(Path(path).read_bytes())
    h.update(np.ascontiguousarray(seq.K, np.float64).tobytes())
    arrays = {f"kp/{k}": v for k, v in seq.keypoints.items()}
    arrays.update({f"gt/{k}": v for k, v in (seq.ground_truth or {}).items()})
    for name in sorted(arrays):
        a = np.asarray(arrays[name])
        h.update(f"{name}:{a.dtype}:{a.shape}".encode())
        if a.dtype != object:
            h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()
