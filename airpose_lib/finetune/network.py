"""A trained network, the crop size and the camera it expects, from a kit training checkpoint
(:func:`airpose_lib.train.evaluate.load_network`, with the crop size a caller may give).

The checkpoint's network record (:mod:`airpose_lib.model.record`) says both; for checkpoints
written before it, :func:`airpose_lib.data.still.training_input.training_input` reconstructs them from
the training config's data (its settings, the dataset's manifest, the profile). Crops and P for
any other camera are formed in the training camera ``K_net`` (``geometry.virtual_crop``).
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import torch
from torch import nn

from airpose_lib.errors import ConfigError
from airpose_lib.train.config import TrainConfig
from airpose_lib.train.evaluate import load_network

__all__ = ["load_sized_network"]


def load_sized_network(checkpoint: str | Path, device: str | torch.device = "cpu",
                       input_size: int | None = None) -> tuple[nn.Module, Any, int]:
    """The network of a kit checkpoint (training or fine-tuning), in eval mode.

    Args:
        checkpoint: a ``checkpoints/*.pt`` of ``airpose train`` or ``airpose finetune``.
        device: where to put it.
        input_size: the crop size, when the checkpoint does not tell.

    Returns:
        ``(model, TrainConfig, input_size)``; ``model.input_size`` and ``model.camera_K`` (the
        training camera of the record) are set too.

    Raises:
        FileNotFoundError: no such file. ValueError: the crop size is unknown (pass it).
    """
    path = Path(checkpoint)
    if not path.is_file():
        raise FileNotFoundError(f"no checkpoint at {path}")
    model, record, state = load_network(path, device)  # the file, read once
    size = input_size if input_size is not None else record.input_size
    if size is None:
        raise ConfigError(f"{path}: the checkpoint does not record its crop size (no network record, input_size, "
                          "config.data crop_size, dataset manifest or profile); pass --input-size (input_size=)")
    model.input_size = int(size)
    model.camera_K = record.camera_K
    return model, TrainConfig.from_dict(state["config"]), int(size)
