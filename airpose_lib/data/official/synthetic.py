"""The official AirPose synthetic data (``copenet_synthetic``) as a kit dataset.

``OfficialSyntheticDataset(root, split)`` reads the authors' release and returns exactly the item
dict of :class:`airpose_lib.data.still.dataset.StillFrameDataset` (same keys, shapes, dtypes and
conventions), so training, evaluation and figures take either.

Layout (learned from the official repository robot-perception-group/AirPose:
``copenet/src/copenet/dsets/aerialpeople.py`` reads it,
``copenet_real_data/scripts/create_aerial_people_new.py`` wrote the per-sample files,
``copenet_real_data/scripts/prepare_aerialpeople.py`` cropped the images and made the split,
``copenet/src/copenet/scripts/prepare_aerialpeople_dataset.py`` rewrites the list files)::

    <root>/dataset/train_pkls.pkl        pickled list of per-sample pkl paths (the authors' absolute
    <root>/dataset/test_pkls.pkl         paths; the part after ``/dataset/`` is kept, see below)
    <root>/dataset/pkls/<subject>/<subject>_<pos>.pkl    one sample: a subject at one position
    <root>/data/<subject>/MyCamera<c>_<pos>.png           camera c's image of that sample

``root`` is the folder holding ``dataset/`` (the data root of the official code is the parent of
``dataset/``). A per-sample pkl is a dict with (shapes as written by the authors' script; a
leading axis of length 1 is accepted everywhere):

=============================== ================================================================
``smplpose``                    ``(1, 21, 3)`` body pose, axis-angle (SMPL-X body joints 1-21)
``smplshape``                   ``(1, 10)`` SMPL-X betas
``smplgender``                  ``"male"`` / ``"female"`` (anything else: neutral model)
``smpltrans``                   ``(1, 3)`` world translation of the SMPL-X **model origin**
``smplorient_rotmat_wrt_origin`` ``(1, 3, 3)`` world root rotation; ``V = R V0 + t``
``smpl_joints_wrt_origin``      ``(1, J, 3)`` world joints of the gendered SMPL-X model
``smpl_vertices_wrt_origin``    ``(1, N, 3)`` world vertices (not used here)
``cam<c>``                      ``{"extr": (4, 4) world -> camera, "intr": (3, 3)}``
``bb<c>``                       ``[[xmin, ymin], [xmax, ymax]]`` integer tight box: the first 23
                                projected joints +- 20 px, clipped to the 1920 x 1080 frame
``j2d<c>``                      ``(23, 2)`` those projected joints
``im<c>``                       image path relative to the data root
=============================== ================================================================

``smpltrans`` is the model-origin translation: the authors add ``pelvis - R pelvis`` to SMPL-X's
``transl`` before moving the body into the world, so the camera-frame root pose of view c is
``phi = R_cw R``, ``tau = R_cw smpltrans + t_cw`` (:func:`airpose_lib.geometry.body_in_camera`),
the kit's convention.

Images. The release stores each camera image **pre-cropped** to the tight box grown by 200 px on
every side and clipped to the frame (``prepare_aerialpeople.py``): a stored image covers full-frame
columns ``max(xmin - 200, 0) .. min(xmax + 200, 1920)`` (same for rows). The loader accepts that
size or a full 1920 x 1080 frame (the uncropped renders), and rejects anything else.

Crops (the network input), as the official loader (``copenet/dsets/aerialpeople.py`` at the
official HEAD): each side of the tight box grows by a whole number of pixels drawn uniformly from
``1 .. m``, where ``m`` is that side's margin in the pre-cropped image (200 px, less where the
frame edge is nearer; no growth where the box touches it) -- the official code keeps
``m - randint(m)`` pixels of the margin (:func:`official_growth`). The official loader does this
for every split, unseeded; here the training split jitters by default and the test split uses the
tight box unless ``jitter=True`` (:func:`airpose_lib.train.official.official_ablation` evaluates
the authors' networks on ``K`` seeded jitter draws, ``jitter_seed``, and on the tight crops). The box is resized
keeping its aspect ratio and padded with black, centred, to ``input_size`` (the official
``resize_with_pad`` of ``copenet/src/copenet/utils/utils.py``). The kit resamples with the exact affine map of
:func:`airpose_lib.geometry.crop_affine_matrix` (integer pixel centres, bilinear), so ``P``, the
crop and the joints agree to floating-point precision; the official code resizes an integer pixel
window (up to one pixel of difference from rounding). The pkl's box numbers are used as
full-frame coordinates as they are.

Ground-truth joints. By default (``joints="pkl"``) the 3D joints are the pkl's
``smpl_joints_wrt_origin`` moved into each camera: they come from the gendered **SMPL-X** model the
betas belong to, exactly what the authors trained and evaluated with. ``joints="model"`` evaluates
the kit's body model (``body_source``) with the sample's gender, betas and pose instead, as the
kit's own generator does; this is only meaningful with ``body_source="smplx"`` (the open body's
shape space is not SMPL-X's, so SMPL-X betas put its joints elsewhere than the rendered person).
The 2D joints are always the 3D joints projected with the pkl's intrinsics (the official loader
also reprojects instead of reading ``j2d<c>``). BODY_25 keypoints assume the pkl's joints follow
the ``smplx`` package order (55 skeleton joints, then the 21 keypoint vertices).

Views: the official loader uses cameras 0 and 1 (the renders have 4); ``views=(0, 1)``.

Split: the list files by default. Without them (or ``split_by="subjects"``) the authors' rule of
``prepare_aerialpeople.py``: subjects are the second ``_``-separated field of the
``dataset/pkls/<subject>`` folder names, sorted; the last 10 are the test split. Note that the
official ``prepare_aerialpeople_dataset.py`` wrote the *training* list into ``test_pkls.pkl`` until
its commit afd33f9 (16 Dec 2021, the official HEAD writes the test list); a test list equal to the
training list is refused with that explanation.

Besides the items, :meth:`OfficialSyntheticDataset.rgb` gives the uint8 crops and
:meth:`OfficialSyntheticDataset.arrays_for` the ground-truth arrays of chosen samples (the
counterparts of ``StillFrameDataset.rgb`` / ``.arrays``, which the figures use).

All files are opened read-only; nothing under ``root`` is ever written.
"""
from __future__ import annotations

