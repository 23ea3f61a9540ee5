"""Cached backbone features of a still-frame dataset, and a dataset that serves them.

With a frozen, shared pretrained backbone (:mod:`airpose_lib.train.pretrain`) the variants of
the ablation differ only in their regressors, so the backbone runs once per crop instead of once
per crop and step: the features of every crop are computed once and the regressors train on them
(about a hundred times cheaper per step on a CPU).

A feature file is keyed by what made it: the backbone file's SHA-256, the dataset's manifest
(fingerprint and shard checksums), the split and the crops (jittered or tight). A change of any of
them gives another key, so stale features are never read.
"""
from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import torch
from torch.utils.data import DataLoader, Dataset

from airpose_lib.atomic import atomic_path
from airpose_lib.data.still.dataset import PER_VIEW_KEYS, StillFrameDataset, swap_views
from airpose_lib.data.still.manifest import load_manifest
from airpose_lib.data.still.shards import sha256_file
from airpose_lib.errors import ConfigError
from airpose_lib.folder_lock import file_lock
from airpose_lib.model.backbone import build_backbone
from airpose_lib.paths import cache_dir
from airpose_lib.progress import progress_bar

__all__ = ["feature_key", "features_path", "ensure_features", "compute_features", "FeatureDataset", "load_backbone_file"]

#: Bumped when the same inputs would give other features.
FEATURES_VERSION = 1


def load_backbone_file(path: str | Path) -> tuple[torch.nn.Module, dict]:
    """A pretrained backbone written by :func:`airpose_lib.train.pretrain.export_backbone`:
    ``(ResNet in eval mode, float32; its metadata)``."""
    blob = torch.load(Path(path), map_location="cpu", weights_only=True)
    meta = json.loads(blob["meta_json"])
    net = build_backbone(meta["backbone"])
    net.load_state_dict({k: v.float() for k, v in blob["state_dict"].items()})
    return net.eval(), meta


def _dataset_id(root: Path) -> dict:
    manifest = load_manifest(Path(root))
    return {"fingerprint": manifest.get("fingerprint"),
            "shards": [r.get("sha256") for r in manifest.get("shards", [])]}


def feature_key(backbone_file: str | Path, data_root: str | Path, split: str, crops: str,
                cut: str | None = None) -> str:
    """SHA-256 (first 16 hex digits) of everything the features depend on (``cut``: the block
    whose input they are; None, the pooled features, leaves the key of earlier versions)."""
    what = {"version": FEATURES_VERSION, "backbone": sha256_file(Path(backbone_file)),
            "data": _dataset_id(Path(data_root)), "split": split, "crops": crops}
    if cut is not None:
        what["cut"] = cut
    blob = json.dumps(what, sort_keys=True)
    return hashlib.sha256(blob.encode()).hexdigest()[:16]


def features_path(backbone_file: str | Path, data_root: str | Path, split: str, crops: str = "jittered",
                  cut: str | None = None) -> Path:
    """Where the feature file of these inputs lives (:func:`feature_key`), made or not:
    ``<kit cache>/features/<key>.npy``."""
    return cache_dir() / "features" / f"{feature_key(backbone_file, data_root, split, crops, cut)}.npy"


@torch.no_grad()
def compute_features(backbone: torch.nn.Module, dataset: StillFrameDataset, batch_size: int = 64,
                     progress: bool = False, cut: str | None = None,
                     device: str | torch.device = "cpu") -> np.ndarray:
    """Features of every crop of ``dataset`` (in order, no augmentation), float32: the pooled
    ``(N, V, C)``, or with ``cut`` the input of that block, ``(N, V, C, h, w)``; computed on
    ``device`` (a GPU's differ from the CPU's by float rounding only)."""
    backbone = backbone.to(device).eval()
    loader = DataLoader(dataset, batch_size=batch_size, shuffle=False)
    out = []
    for batch in progress_bar(loader, enabled=progress, desc="features"):
        x = batch["images"].to(device)
        B, V = x.shape[:2]
        f = backbone(x.flatten(0, 1)) if cut is None else backbone.forward_until(x.flatten(0, 1), cut)
        out.append(f.contiguous().reshape(B, V, *f.shape[1:]).cpu().numpy())
    return np.concatenate(out).astype(np.float32)


