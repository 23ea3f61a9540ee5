"""Fine-tuning on 2D detections of a two-drone recording (paper Sec. IV, real data) and running a
network over a recording.

Modules: ``keypoints`` (the OpenPose/AlphaPose agreement filter -> 2D targets), ``predict``
(detections -> crops -> per-view SMPL-X parameters; the predictions ``.npz``), ``loss`` (the
fine-tuning loss), ``network`` (a checkpoint's network and crop size), ``train`` (frozen
backbone, cached features, regressor training; resumable), ``cli`` (``airpose finetune`` /
``airpose predict``).

Names are imported lazily (``from airpose_lib.finetune import finetune`` works), so the CLI can
build its parser from ``finetune.cli`` without importing torch.
"""
from __future__ import annotations

import importlib

_MODULES = ("keypoints", "loss", "network", "predict", "train")


def __getattr__(name: str):
    if not name.startswith("_"):
        for candidate in _MODULES:
            mod = importlib.import_module(f"{__name__}.{candidate}")
            if name in getattr(mod, "__all__", ()):
                value = getattr(mod, name)
                globals()[name] = value
                return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    names = set(globals()) | set(_MODULES)
    for candidate in _MODULES:
        names |= set(getattr(importlib.import_module(f"{__name__}.{candidate}"), "__all__", ()))
    return sorted(names)