import pickle
from collections.abc import Mapping, Sequence
from pathlib import Path, PurePosixPath

import numpy as np
import torch
from torch.utils.data import Dataset

from airpose_lib import safe_pickle
from airpose_lib.body import BODY_25_FROM_SMPLX, load_body_model
from airpose_lib.body.forward import rest_body
from airpose_lib.body.genders import GENDER_CODES
from airpose_lib.geometry import body_in_camera, crop_affine_matrix, crop_from_image, crop_vector, project_points

from ..still.dataset import normalize_images, swap_views
from ..still.manifest import DatasetError
from ..still.scene import points_in_frame

__all__ = [
    "OfficialDataError",
    "OfficialSyntheticDataset",
    "OFFICIAL_FRAME_SIZE",
    "OFFICIAL_CROP_MARGIN",
    "read_official_sample",
    "remap_official_path",
    "official_split_files",
    "subject_of",
    "stored_image_box",
    "crop_image",
    "official_growth",
]

#: Full frame of the synthetic renders, ``(W, H)`` pixels.
OFFICIAL_FRAME_SIZE: tuple[int, int] = (1920, 1080)
#: Margin (px) of the pre-cropped release images and of the training jitter.
OFFICIAL_CROP_MARGIN = 200

_LIST_FILES = {"train": "train_pkls.pkl", "test": "test_pkls.pkl"}
_REQUIRED = ("smplpose", "smplshape", "smplgender", "smpltrans", "smplorient_rotmat_wrt_origin")
_RELEASE_HINT = "re-extract it from the official copenet_synthetic archive"


class OfficialDataError(DatasetError):
    """The official data on disk is missing, damaged or not in the official layout (names the file)."""


