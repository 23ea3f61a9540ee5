"""The official AirPose real-data release (``copenet_dji``): splits, detections, marker poses.

Layout (learned from the official repository robot-perception-group/AirPose,
``copenet_real/src/copenet_real/dsets/copenet_real.py``, which reads it, and
``copenet_real_data/scripts/prepare_copenet_dataset.py`` / ``dji_data_aruco_detecion.py``, which
made the calibration and the marker poses). One folder holds both drones' recordings::

    <root>/machine_{1,2}/images/%06d.jpg                frames, numbered alike on both drones
    <root>/machine_{1,2}/camera_calib.yml               OpenCV FileStorage, 3x3 matrix ``K``
    <root>/machine_{1,2}/openpose_res.pkl               see below
    <root>/machine_{1,2}/alphapose_res.json             see below
    <root>/machine_{1,2}/markerposes_corrected_all.pkl  ArUco board pose per frame

Splits: the official loader (``get_copenet_real_traintest``) trains on frames 0-6999 and tests
on frames 8000-14999 of that folder. The paper fine-tunes on person 1 and tests on person 2, so
person 1 is frames 0-6999 and person 2 frames 8000-14999 (:data:`REAL_DATA_SPLITS`,
:data:`PERSON_SPLITS`); frames 7000-7999 belong to neither.

Detection files in the release differ from the ones the kit's generator writes; the recording
reader (``load_sequence``) reads both, one reader per format in
:mod:`airpose_lib.data.sequences.detector_files`:

* ``openpose_res.pkl``: a dict ``"%06d" -> {"pose": (persons, 25, 3)}`` (BODY_25 ``[x, y, c]``;
  person 0 is the subject). The kit's files map the frame to the array directly.
* ``alphapose_res.json``: a dict ``"%06d" -> {"people": [{"pose_keypoints_2d": [x, y, c] * 18},
  ...]}`` (COCO-18, person 0). The kit's files are AlphaPose's own list format.

A frame without an entry is "not detected" (zeros), as the official loader treats it; the counts
are in ``Sequence.info``.

Marker poses (``markerposes_corrected_all.pkl``): a dict ``"%06d" -> {marker id (str) ->
{"rvec": (3,), "tvec": (3,)}}`` holding OpenCV's ``estimatePoseSingleMarkers`` output, i.e. the
marker -> camera transform ``x_cam = R(rvec) x_marker + tvec`` (metres). The official loader uses
marker ``"0"`` as the world frame of both drones; frames where it was not detected get the
identity rotation and zero translation there. (Its rotation is read by the position of the frame
in the sorted key list while its translation is read by frame number, which differ as soon as a
frame lacks a detection; :func:`read_marker_poses` reads both by frame number and returns a
validity mask instead.) The "corrected" values are the authors' post-processed ones; how they were
corrected is not in the repository.
"""
from __future__ import annotations

from collections.abc import Iterable, Mapping
from collections.abc import Sequence as SequenceABC
from pathlib import Path

import numpy as np

from airpose_lib import safe_pickle

from ..sequences.layout import SequenceFormatError, _frame_name, _image_index, _lookup, _machines
from ..sequences.marker_poses import MarkerPoses
from ..sequences.reader import Sequence, load_sequence

__all__ = [
    "REAL_DATA_SPLITS",
    "PERSON_SPLITS",
    "MARKER_POSES_FILE",
    "real_split_frames",
    "read_marker_poses",
    "load_marker_poses",
    "load_official_real",
]

#: Frame ranges of the paper's real-data splits (official ``get_copenet_real_traintest``).
REAL_DATA_SPLITS: dict[str, range] = {"train": range(0, 7000), "test": range(8000, 15000)}
#: Person -> split: the paper fine-tunes on person 1 and tests on person 2.
PERSON_SPLITS: dict[int, str] = {1: "train", 2: "test"}
#: File of the ArUco board poses in each ``machine_k`` folder.
MARKER_POSES_FILE = "markerposes_corrected_all.pkl"


def real_split_frames(split: str | None = None, person: int | None = None) -> range | None:
    """Frame range of a split (``"train"``, ``"test"``, ``"all"``/None) or a person (1, 2).

    Raises:
        ValueError: unknown split or person, or a person that contradicts the split.
    """
    if person is not None:
        if person not in PERSON_SPLITS:
            raise ValueError(f"person must be 1 or 2 (the release's two subjects), got {person!r}")
        if split not in (None, "all", PERSON_SPLITS[person]):
            raise ValueError(f"person {person} is the {PERSON_SPLITS[person]!r} split, not {split!r}")
        split = PERSON_SPLITS[person]
    if split in (None, "all"):
        return None
    if split not in REAL_DATA_SPLITS:
        raise ValueError(f"split must be 'train', 'test' or 'all', got {split!r}")
    return REAL_DATA_SPLITS[split]


def _load_pickle(path: Path):
    try:
        return safe_pickle.load(path)  # read-only; plain data only: a release file never runs code
    except FileNotFoundError:
        raise SequenceFormatError(f"missing file {path}") from None
    except Exception as e:  # noqa: BLE001 - any broken pickle
        raise SequenceFormatError(f"cannot read {path} (truncated or corrupted: {type(e).__name__}: {e})") from None