def ensure_features(backbone_file: str | Path, data_root: str | Path, split: str, crops: str = "jittered",
                    progress: bool = False, cut: str | None = None, device: str | torch.device = "cpu") -> Path:
    """The feature file of a dataset split (computed on first use, atomically, under a lock);
    ``cut`` and ``device`` as :func:`compute_features`.

    Returns ``<kit cache>/features/<key>.npy``.
    """
    path = features_path(backbone_file, data_root, split, crops, cut)
    with file_lock(path.with_suffix(".lock")):
        if not path.is_file():
            backbone, _ = load_backbone_file(backbone_file)
            ds = StillFrameDataset(data_root, split, augment=False, crops=crops)
            feats = compute_features(backbone, ds, progress=progress, cut=cut, device=device)
            with atomic_path(path) as tmp:
                with open(tmp, "wb") as f:
                    np.save(f, feats)
            (path.with_suffix(".json")).write_text(json.dumps(
                {"backbone_file": str(backbone_file), "data_root": str(data_root), "split": split,
                 "crops": crops, "cut": cut, "shape": list(feats.shape)}, indent=2))
    return path


class FeatureDataset(Dataset):
    """A still-frame split whose items carry backbone ``features (V, C)`` (or ``(V, C, h, w)``, the
    input of a block: :func:`compute_features`) instead of ``images``.

    Items hold every key of :class:`~airpose_lib.data.still.dataset.StillFrameDataset` but ``images``,
    plus ``features``; the view-swap augmentation permutes the features with the other per-view
    entries.

    Args:
        data_root: dataset folder; split / crops: as the feature file was made.
        features: the ``(N, V, C)`` array or its ``.npy`` path (:func:`ensure_features`).
        augment: random view permutation (default: train split).
        mirror: refused when true: the cached features are those of the stored crops, and a
            mirrored sample needs the features of the flipped crops (mirror in pretraining instead,
            a ``pretrain:`` stage's ``data: {mirror: true}``).
    """

    def __init__(self, data_root: str | Path, split: str, features: np.ndarray | str | Path, *,
                 crops: str = "jittered", augment: bool | None = None, mirror: bool = False) -> None:
        if mirror:
            raise ConfigError("data.mirror needs the crops, but the regressor task trains on features cached "
                              "from the stored crops; set mirror in a `pretrain:` stage's `data:` (or train the "
                              "supervised task)")
        # verified like any read of the shards (once per process): features cached from an intact
        # copy must never be served with labels read from a damaged one
        self.still = StillFrameDataset(data_root, split, augment=False, crops=crops)
        self.features = np.load(features, mmap_mode="r") if not isinstance(features, np.ndarray) else features
        if len(self.features) != len(self.still):
            raise ValueError(f"{len(self.features)} feature rows for {len(self.still)} samples of {data_root} "
                             f"({split}); the feature file belongs to another dataset")
        self.augment = (split == "train") if augment is None else bool(augment)
        self.crop_size = self.still.crop_size
        self.num_views = self.still.num_views

    def __len__(self) -> int:
        return len(self.still)

    def __getitem__(self, i: int) -> dict[str, torch.Tensor]:
        item = {"features": torch.from_numpy(np.array(self.features[i], dtype=np.float32)),
                **self.still.ground_truth(i)}
        item["crop_size"] = torch.tensor(self.crop_size, dtype=torch.int64)  # S of the crops behind P
        if self.augment:
            swap_views(item, ("features",) + tuple(k for k in PER_VIEW_KEYS if k != "images"))
        return item
