"""What a checkpoint says about its network: enough to rebuild the network and form its input.

Every training and fine-tuning checkpoint holds ``state["network"]`` (plain types, loadable with
``weights_only=True``):

=================  ===============================================================================
``version``        1
``variant``        ``baseline``, ``multiview``, ``fullcam`` or ``airpose``
``backbone``       ``resnet18`` / ``resnet34`` / ``resnet50``
``model``          the other keyword arguments of :func:`~airpose_lib.model.build_model`
``input_size``     crop side S in pixels
``normalisation``  ``"imagenet"``: RGB / 255, then the ImageNet mean and std per channel
                   (``data.still.dataset.normalize_images``, ``data.network_input.crop_input``)
``camera_rule``    ``"virtual_crop"``: the crop and P of a box seen by a camera K are formed in
                   the virtual camera ``camera_K`` (``geometry.virtual_crop``)
``camera_K``       ``(3, 3)`` intrinsics ``K_net`` of the training camera, nested lists
=================  ===============================================================================

:func:`read_network` reads it back; :func:`network_from_checkpoint` makes the network of a
checkpoint (every loader: ``train.evaluate.load_network``, the drones' ``runtime.backends``). Checkpoints written before the record (the kit's earlier
runs, tests' fixtures) hold only the training config and, from fine-tuning, ``input_size`` and
``camera_K``; for them the caller passes ``legacy``, which reconstructs the crop size and camera
from the config's data (``data.still.training_input.training_input``: the data settings, the dataset's
manifest, the profile). ``model`` may not import ``data``, hence the argument.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from torch import nn

from .variants import build_model

__all__ = ["NETWORK_KEY", "NORMALISATIONS", "CAMERA_RULES", "NetworkRecord", "network_record", "read_network",
           "network_from_checkpoint"]

#: Key of the record in a checkpoint dict.
NETWORK_KEY = "network"
RECORD_VERSION = 1
#: Input normalisations a record may name (the kit has one).
NORMALISATIONS = ("imagenet",)
#: Camera rules a record may name (the kit has one).
CAMERA_RULES = ("virtual_crop",)

#: ``config -> (input_size or None, (3, 3) K_net)`` for checkpoints without a record.
LegacyInput = Callable[[Mapping[str, Any]], tuple[int | None, np.ndarray]]


@dataclass(frozen=True)
class NetworkRecord:
    """A network's build settings and input (see the module docstring for each field).

    ``input_size`` or ``camera_K`` is None only for an old checkpoint read without ``legacy`` or
    whose data nobody can tell.
    """

    variant: str
    backbone: str
    model: dict = field(default_factory=dict)
    input_size: int | None = None
    camera_K: np.ndarray | None = None
    normalisation: str = "imagenet"
    camera_rule: str = "virtual_crop"


def network_record(variant: str, backbone: str, model: Mapping[str, Any], input_size: int,
                   camera_K: np.ndarray, *, normalisation: str = "imagenet",
                   camera_rule: str = "virtual_crop") -> dict:
    """The ``state["network"]`` entry of a checkpoint.

    Args:
        variant, backbone, model: :func:`~airpose_lib.model.build_model`'s arguments.
        input_size: crop side S.
        camera_K: ``(3, 3)`` training camera ``K_net``.
        normalisation, camera_rule: one of :data:`NORMALISATIONS` / :data:`CAMERA_RULES`.
    """
    if normalisation not in NORMALISATIONS or camera_rule not in CAMERA_RULES:
        raise ValueError(f"normalisation must be one of {NORMALISATIONS} and camera_rule one of "
                         f"{CAMERA_RULES}, got {normalisation!r} / {camera_rule!r}")
    return {"version": RECORD_VERSION, "variant": str(variant), "backbone": str(backbone), "model": dict(model),
            "input_size": int(input_size), "normalisation": normalisation, "camera_rule": camera_rule,
            "camera_K": np.asarray(camera_K, np.float64).reshape(3, 3).tolist()}


def read_network(state: Mapping[str, Any], legacy: LegacyInput | None = None) -> NetworkRecord:
    """The :class:`NetworkRecord` of a loaded checkpoint dict.

    Args:
        state: a checkpoint of ``airpose train`` or ``airpose finetune`` (``torch.load``-ed).
        legacy: for a checkpoint without ``state["network"]``: reconstructs the crop size and
            camera from its config (``data.still.training_input.training_input``); a fine-tuning
            checkpoint's own ``input_size`` / ``camera_K`` win over it.

    Raises:
        KeyError: neither a record nor a training config (not a kit checkpoint).
    """
    rec = state.get(NETWORK_KEY)
    if rec:
        return NetworkRecord(variant=rec["variant"], backbone=rec["backbone"], model=dict(rec.get("model") or {}),
                             input_size=int(rec["input_size"]),
                             camera_K=np.asarray(rec["camera_K"], np.float64).reshape(3, 3),
                             normalisation=rec.get("normalisation", "imagenet"),
                             camera_rule=rec.get("camera_rule", "virtual_crop"))
    cfg = state["config"]
    size, K = legacy(cfg) if legacy is not None else (None, None)
    if state.get("input_size"):  # fine-tuning checkpoints before the record
        size = int(state["input_size"])
    if state.get("camera_K") is not None:
        K = np.asarray(state["camera_K"], np.float64).reshape(3, 3)
    return NetworkRecord(variant=cfg.get("variant", "airpose"), backbone=cfg.get("backbone", "resnet50"),
                         model=dict(cfg.get("model") or {}), input_size=None if size is None else int(size),
                         camera_K=K)


def network_from_checkpoint(state: Mapping[str, Any], legacy: LegacyInput | None = None
                            ) -> tuple[nn.Module, NetworkRecord]:
    """The network of a loaded checkpoint dict, with its weights (CPU, eval mode), and its record.

    Args:
        state: a checkpoint of ``airpose train`` or ``airpose finetune`` (``torch.load``-ed): its
            record (or, before the record, its config) gives ``build_model``'s arguments,
            ``state["model"]`` the weights.
        legacy: as for :func:`read_network`.

    Returns:
        ``(model, record)``.
    """
    record = read_network(state, legacy)
    model = build_model(record.variant, backbone=record.backbone, **record.model)
    model.load_state_dict(state["model"])
    return model.eval(), record
