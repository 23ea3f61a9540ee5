"""PyTorch dataset over generated still-frame shards.

``StillFrameDataset(root, split)`` returns, per sample, the dict the model and training code
agree on (``V`` views, crop side ``S``):

==============  =====================  ===========================================================
key             shape / dtype          meaning
==============  =====================  ===========================================================
images          (V, 3, S, S) float32   RGB / 255, ImageNet-normalised; bbox resized keeping aspect,
                                       black padding outside the box (geometry.crop_affine_matrix)
P               (V, 3) float32         ``[bx, by, s]`` = geometry.crop_vector(bbox, K, S)
K               (V, 3, 3) float32      full-frame intrinsics
bbox            (V, 4) float32         ``[x0, y0, x1, y1]`` of the crop, full-frame pixels
R_cw, t_cw      (V, 3, 3), (V, 3)      world -> camera extrinsics
phi, tau        (V, 3, 3), (V, 3)      root rotation / model-origin translation in each camera
theta           (21, 3) float32        body pose, axis-angle
beta            (10,) float32          shape
gender          () int64               0 neutral, 1 male, 2 female (ground-truth model)
j2d             (V, 22, 2) float32     22 body joints projected into the full frame
kp2d            (V, 25, 2) float32     BODY_25 keypoints in the full frame
kp_visible      (V, 25) bool           keypoint inside the frame
j3d_cam         (V, 22, 3) float32     22 body joints in each camera frame, metres
index           () int64               sample index in the dataset
==============  =====================  ===========================================================

``crops="tight"`` (test split only) gives the same samples with the tight-box crops instead of the
jittered ones (``P`` and ``bbox`` follow the crop; see ``GenerationConfig.test_crops``).

Training augmentation (``augment=True``, the default for the train split) permutes the views
(a swap for two views); every per-view field moves together, so the sample stays consistent.
With ``mirror=True`` it also mirrors half the samples left-right (:mod:`.mirror`: the crops'
columns flipped and every view's geometry, joints, root and pose mirrored with them).
Shards are checked against the manifest's SHA-256 when the dataset is opened.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
from torch.utils.data import Dataset

from airpose_lib.errors import ConfigError

from ..network_input import IMAGENET_MEAN, IMAGENET_STD, normalize
from .config import SPLITS
from .manifest import check_complete, verify_shard
from .mirror import mirror_sample
from .shards import ShardImages, read_shard

__all__ = ["StillFrameDataset", "split_arrays", "PER_VIEW_KEYS", "SAMPLE_KEYS", "EXTRA_KEYS",
           "normalize_images", "denormalize_images", "decode_image", "swap_views"]


#: Per-view entries of a sample (permuted together by the view-swap augmentation).
PER_VIEW_KEYS: tuple[str, ...] = ("images", "P", "K", "bbox", "R_cw", "t_cw", "phi", "tau",
                                  "j2d", "kp2d", "kp_visible", "j3d_cam")
#: All keys of a sample dict.
SAMPLE_KEYS: tuple[str, ...] = PER_VIEW_KEYS + ("theta", "beta", "gender", "index")

_FLOAT_KEYS = ("P", "K", "bbox", "R_cw", "t_cw", "phi", "tau", "j2d", "kp2d", "j3d_cam", "theta", "beta")
#: Stored with every sample besides the item's keys (world pose, cameras, tight box, scene draws),
#: for analysis and figures: see :attr:`StillFrameDataset.arrays`.
EXTRA_KEYS: tuple[str, ...] = ("R_wb", "t_wb", "heading", "cam_centre", "cam_distance", "cam_pitch",
                               "cam_azimuth", "bbox_tight", "attempt", "env_texture", "env_light_dir",
                               "env_light_intensity", "env_num_distractors", "skin_color")
_LOADED = _FLOAT_KEYS + ("kp_visible", "gender", "index", "image_offsets") + EXTRA_KEYS
_TIGHT = ("P_tight", "bbox_tight_crop", "image_offsets_tight")  # test shards only


def swap_views(item: dict[str, torch.Tensor], keys: tuple[str, ...] = PER_VIEW_KEYS) -> dict[str, torch.Tensor]:
    """The view-swap augmentation, in place: one random permutation of the views applied to every
    per-view entry (``keys``, default :data:`PER_VIEW_KEYS`, each ``(V, ...)``), so that a network
    cannot learn which view comes first (torch's RNG, seeded per sample by the training loop)."""
    V = item[keys[0]].shape[0]
    if V > 1:
        perm = torch.randperm(V)
        for k in keys:
            item[k] = item[k][perm]
    return item


def decode_image(data: bytes) -> np.ndarray:
    """Encoded JPEG/PNG bytes -> ``(S, S, 3)`` uint8 RGB."""
    import cv2

    img = cv2.imdecode(np.frombuffer(data, dtype=np.uint8), cv2.IMREAD_COLOR)
    if img is None:
        raise ValueError("could not decode an image of the shard (corrupted data)")
    return np.ascontiguousarray(img[..., ::-1])


def normalize_images(rgb: np.ndarray) -> torch.Tensor:
    """``(..., S, S, 3)`` uint8 RGB -> ``(..., 3, S, S)`` float32, /255 and ImageNet-normalised
    (``network_input.normalize``, the rule of the drones' crops)."""
    return torch.from_numpy(normalize(rgb))


def denormalize_images(x: torch.Tensor) -> np.ndarray:
    """Inverse of :func:`normalize_images`: ``(..., 3, S, S)`` -> ``(..., S, S, 3)`` uint8 (for figures)."""
    mean = torch.tensor(IMAGENET_MEAN).view(3, 1, 1)
    std = torch.tensor(IMAGENET_STD).view(3, 1, 1)
    rgb = (x.detach().cpu().float() * std + mean).clamp(0, 1).mul(255).round().to(torch.uint8)
    return rgb.movedim(-3, -1).numpy()


def _check_split(split: str) -> None:
    if split not in (*SPLITS, "all"):
        raise ConfigError(f"split must be one of {', '.join(SPLITS)} or 'all', got {split!r}")


def _split_records(manifest: dict, split: str) -> list[dict]:
    """The manifest's shard records of ``split`` (``"all"``: every one), in shard order."""
    return [r for r in manifest["shards"] if split == "all" or r["split"] == split]


def _joined(key: str, parts: list[np.ndarray]) -> np.ndarray:
    """One array of a split from its shards' parts; the float keys as float32, the items' dtype."""
    a = np.concatenate(parts)
    return a.astype(np.float32) if key in _FLOAT_KEYS else a


def split_arrays(root: Path | str, split: str, names: tuple[str, ...] | list[str],
                 max_samples: int | None = None, *, verify: bool = True) -> dict[str, np.ndarray]:
    """Some arrays of a split's first samples, reading (and verifying) only the shards that hold them.

    :attr:`StillFrameDataset.arrays` reads every shard of the split; a reader that needs a few
    arrays of a few samples (the stature model: ``beta`` and ``gender`` of 4,000 training subjects,
    20 of the ``cpu`` profile's 140 training shards) pays for those shards only.

    Args:
        root: dataset folder. split: as :class:`StillFrameDataset`. names: keys of
            :attr:`StillFrameDataset.arrays`. max_samples: the first this many (None: all).
    Returns:
        name -> ``(n, ...)``, typed as :attr:`StillFrameDataset.arrays` types it.
    Raises:
        as :class:`StillFrameDataset`; ConfigError for a name that is not a stored array.
    """
    unknown = sorted(n for n in names if n not in _LOADED or n == "image_offsets")
    if unknown:
        raise ConfigError(f"not arrays of a still-frame split: {', '.join(unknown)}")
    _check_split(split)
    root = Path(root)
    manifest = check_complete(root)
    parts: dict[str, list[np.ndarray]] = {k: [] for k in names}
    n = 0
    for rec in _split_records(manifest, split):
        if max_samples is not None and n >= max_samples:
            break
        path = verify_shard(root, rec, manifest) if verify else root / rec["file"]
        arrays = read_shard(path, list(names))
        for k in names:
            parts[k].append(arrays[k])
        n += len(arrays[names[0]])
    if not n:
        raise ConfigError(f"{root}: the {split!r} split is empty")
    return {k: _joined(k, v)[:max_samples] for k, v in parts.items()}


class StillFrameDataset(Dataset):
    """Multi-view still frames of a generated dataset (see the module docstring for the items).

    Args:
        root: dataset folder (with ``manifest.yaml`` and ``shard_*.npz``).
        split: ``"train"``, ``"val"``, ``"test"`` or ``"all"`` (a dataset generated before the
            validation split existed has no ``"val"`` shards: that split is then empty and refused).
        augment: random view permutation; default True for the train split, else False.
        mirror: with ``augment``, also mirror each sample with probability 1/2
            (:func:`~.mirror.mirror_sample`; torch's RNG, seeded per sample like the view swap).
            Off by default; no effect without ``augment`` (validation and test stay as stored).
        verify: check every shard's size and SHA-256 against the manifest when opening.
        crops: ``"jittered"`` (the stored crops) or ``"tight"`` (the tight-box crops that test
            shards also hold).

    Raises:
        DatasetError: no dataset, or an unfinished one (with the command that completes it).
        ShardIntegrityError: a shard is missing, truncated or altered (names the file and fix).
    """

    def __init__(self, root: Path | str, split: str = "train", augment: bool | None = None, *,
                 verify: bool = True, crops: str = "jittered", mirror: bool = False) -> None:
        _check_split(split)
        if crops not in ("jittered", "tight"):
            raise ConfigError(f"crops must be 'jittered' or 'tight', got {crops!r}")
        self.crops = crops
        self.root = Path(root)
        self.split = split
        self.augment = (split == "train") if augment is None else bool(augment)
        self.mirror = bool(mirror)
        self.manifest = check_complete(self.root)
        records = _split_records(self.manifest, split)
        self.num_views = int(self.manifest["num_views"])
        self.crop_size = int(self.manifest["crop_size"])
        parts: dict[str, list[np.ndarray]] = {k: [] for k in _LOADED}
        self._images: list[ShardImages] = []
        loc = []
        for s, rec in enumerate(records):
            path = verify_shard(self.root, rec, self.manifest) if verify else self.root / rec["file"]
            if crops == "tight":
                try:
                    arrays = read_shard(path, list(_LOADED) + list(_TIGHT))
                except KeyError:
                    raise ConfigError(f"{path}: no tight-box crops in this shard (only test shards of "
                                      "generator version 2 or later with tight_test_crops hold them)") from None
                arrays["P"], arrays["bbox"] = arrays.pop("P_tight"), arrays.pop("bbox_tight_crop")
                images = ShardImages(path, arrays.pop("image_offsets_tight"), member="images_tight")
            else:
                arrays = read_shard(path, list(_LOADED))
                images = ShardImages(path, arrays["image_offsets"])
            for k in _LOADED:
                if k != "image_offsets":
                    parts[k].append(arrays[k])
            self._images.append(images)
            n = len(arrays["index"])
            loc.append(np.stack([np.full(n, s), np.arange(n)], 1))
        if not loc:
            raise ConfigError(f"{self.root}: the {split!r} split is empty")
        self._loc = np.concatenate(loc).astype(np.int64)
        self._arrays = {k: _joined(k, parts[k]) for k in _LOADED if k != "image_offsets"}

    def __len__(self) -> int:
        return len(self._loc)

    @property
    def arrays(self) -> dict[str, np.ndarray]:
        """The split's arrays, one row per sample (no images): the item keys (float32) and
        :data:`EXTRA_KEYS` as stored (float64): world root pose ``R_wb (N, 3, 3)``, ``t_wb (N, 3)``
        and ``heading``, camera centres ``cam_centre (N, V, 3)``, distances and pitches, the
        tight boxes and the scene draws."""
        return self._arrays

    def rgb(self, i: int) -> np.ndarray:
        """The crops of sample ``i`` as stored: ``(V, S, S, 3)`` uint8 RGB."""
        s, j = self._loc[i]
        V = self.num_views
        return np.stack([decode_image(self._images[s].get(j * V + c)) for c in range(V)])

    def __getitem__(self, i: int) -> dict[str, torch.Tensor]:
        if not -len(self) <= i < len(self):
            raise IndexError(f"index {i} out of range for {len(self)} samples")
        i = i % len(self)
        item = {"images": normalize_images(self.rgb(i)), **self.ground_truth(i)}
        if self.augment:
            swap_views(item)
            # drawn after the swap, so that mirroring leaves the swap's draws as they were
            if self.mirror and bool(torch.rand(()) < 0.5):
                item = mirror_sample(item, self.crop_size)
        return item

    def ground_truth(self, i: int) -> dict[str, torch.Tensor]:
        """Every key of the item of sample ``i`` but ``images`` (no augmentation)."""
        a = self._arrays
        item = {k: torch.from_numpy(a[k][i].copy()) for k in
                ("P", "K", "bbox", "R_cw", "t_cw", "phi", "tau", "j2d", "kp2d", "j3d_cam", "theta", "beta",
                 "kp_visible")}
        item["gender"] = torch.tensor(int(a["gender"][i]), dtype=torch.int64)
        item["index"] = torch.tensor(int(a["index"][i]), dtype=torch.int64)
        return item

    def __repr__(self) -> str:
        return (f"StillFrameDataset({str(self.root)!r}, split={self.split!r}, n={len(self)}, "
                f"views={self.num_views}, S={self.crop_size}, augment={self.augment}, mirror={self.mirror}, "
                f"crops={self.crops!r})")