# -- marker poses -------------------------------------------------------------------------------
def read_marker_poses(path: Path | str, frames: Iterable[int], marker: str = "0"
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The ArUco marker -> camera pose per frame from ``markerposes_corrected_all.pkl``.

    Args:
        path: the file (see the module docstring).
        frames: frame numbers.
        marker: marker id (the official code uses ``"0"``).

    Returns:
        ``R (F, 3, 3)``, ``t (F, 3)`` (``x_cam = R x_marker + t``, metres; identity / zero where
        the marker was not detected) and ``valid (F,)`` bool.
    """
    import cv2

    path = Path(path)
    res = _load_pickle(path)
    if not isinstance(res, Mapping):
        raise SequenceFormatError(f"{path}: expected a dict '%06d' -> {{marker id: {{'rvec', 'tvec'}}}}")
    frames = [int(i) for i in frames]
    R = np.tile(np.eye(3), (len(frames), 1, 1))
    t = np.zeros((len(frames), 3))
    valid = np.zeros(len(frames), bool)
    for n, i in enumerate(frames):
        e = _lookup(res, i)
        m = e.get(str(marker), e.get(marker)) if isinstance(e, Mapping) else None
        if m is None:
            continue
        try:
            rvec = np.asarray(m["rvec"], dtype=np.float64).reshape(3)
            tvec = np.asarray(m["tvec"], dtype=np.float64).reshape(3)
        except (KeyError, TypeError, ValueError):
            raise SequenceFormatError(f"{path}: frame {_frame_name(i)} marker {marker!r} lacks 3-vectors "
                                      f"'rvec' and 'tvec'") from None
        if not (np.isfinite(rvec).all() and np.isfinite(tvec).all()):
            continue
        R[n] = cv2.Rodrigues(rvec)[0]
        t[n] = tvec
        valid[n] = True
    return R, t, valid


def load_marker_poses(root: Path | str, frames: Iterable[int], marker: str = "0",
                      num_views: int = 2) -> MarkerPoses:
    """Marker poses of ``machine_1 .. machine_<num_views>`` for ``frames``."""
    root = Path(root)
    frames = np.asarray([int(i) for i in frames], dtype=np.int64)
    parts = [read_marker_poses(root / f"machine_{v + 1}" / MARKER_POSES_FILE, frames, marker)
             for v in range(num_views)]
    return MarkerPoses(frames, np.stack([p[0] for p in parts], 1), np.stack([p[1] for p in parts], 1),
                       np.stack([p[2] for p in parts], 1))


# -- the recording ------------------------------------------------------------------------------
def load_official_real(root: Path | str, person: int | None = None, split: str | None = None, *,
                       frames: Iterable[int] | None = None,
                       detectors: SequenceABC[str] = ("openpose", "alphapose"),
                       missing_detections: str = "zero", strict: bool = True) -> Sequence:
    """A split of the real-data release as a :class:`~airpose_lib.data.sequences.reader.Sequence`.

    Images, calibration, time stamps and detections come from
    :func:`~airpose_lib.data.sequences.reader.load_sequence`, which reads the release's detection
    formats (``detector_files.read_official_openpose``, ``read_official_alphapose``) and the kit's.

    Args:
        root: the release folder (``machine_1``, ``machine_2``).
        person: 1 (frames 0-6999) or 2 (frames 8000-14999), or None.
        split: ``"train"``, ``"test"`` or ``"all"``/None (overridden by ``person``; they must agree).
        frames: explicit frame numbers instead of a split.
        detectors: which detection files to read.
        missing_detections: for kit-format files (``load_sequence``); release-format files always
            treat an absent frame as not detected.
        strict: both machines must hold the same frames.

    Returns:
        The Sequence of the split's frames present on disk; ``meta`` records ``source``,
        ``split``, ``person`` and each detector file's format; ``info[detector]`` counts the
        zero-filled frames and keypoints; ``info["missing_images"]`` counts frames of the range
        without an image.

    Raises:
        SequenceFormatError: no frame of the range on disk, or a malformed file (names it).
    """
    root = Path(root)
    rng = real_split_frames(split, person)
    wanted = set(int(i) for i in frames) if frames is not None else (set(rng) if rng is not None else None)
    sel = None
    if wanted is not None:
        machines = _machines(root)
        on_disk = set.intersection(*(set(_image_index(m)) for m in machines))
        sel = sorted(wanted & on_disk)
        if not sel:
            first, last = min(on_disk, default=-1), max(on_disk, default=-1)
            span = (f"frames {rng.start}-{rng.stop - 1}" if rng is not None and frames is None
                    else "the requested frames")
            raise SequenceFormatError(f"{root}: none of {span} is on disk (images go from {first} to {last})")
    # load_sequence reads the release's and the kit's detection formats alike, each file once.
    seq = load_sequence(root, sel, detectors=detectors, missing_detections=missing_detections, strict=strict,
                        ground_truth=False)
    seq.info["missing_images"] = len(wanted) - len(sel) if wanted is not None else 0
    fmt = {name: seq.info[name]["format"] for name in detectors}
    seq.meta = {**seq.meta, "source": "official_real", "split": split if person is None else PERSON_SPLITS[person],
                "person": person, "detector_formats": fmt}
    return seq
