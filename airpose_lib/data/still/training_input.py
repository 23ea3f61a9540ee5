"""The crop size and camera of the still-frame data a training config names.

Checkpoints record their network's input (``model.record``); those written before the record
hold only the :class:`~airpose_lib.train.TrainConfig`, whose ``data`` settings name the data.
:func:`training_input` finds, in order, the crop size S in ``data.crop_size``, the manifest of
``data.root``, and the manifest of the default dataset folder of the profile such a config names
(``data.profile`` or ``profile``: the data the profile made, ``RunFolders.still``; no profile is
read); and the training camera ``K_net`` in the same places' ``scene`` settings, else
:class:`~.scene.SceneConfig`'s defaults (the paper's f = 1475 px at 1920x1080).
Training uses it to fill the record of a new checkpoint; readers pass it as ``legacy`` to
:func:`airpose_lib.model.record.read_network` for the old ones.
"""
from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from airpose_lib.paths import RunFolders

from .manifest import DatasetError, load_manifest
from .scene import SceneConfig

__all__ = ["training_input"]


def training_input(config: Mapping[str, Any]) -> tuple[int | None, np.ndarray]:
    """``(S or None, (3, 3) K_net)`` of the data a ``TrainConfig.to_dict()`` trained on."""
    data = config.get("data") or {}
    manifest = _manifest(data.get("root")) or _profile_manifest(data.get("profile") or config.get("profile"))
    size = data.get("crop_size") or (manifest or {}).get("crop_size")
    if data.get("scene"):
        scene = dict(data["scene"])
    else:
        scene = dict(((manifest or {}).get("config") or {}).get("scene") or {})
    return (int(size) if size else None), _camera(scene)


def _manifest(root: str | Path | None) -> dict | None:
    """The manifest of the dataset in ``root`` (None when there is none or it cannot be read)."""
    if not root:
        return None
    try:
        return load_manifest(Path(root))
    except (DatasetError, OSError, ValueError):
        return None


def _profile_manifest(name: str | None) -> dict | None:
    """The manifest of the dataset in the default folder of the profile an old config names
    (``name``: where its training generated the data when the config named no folder)."""
    return _manifest(RunFolders.of(name).still) if name else None


def _camera(scene: Mapping[str, Any]) -> np.ndarray:
    """``(3, 3)`` K of ``scene`` settings (``image_size``, ``focal``, ``principal_point``; the
    others keep :class:`SceneConfig`'s defaults)."""
    kw: dict[str, Any] = {}
    if scene.get("image_size"):
        kw["image_size"] = tuple(int(x) for x in scene["image_size"])
    if scene.get("focal"):
        kw["focal"] = float(scene["focal"])
    if scene.get("principal_point"):
        kw["principal_point"] = tuple(float(x) for x in scene["principal_point"])
    return SceneConfig(**kw).K