# -- paths --------------------------------------------------------------------------------------
def remap_official_path(entry: str, root: Path, anchor: str = "dataset") -> Path:
    """Map a path written on the authors' machine to ``root``.

    The official list files hold absolute paths such as
    ``/home/<user>/.../agora_copenet_uniform_new_cropped/dataset/pkls/<subject>/<file>.pkl``; the
    part after the last ``/<anchor>/`` component is kept and put under ``root / anchor``.

    Args:
        entry: the stored path (POSIX or Windows separators).
        root: the local data root (holding ``dataset/`` and ``data/``).
        anchor: the folder name to cut at (``"dataset"`` for pkls, ``"data"`` for images).

    Raises:
        OfficialDataError: no ``anchor`` component in ``entry``.
    """
    parts = PurePosixPath(str(entry).replace("\\", "/")).parts
    hits = [i for i, p in enumerate(parts) if p == anchor]
    if not hits:
        raise OfficialDataError(f"path {entry!r} has no '{anchor}/' component, so it cannot be mapped under "
                                f"{root}; the list file is not in the official format")
    return Path(root, anchor, *parts[hits[-1] + 1:])


def subject_of(pkl_path: Path) -> str:
    """Subject id of a sample: the second ``_`` field of its ``pkls/<subject>`` folder (the
    authors' split key in ``prepare_aerialpeople.py``), or the whole folder name without ``_``."""
    folder = Path(pkl_path).parent.name
    fields = folder.split("_")
    return fields[1] if len(fields) > 1 else folder


def _load_pickle(path: Path, what: str):
    try:
        return safe_pickle.load(path)  # read-only; plain data only: a sample file never runs code
    except FileNotFoundError:
        raise OfficialDataError(f"missing {what} {path}; {_RELEASE_HINT}") from None
    except (EOFError, pickle.UnpicklingError, ValueError, TypeError, AttributeError, ImportError,
            IndexError, MemoryError) as e:
        raise OfficialDataError(f"cannot read {what} {path} (truncated or corrupted pickle: "
                                f"{type(e).__name__}: {e}); {_RELEASE_HINT}") from None


#: Training subjects of the official release held out as the validation split.
VAL_SUBJECTS = 2


def official_split_files(root: Path | str, split: str, split_by: str = "auto",
                         num_test_subjects: int = 10, num_val_subjects: int = VAL_SUBJECTS) -> list[Path]:
    """Per-sample pkl paths of a split, mapped under ``root``.

    The release has a training and a test split only. ``"val"`` (where every choice is made, so
    that the test split is read only for the reported table) is the last ``num_val_subjects``
    subjects of the training split, and ``"train"`` is then the rest of it.

    Args:
        root: the folder holding ``dataset/``.
        split: ``"train"``, ``"val"``, ``"test"`` or ``"all"``.
        split_by: ``"lists"`` (``dataset/{train,test}_pkls.pkl``), ``"subjects"`` (the last
            ``num_test_subjects`` subjects are the test split) or ``"auto"`` (lists if both exist).
        num_test_subjects: test subjects for ``split_by="subjects"`` (10 in the paper).
        num_val_subjects: training subjects held out as the validation split (0, or not fewer
            than the training split has: no validation split, ``"train"`` is the authors' whole
            training split).

    Raises:
        OfficialDataError: no ``dataset/`` folder, missing or unreadable list file, a listed pkl
            that does not exist, a test list equal to the training list, an empty split.
    """
    root = Path(root)
    ds = root / "dataset"
    if not ds.is_dir():
        raise OfficialDataError(f"{root} has no dataset/ folder: pass the folder that holds dataset/ and data/ "
                                f"(the extracted copenet_synthetic archive)")
    if split not in ("train", "val", "test", "all"):
        raise ValueError(f"split must be 'train', 'val', 'test' or 'all', got {split!r}")
    if split_by not in ("auto", "lists", "subjects"):
        raise ValueError(f"split_by must be 'auto', 'lists' or 'subjects', got {split_by!r}")
    have_lists = all((ds / f).is_file() for f in _LIST_FILES.values())
    if split_by == "lists" or (split_by == "auto" and have_lists):
        lists = {}
        for name, fname in _LIST_FILES.items():
            entries = _load_pickle(ds / fname, "list file")
            if not isinstance(entries, (list, tuple)) or not all(isinstance(e, str) for e in entries):
                raise OfficialDataError(f"{ds / fname}: expected a pickled list of pkl paths")
            lists[name] = [remap_official_path(e, root) for e in entries]
        if lists["train"] and lists["train"] == lists["test"]:
            raise OfficialDataError(
                f"{ds / 'test_pkls.pkl'} lists exactly the training samples (the official "
                f"prepare_aerialpeople_dataset.py wrote the train list into it before its fix afd33f9 of "
                f"16 Dec 2021); run that script of the official HEAD again, or pass split_by='subjects' "
                f"(--set data.split_by=subjects) to split by the authors' rule (last 10 subjects are the test split)")
        files = lists["train"] + lists["test"] if split == "all" else lists["train" if split == "val" else split]
    else:
        files_all = sorted((ds / "pkls").glob("*/*.pkl"))
        if not files_all:
            raise OfficialDataError(f"{ds / 'pkls'} holds no <subject>/<sample>.pkl files; {_RELEASE_HINT}")
        subjects = sorted({subject_of(f) for f in files_all})
        test = set(subjects[-num_test_subjects:]) if num_test_subjects > 0 else set()
        files = [f for f in files_all if split == "all" or (subject_of(f) in test) == (split == "test")]
    subjects = sorted({subject_of(f) for f in files})
    if split in ("train", "val") and 0 < num_val_subjects < len(subjects):  # some training subjects stay
        held = set(subjects[-num_val_subjects:])
        files = [f for f in files if (subject_of(f) in held) == (split == "val")]
    elif split == "val":
        files = []  # no validation split: refused below
    if not files:
        raise OfficialDataError(f"{root}: the {split!r} split is empty")
    missing = [f for f in files if not f.is_file()]
    if missing:
        raise OfficialDataError(f"{len(missing)} of the {len(files)} {split!r} samples listed are missing, e.g. "
                                f"{missing[0]}; {_RELEASE_HINT} (dataset/pkls must be complete)")
    return files


