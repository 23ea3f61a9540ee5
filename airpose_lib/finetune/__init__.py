"""Fine-tuning on 2D detections of a two-drone recording (paper Sec. IV, real data) and running a
network over a recording.

Modules: ``config`` (a run's settings, from a profile's ``finetune:`` section), ``keypoints`` (the OpenPose/AlphaPose agreement filter -> 2D targets), ``predict``
(detections -> crops -> per-view SMPL-X parameters; the predictions ``.npz``), ``loss`` (the
fine-tuning loss), ``network`` (a checkpoint's network and crop size), ``selection`` (which checkpoint is
kept: the paper's "stop once any loss component starts overfitting"), ``train`` (frozen
backbone, cached features, regressor training; resumable). The commands (``airpose finetune``,
``airpose predict``) are in :mod:`airpose_lib.cli.finetune`.

Names are imported lazily (``from airpose_lib.finetune import finetune`` works), so importing the
package does not import torch.
"""
from __future__ import annotations

from airpose_lib._lazy import lazy_namespace

_MODULES = ("config", "keypoints", "loss", "network", "predict", "selection", "train")
__getattr__, __dir__ = lazy_namespace(__name__, globals(), _MODULES)
