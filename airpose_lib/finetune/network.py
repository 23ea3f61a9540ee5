"""A trained network, the crop size and the camera it expects, from a kit training checkpoint.

Kit checkpoints (``airpose_lib.engine.checkpoint``) store the :class:`~airpose_lib.train.TrainConfig`
but not the crop size directly: it is the still-frame dataset's. :func:`checkpoint_input_size`
looks, in order, at the checkpoint's ``input_size`` (written by fine-tuning), ``config.data.crop_size``,
the manifest of ``config.data.root``, and the ``data: still: crop_size`` of the profile that made
the data (``config.data.profile`` or ``config.profile``). :func:`checkpoint_camera` finds the
training camera ``K_net`` the same way (the data's ``scene`` settings; default the paper's
f = 1475 px at 1920x1080): crops and P for any other camera are formed in that virtual camera
(``geometry.virtual_crop``).
"""
from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

__all__ = ["checkpoint_input_size", "checkpoint_camera", "load_network"]


def checkpoint_input_size(state: Mapping[str, Any]) -> int | None:
    """Crop side S of the network in a loaded checkpoint dict, or None if nothing says."""
    if state.get("input_size"):
        return int(state["input_size"])
    cfg = state.get("config") or {}
    data = cfg.get("data") or {}
    if data.get("crop_size"):
        return int(data["crop_size"])
    if data.get("root"):
        from airpose_lib.data.manifest import DatasetError, load_manifest

        try:
            manifest = load_manifest(Path(data["root"]))
        except (DatasetError, OSError, ValueError):
            manifest = None
        if manifest and manifest.get("crop_size"):
            return int(manifest["crop_size"])
    profile = data.get("profile") or cfg.get("profile")
    if profile:
        import yaml

        from airpose_lib.train.config import profile_path

        path = profile_path(profile)
        if path.is_file():
            still = ((yaml.safe_load(path.read_text()) or {}).get("data") or {}).get("still") or {}
            if still.get("crop_size"):
                return int(still["crop_size"])
    return None


def _data_scene(state: Mapping[str, Any]) -> dict:
    """The ``scene`` settings of the still-frame data a checkpoint was trained on ({} if unknown)."""
    cfg = state.get("config") or {}
    data = cfg.get("data") or {}
    if data.get("scene"):
        return dict(data["scene"])
    if data.get("root"):
        from airpose_lib.data.manifest import DatasetError, load_manifest

        try:
            manifest = load_manifest(Path(data["root"]))
        except (DatasetError, OSError, ValueError):
            manifest = None
        if manifest:
            return dict((manifest.get("config") or {}).get("scene") or {})
    profile = data.get("profile") or cfg.get("profile")
    if profile:
        import yaml

        from airpose_lib.train.config import profile_path

        path = profile_path(profile)
        if path.is_file():
            still = ((yaml.safe_load(path.read_text()) or {}).get("data") or {}).get("still") or {}
            return dict(still.get("scene") or {})
    return {}


def checkpoint_camera(state: Mapping[str, Any]) -> np.ndarray:
    """``(3, 3)`` intrinsics ``K_net`` of the camera a checkpoint's network was trained with.

    In order: the checkpoint's ``camera_K`` (written by fine-tuning), the ``image_size``,
    ``focal`` and ``principal_point`` of its still-frame data's ``scene`` settings, the defaults
    of :class:`~airpose_lib.data.scene.SceneConfig` (f = 1475 px, 1920x1080, the paper's).
    """
    from airpose_lib.data.scene import SceneConfig

    if state.get("camera_K") is not None:
        return np.asarray(state["camera_K"], np.float64).reshape(3, 3)
    scene = _data_scene(state)
    kw: dict[str, Any] = {}
    if scene.get("image_size"):
        kw["image_size"] = tuple(int(x) for x in scene["image_size"])
    if scene.get("focal"):
        kw["focal"] = float(scene["focal"])
    if scene.get("principal_point"):
        kw["principal_point"] = tuple(float(x) for x in scene["principal_point"])
    return SceneConfig(**kw).K


def load_network(checkpoint: str | Path, device: str | torch.device = "cpu",
                 input_size: int | None = None) -> tuple[nn.Module, Any, int]:
    """The network of a kit checkpoint (training or fine-tuning), in eval mode.

    Args:
        checkpoint: a ``checkpoints/*.pt`` of ``airpose train`` or ``airpose finetune``.
        device: where to put it.
        input_size: the crop size, when the checkpoint does not tell.

    Returns:
        ``(model, TrainConfig, input_size)``; ``model.input_size`` and ``model.camera_K`` (the
        training camera, :func:`checkpoint_camera`) are set too.

    Raises:
        FileNotFoundError: no such file. ValueError: the crop size is unknown (pass it).
    """
    from airpose_lib.engine.checkpoint import load_checkpoint
    from airpose_lib.train.evaluate import load_trained_model

    path = Path(checkpoint)
    if not path.is_file():
        raise FileNotFoundError(f"no checkpoint at {path}")
    state = load_checkpoint(path)
    size = input_size if input_size is not None else checkpoint_input_size(state)
    if size is None:
        raise ValueError(f"{path}: the checkpoint does not record its crop size (no input_size, config.data "
                         "crop_size, dataset manifest or profile); pass input_size")
    model, cfg = load_trained_model(path, device)
    model.input_size = int(size)
    model.camera_K = checkpoint_camera(state)
    return model, cfg, int(size)