# -- one sample ---------------------------------------------------------------------------------
def _array(d: Mapping, key: str, shape: tuple[int, ...], path: Path) -> np.ndarray:
    """``d[key]`` as float64 of ``shape`` (leading axes of length 1 dropped)."""
    try:
        a = np.asarray(d[key], dtype=np.float64)
    except KeyError:
        raise OfficialDataError(f"{path} lacks {key!r}; {_RELEASE_HINT}") from None
    except (TypeError, ValueError):
        raise OfficialDataError(f"{path}: {key!r} is not numeric; {_RELEASE_HINT}") from None
    while a.ndim > len(shape) and a.shape[0] == 1:
        a = a[0]
    if a.shape != shape and not (len(shape) == 1 and a.size == shape[0]):
        raise OfficialDataError(f"{path}: {key!r} has shape {a.shape}, expected {shape}; {_RELEASE_HINT}")
    return a.reshape(shape)


def read_official_sample(path: Path | str, views: Sequence[int] = (0, 1)) -> dict:
    """One per-sample pkl, validated, as float64 numpy arrays.

    Returns:
        dict with ``theta (21, 3)``, ``beta (10,)``, ``gender`` (str), ``R_wb (3, 3)``,
        ``t_wb (3,)``, ``joints_w (J, 3)`` or None, ``K (V, 3, 3)``, ``R_cw (V, 3, 3)``,
        ``t_cw (V, 3)``, ``bb (V, 4)`` ``[xmin, ymin, xmax, ymax]``, ``im`` (list of V str).

    Raises:
        OfficialDataError: unreadable file, missing key or wrong shape (names the file).
    """
    path = Path(path)
    d = _load_pickle(path, "sample")
    if not isinstance(d, Mapping):
        raise OfficialDataError(f"{path}: expected a dict per sample, got {type(d).__name__}; {_RELEASE_HINT}")
    for k in _REQUIRED:
        if k not in d:
            raise OfficialDataError(f"{path} lacks {k!r}; {_RELEASE_HINT}")
    out = {
        "theta": _array(d, "smplpose", (21, 3), path),
        "beta": _array(d, "smplshape", (10,), path),
        "gender": str(d["smplgender"]),
        "R_wb": _array(d, "smplorient_rotmat_wrt_origin", (3, 3), path),
        "t_wb": _array(d, "smpltrans", (3,), path),
        "joints_w": None,
    }
    if "smpl_joints_wrt_origin" in d:
        j = np.asarray(d["smpl_joints_wrt_origin"], dtype=np.float64)
        j = j[0] if j.ndim == 3 and j.shape[0] == 1 else j
        if j.ndim != 2 or j.shape[1] != 3 or j.shape[0] < 22:
            raise OfficialDataError(f"{path}: 'smpl_joints_wrt_origin' has shape {j.shape}, expected (J >= 22, 3)")
        out["joints_w"] = j
    K, R, t, bb, im = [], [], [], [], []
    for c in views:
        cam = d.get(f"cam{c}")
        if not isinstance(cam, Mapping) or "extr" not in cam or "intr" not in cam:
            raise OfficialDataError(f"{path} lacks camera {c} ('cam{c}' with 'extr' and 'intr'); {_RELEASE_HINT}")
        E = _array(cam, "extr", (4, 4), path)
        K.append(_array(cam, "intr", (3, 3), path))
        R.append(E[:3, :3])
        t.append(E[:3, 3])
        box = _array(d, f"bb{c}", (2, 2), path)
        bb.append([box[0, 0], box[0, 1], box[1, 0], box[1, 1]])
        if f"im{c}" not in d:
            raise OfficialDataError(f"{path} lacks 'im{c}'; {_RELEASE_HINT}")
        im.append(str(d[f"im{c}"]))
    out.update(K=np.stack(K), R_cw=np.stack(R), t_cw=np.stack(t), bb=np.asarray(bb, np.float64), im=im)
    return out


def stored_image_box(bb: np.ndarray, frame_size: tuple[int, int] = OFFICIAL_FRAME_SIZE,
                     margin: int = OFFICIAL_CROP_MARGIN) -> tuple[int, int, int, int]:
    """Full-frame pixel window ``(x0, y0, x1, y1)`` (end exclusive) of a pre-cropped release image.

    The tight box ``bb (4,)`` grown by ``margin`` on every side and clipped to the frame, in
    integers as ``prepare_aerialpeople.py`` cut it.
    """
    W, H = frame_size
    x0, y0, x1, y1 = (int(v) for v in bb)
    return max(x0 - margin, 0), max(y0 - margin, 0), min(x1 + margin, W), min(y1 + margin, H)


def official_growth(margins: np.ndarray, rng) -> np.ndarray:
    """Pixels each side of the tight box grows by, as the official loader draws them: ``margins``
    ``(4,)`` whole pixels available per side (left, top, right, bottom); side ``k`` keeps
    ``m - randint(m)``, uniform on ``1 .. m`` (``0`` when ``m == 0``). ``rng``: ``np.random`` or a
    ``numpy.random.Generator``."""
    m = np.maximum(np.asarray(margins, np.int64), 0)
    draw = rng.integers if isinstance(rng, np.random.Generator) else rng.randint
    return np.array([k - draw(k) if k > 0 else 0 for k in m], np.int64)


def crop_image(image: np.ndarray, offset: tuple[float, float], bbox: np.ndarray, size: int) -> np.ndarray:
    """The network input of a box: resize keeping aspect, black outside the box, centred.

    Args:
        image: ``(h, w, 3)`` uint8, whose pixel ``(row i, col j)`` is the full-frame pixel
            ``(offset[0] + j, offset[1] + i)`` (integer pixel centres).
        offset: ``(ox, oy)`` full-frame position of the image's pixel (0, 0).
        bbox: ``(4,)`` crop box ``[x0, y0, x1, y1]`` in full-frame pixels.
        size: crop side S.

    Returns:
        ``(S, S, 3)`` uint8: :func:`airpose_lib.geometry.crop_from_image` of the box (bilinear, black
        outside the box by the rule the kit's own data use).
    """
    A = crop_affine_matrix(torch.as_tensor(bbox, dtype=torch.float64), size).numpy()
    M = A @ np.array([[1.0, 0.0, offset[0]], [0.0, 1.0, offset[1]], [0.0, 0.0, 1.0]])
    return crop_from_image(image, M, bbox, size)


# -- the dataset --------------------------------------------------------------------------------
class OfficialSyntheticDataset(Dataset):
    """The official synthetic release, items as :class:`~airpose_lib.data.still.dataset.StillFrameDataset`.

    Args:
        root: the folder holding ``dataset/`` and ``data/``.
        split: ``"train"``, ``"val"``, ``"test"`` or ``"all"``.
        augment: random view permutation (the official random camera swap); default True for the
            train split.
        input_size: crop side S (224 in the paper).
        jitter: grow each side of the box as the official loader (:func:`official_growth`, at most
            ``jitter_px``); default True for the train split (the official loader jitters every
            split: pass True to match it).
        jitter_px: the maximum growth per side (200 px).
        jitter_seed: draw the growth of sample ``i``, view ``v`` from
            ``numpy.random.default_rng([jitter_seed, i, v])`` (one reproducible draw of the test
            crops per seed); None: numpy's global RNG (seeded per sample in training).
        views: which of the sample's cameras, in order (the official loader: 0 and 1).
        split_by: ``"auto"``, ``"lists"`` or ``"subjects"`` (:func:`official_split_files`).
        num_test_subjects: test subjects for ``split_by="subjects"``.
        num_val_subjects: training subjects held out as ``"val"`` (:func:`official_split_files`).
        joints: ``"pkl"`` (default) or ``"model"`` (see the module docstring).
        body_source: body model for ``joints="model"`` (``"smplx"`` for the official data).
        frame_size: ``(W, H)`` of the full frame (1920 x 1080).

    Raises:
        OfficialDataError: missing ``dataset/`` folder, list or sample files (at construction);
            an unreadable sample, a missing image or an image of the wrong size (on access).
            Every message names the file and what to do.
    """

    def __init__(self, root: Path | str, split: str = "train", augment: bool | None = None,
                 input_size: int = 224, *, jitter: bool | None = None, jitter_px: float = OFFICIAL_CROP_MARGIN,
                 jitter_seed: int | None = None,
                 views: Sequence[int] = (0, 1), split_by: str = "auto", num_test_subjects: int = 10,
                 num_val_subjects: int = VAL_SUBJECTS,
                 joints: str = "pkl", body_source: str = "smplx",
                 frame_size: tuple[int, int] = OFFICIAL_FRAME_SIZE) -> None:
        if joints not in ("pkl", "model"):
            raise ValueError(f"joints must be 'pkl' or 'model', got {joints!r}")
        if input_size < 8:
            raise ValueError(f"input_size too small: {input_size}")
        self.root = Path(root)
        self.split = split
        self.files = official_split_files(self.root, split, split_by, num_test_subjects, num_val_subjects)
        self.augment = (split == "train") if augment is None else bool(augment)
        self.jitter = (split == "train") if jitter is None else bool(jitter)
        self.jitter_px = float(jitter_px)
        self.jitter_seed = jitter_seed
        self.views = tuple(int(v) for v in views)
        self.num_views = len(self.views)
        self.crop_size = int(input_size)
        self.joints = joints
        self.body_source = body_source
        self.frame_size = (int(frame_size[0]), int(frame_size[1]))
        self._models: dict = {}

        self._body25 = np.asarray(BODY_25_FROM_SMPLX)

    def __len__(self) -> int:
        return len(self.files)

    # -- pieces -----------------------------------------------------------------------------
    def image_path(self, pkl: Path, entry: str, view: int) -> Path:
        """Where image ``entry`` (the pkl's ``im<c>``) of sample ``pkl`` is on disk.

        Tried in order: ``entry`` under the data root; its part after ``/data/`` (absolute author
        paths); ``data/<pkl folder>/MyCamera<c>_<pos>.png`` (the cropped release's naming).
        """
        cands = [self.root / entry]
        try:
            cands.append(remap_official_path(entry, self.root, "data"))
        except OfficialDataError:
            pass
        pos = pkl.stem.rsplit("_", 1)[-1]
        cands.append(self.root / "data" / pkl.parent.name / f"MyCamera{view}_{pos}.png")
        for c in cands:
            if c.is_file():
                return c
        raise OfficialDataError(f"missing image for camera {view} of {pkl}: looked for "
                                f"{', '.join(str(c) for c in dict.fromkeys(cands))}; {_RELEASE_HINT} "
                                f"(data/ must sit next to dataset/)")

    def load_image(self, pkl: Path, sample: dict, v: int) -> tuple[np.ndarray, tuple[int, int]]:
        """View ``v``'s stored image (RGB uint8) and the full-frame offset of its pixel (0, 0)."""
        import cv2

        path = self.image_path(pkl, sample["im"][v], self.views[v])
        img = cv2.imread(str(path), cv2.IMREAD_COLOR)  # read-only
        if img is None:
            raise OfficialDataError(f"cannot decode image {path} (truncated or not an image); {_RELEASE_HINT}")
        h, w = img.shape[:2]
        W, H = self.frame_size
        x0, y0, x1, y1 = stored_image_box(sample["bb"][v], self.frame_size, OFFICIAL_CROP_MARGIN)
        if (w, h) == (W, H):
            offset = (0, 0)
        elif (w, h) == (x1 - x0, y1 - y0):
            offset = (x0, y0)
        else:
            raise OfficialDataError(
                f"image {path} is {w}x{h} px; expected the full {W}x{H} frame or the official pre-cropped "
                f"{x1 - x0}x{y1 - y0} window of box {sample['bb'][v].astype(int).tolist()} in {pkl} "
                f"(tight box + {OFFICIAL_CROP_MARGIN} px); data/ and dataset/ come from different releases "
                f"or the image was altered: {_RELEASE_HINT}")
        return np.ascontiguousarray(img[..., ::-1]), offset

    def crop_box(self, tight: np.ndarray, offset: tuple[int, int], shape: tuple[int, ...], rng=np.random
                 ) -> np.ndarray:
        """The crop box ``(4,)``: the tight box, grown per side as the official loader when
        jittering (:func:`official_growth` over the margins to the stored image's edges, at most
        ``jitter_px``), clipped to the stored image (integer pixel centres: it spans
        ``[o - 0.5, o + n - 0.5]``)."""
        box = np.asarray(tight, np.float64).copy()
        lo = np.array([offset[0], offset[1]], np.float64) - 0.5
        hi = lo + np.array([shape[1], shape[0]], np.float64)
        if self.jitter and self.jitter_px > 0:
            room = np.r_[box[:2] - lo, hi - box[2:]]  # pixels between the box and the image's edges
            margins = np.minimum(np.floor(room + 1e-9), self.jitter_px)
            box += official_growth(margins, rng) * np.array([-1.0, -1.0, 1.0, 1.0])
        return np.clip(box, np.r_[lo, lo], np.r_[hi, hi])

    def model_joints(self, sample: dict) -> np.ndarray:
        """World joints ``(76, 3)`` from the body model (``joints="model"``): ``R_wb J0 + t_wb``."""
        g = sample["gender"].lower()
        g = g if g in ("male", "female") else "neutral"
        if g not in self._models:
            self._models[g] = load_body_model(self.body_source, g, dtype=torch.float64)
        _, j0 = rest_body(self._models[g], sample["beta"][None], sample["theta"][None], mesh=False)
        return j0[0] @ sample["R_wb"].T + sample["t_wb"]

    # -- the item ---------------------------------------------------------------------------
    def _index(self, i: int) -> int:
        if not -len(self) <= i < len(self):
            raise IndexError(f"index {i} out of range for {len(self)} samples")
        return i % len(self)

    def sample_arrays(self, i: int, images: bool = True) -> dict[str, np.ndarray]:
        """Sample ``i`` in camera order, before the view permutation, as numpy arrays.

        The item's keys except ``images`` (float64; ``kp_visible`` bool, ``gender`` and ``index``
        int), plus ``R_wb (3, 3)``, ``t_wb (3,)`` (world root pose), ``bbox_tight (V, 4)`` and,
        with ``images``, ``rgb (V, S, S, 3)`` uint8 crops. Without ``images`` no image is read and
        ``bbox`` / ``P`` are those of the tight box (no jitter).
        """
        i = self._index(i)
        pkl = self.files[i]
        s = read_official_sample(pkl, self.views)
        V, S = self.num_views, self.crop_size
        T = lambda a: torch.as_tensor(np.asarray(a), dtype=torch.float64)  # noqa: E731

        joints_w = s["joints_w"] if self.joints == "pkl" else self.model_joints(s)
        if joints_w is None:
            raise OfficialDataError(f"{pkl} has no 'smpl_joints_wrt_origin'; use joints='model' with "
                                    f"body_source='smplx' to compute them")
        phi, tau = (x.numpy() for x in body_in_camera(T(s["R_wb"]), T(s["t_wb"]), T(s["R_cw"]), T(s["t_cw"])))
        jc = joints_w[None] @ s["R_cw"].transpose(0, 2, 1) + s["t_cw"][:, None]  # (V, J, 3)
        uv = project_points(T(jc), T(s["K"])).numpy()  # (V, J, 2)

        out: dict[str, np.ndarray] = {}
        if images:
            crops, boxes = [], []
            for v in range(V):
                img, offset = self.load_image(pkl, s, v)
                rng = np.random if self.jitter_seed is None else np.random.default_rng([self.jitter_seed, i, v])
                box = self.crop_box(s["bb"][v], offset, img.shape, rng)
                boxes.append(box)
                crops.append(crop_image(img, offset, box, S))
            out["rgb"] = np.stack(crops)
            bbox = np.stack(boxes)
        else:
            bbox = s["bb"].copy()
        P = crop_vector(T(bbox), T(s["K"]), S).numpy()

        kp_idx = self._body25
        ok = (kp_idx >= 0) & (kp_idx < jc.shape[1])
        safe = np.where(ok, kp_idx, 0)
        kp2d = np.where(ok[None, :, None], uv[:, safe], np.nan)
        kp_z = np.where(ok[None], jc[:, safe, 2], -1.0)
        out.update({
            "P": P, "K": s["K"], "bbox": bbox, "R_cw": s["R_cw"], "t_cw": s["t_cw"], "phi": phi, "tau": tau,
            "j2d": uv[:, :22], "kp2d": kp2d, "kp_visible": ok[None] & points_in_frame(kp2d, kp_z, self.frame_size),
            "j3d_cam": jc[:, :22], "theta": s["theta"], "beta": s["beta"],
            "gender": np.int64(GENDER_CODES.get(s["gender"].lower(), 0)), "index": np.int64(i),
            "R_wb": s["R_wb"], "t_wb": s["t_wb"], "bbox_tight": s["bb"],
        })
        return out

    def rgb(self, i: int) -> np.ndarray:
        """The crops of sample ``i``: ``(V, S, S, 3)`` uint8 RGB in camera order (random boxes
        when jittering)."""
        return self.sample_arrays(i)["rgb"]

    def arrays_for(self, indices) -> dict[str, np.ndarray]:
        """:meth:`sample_arrays` (no images, tight boxes) of several samples, stacked: the
        counterpart of ``StillFrameDataset.arrays`` for a subset (reading every pkl of the
        release for all rows would take long)."""
        rows = [self.sample_arrays(int(i), images=False) for i in indices]
        return {k: np.stack([r[k] for r in rows]) for k in rows[0]}

    def __getitem__(self, i: int) -> dict[str, torch.Tensor]:
        a = self.sample_arrays(i)
        f32 = lambda x: torch.from_numpy(np.ascontiguousarray(x, dtype=np.float32))  # noqa: E731
        item = {"images": normalize_images(a["rgb"])}
        for k in ("P", "K", "bbox", "R_cw", "t_cw", "phi", "tau", "j2d", "kp2d"):
            item[k] = f32(a[k])
        item["kp_visible"] = torch.from_numpy(np.ascontiguousarray(a["kp_visible"]))
        for k in ("j3d_cam", "theta", "beta"):
            item[k] = f32(a[k])
        item["gender"] = torch.tensor(int(a["gender"]), dtype=torch.int64)
        item["index"] = torch.tensor(int(a["index"]), dtype=torch.int64)
        if self.augment:
            swap_views(item)
        return item

    def __repr__(self) -> str:
        return (f"OfficialSyntheticDataset({str(self.root)!r}, split={self.split!r}, n={len(self)}, "
                f"views={self.views}, S={self.crop_size}, augment={self.augment}, jitter={self.jitter}, "
                f"joints={self.joints!r})")
