"""The settings of a fine-tuning run (:class:`FineTuneConfig`, stored in its checkpoints) and
where they come from: a profile's ``finetune:`` section and the command line's overrides."""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from airpose_lib.config_fields import ConfigError, check_fields, config_from, ranged, require
from airpose_lib.devices import is_device_name

from .selection import SELECTION_RULES

__all__ = ["TARGET_SOURCES", "FineTuneConfig", "finetune_config"]

#: Where the 2D targets come from (``FineTuneConfig.targets``).
TARGET_SOURCES = ("detections", "ground_truth", "mediapipe")


@dataclass
class FineTuneConfig:
    """Everything that determines a fine-tuning run (stored in its checkpoints).

    Attributes:
        steps: optimiser steps in total.
        batch_size: frames per step (each with all its views); paper: 30.
        lr, amsgrad, weight_decay: Adam (paper: lr 5e-5, AMSGrad).
        seed: frame order, dropout and VPoser samples (paper: 123).
        loss: :class:`~airpose_lib.finetune.loss.FineTuneLossConfig` overrides (``w_j2d``,
            ``w_beta``, ``w_vposer``, ``w_theta``, ``cross_view_beta`` ...) on top of the variant's
            paper weights; ``official_loss`` applies the official code's x60 and depth term first.
        threshold_px, min_confidence, unmatched: the agreement filter (``agreement_targets``);
            ``threshold_px`` at ``reference_width``.
        targets: ``detections`` (the paper: OpenPose keypoints that AlphaPose confirms) or
            ``ground_truth``, a control on generated recordings: the true BODY_25 keypoints
            (:func:`~airpose_lib.finetune.keypoints.true_targets`) with the same frames and crops,
            to tell what the detectors' errors cost from what fine-tuning on one person does; or
            ``mediapipe``: the same agreement filter with MediaPipe's BODY_25 keypoints (a real
            detector, ``scripts/mediapipe_detect.py``) in OpenPose's place, confirmed by AlphaPose.
        reference_width: image width (px) the pixel quantities (``threshold_px``, the 2D loss
            weight) refer to: the paper's 1920; each view uses them at its own width.
        holdout_fraction: the last part of the selected frames held out for model selection
            (0: no selection, the last checkpoint is the result).
        selection: the model-selection rule (:data:`~airpose_lib.finetune.selection.SELECTION_RULES`):
            ``first_overfit`` (the paper's) or ``min_heldout_j2d``.
        frames: ``[start, stop)`` image numbers to train on (paper: ``[0, 7000]``); None: all.
        input_size: crop side S (default: from the checkpoint).
        detector, box_min_confidence, margin_px: where the crops' boxes come from
            (``predict_sequence``; the drones' defaults: a margin of None frames the person as
            the training crops do, ``data.network_input.network_box_margin``).
        feature_batch_size: frames per backbone batch when caching the features.
        trainable_from: the first backbone block that trains with the regressor (e.g.
            ``layer4.1``, the last block of a ResNet-18), the features then cached at that
            block's input; None (the paper's fine-tuning here so far): the backbone stays frozen.
            A frozen backbone can only re-weigh features learned on the training renders; the
            last block can adapt them to the recording's pixels. Its BatchNorm statistics stay
            fixed while it trains (one recording's batches are too alike to normalise by;
            ``adapt_bn`` moves them once, towards those of all the training frames).
        backbone_lr_scale: the trainable blocks' rate as a share of ``lr``.
        adapt_bn: the recording's share of the backbone's BatchNorm statistics: before the
            features are cached, each layer's mean and variance move this far towards those of the
            training frames' crops, every view (1: AdaBN;
            :func:`~airpose_lib.finetune.predict.adapt_batchnorm`; no labels, the held-out frames
            unseen). 0 (the paper's): pretraining's statistics. The fine-tuned checkpoints carry
            the adapted statistics, so every later use of the network sees them.
        checkpoint_every, keep_checkpoints, log_every: as ``TrainConfig``.
        prior, prior_path, prior_tag: the pose prior (``airpose_lib.prior.load_prior``).
        body_source: body model of the loss (``open`` or ``smplx``; the predictions' neutral body).
        missing_detections: ``load_sequence``'s handling of short detector files.
        eval_batch_size: frames per batch of the before/after loss evaluation.
        num_threads: torch threads during the run (None: unchanged).
        device: ``auto`` (CUDA if available), ``cpu`` or ``cuda``.
    """

    steps: int = ranged(1000, ge=0)
    batch_size: int = ranged(30, ge=1)
    lr: float = ranged(5e-5, gt=0)
    amsgrad: bool = True
    weight_decay: float = ranged(0.0, ge=0)
    seed: int = 123
    loss: dict = field(default_factory=dict)
    official_loss: bool = False
    threshold_px: float = ranged(100.0, gt=0)
    targets: str = "detections"
    reference_width: float = ranged(1920.0, gt=0)
    holdout_fraction: float = ranged(0.2, ge=0, lt=1)
    selection: str = "first_overfit"
    min_confidence: float = ranged(0.05, ge=0, le=1)
    unmatched: str = "drop"
    frames: list | None = None
    input_size: int | None = ranged(None, ge=32)
    detector: str = "openpose"
    box_min_confidence: float = ranged(0.2, ge=0, le=1)
    margin_px: float | None = ranged(None, ge=0)
    feature_batch_size: int = ranged(16, ge=1)
    trainable_from: str | None = None
    backbone_lr_scale: float = ranged(0.1, gt=0)
    adapt_bn: float = ranged(0.0, ge=0, le=1)
    checkpoint_every: int = ranged(100, ge=1)
    keep_checkpoints: int = ranged(2, ge=0)  # 0: only last.pt
    log_every: int = ranged(10, ge=1)
    prior: str = "kit"
    prior_path: str | None = None
    prior_tag: str | None = None
    body_source: str = "open"
    missing_detections: str = "error"
    eval_batch_size: int = ranged(256, ge=1)
    num_threads: int | None = ranged(None, ge=1)
    device: str = "auto"

    # Fields whose change makes a resumed run differ from a straight one.
    RESUME_KEYS = ("batch_size", "lr", "amsgrad", "weight_decay", "seed", "loss", "official_loss", "threshold_px",
                   "targets", "reference_width", "holdout_fraction", "selection",
                   "min_confidence", "unmatched", "frames", "input_size", "detector", "box_min_confidence",
                   "margin_px", "prior", "prior_path", "prior_tag", "body_source", "trainable_from",
                   "backbone_lr_scale", "adapt_bn")

    def __post_init__(self) -> None:
        check_fields(self)  # types and declared ranges first (`--set lr=abc`, a profile's `steps: ten`)
        require(self.body_source in ("open", "smplx"), "body_source", "'open' or 'smplx'", self.body_source)
        require(is_device_name(self.device), "device",
                "'auto', 'cpu', 'cuda' or 'cuda:N'", self.device)
        require(self.targets in TARGET_SOURCES, "targets", f"one of {', '.join(TARGET_SOURCES)}", self.targets)
        require(self.selection in SELECTION_RULES, "selection", f"one of {', '.join(SELECTION_RULES)}",
                self.selection)
        if self.frames is not None:
            frames = list(self.frames)
            if len(frames) != 2 or not all(isinstance(x, (int, np.integer)) for x in frames) or frames[0] >= frames[1]:
                raise ConfigError(f"frames must be [start, stop) image numbers with start < stop, got {self.frames!r}")
            self.frames = [int(frames[0]), int(frames[1])]
        self.loss = dict(self.loss or {})

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    def replace(self, **changes: Any) -> "FineTuneConfig":
        return dataclasses.replace(self, **changes)


def finetune_config(base: FineTuneConfig | None = None, **overrides: Any) -> FineTuneConfig:
    """``base`` (a profile's ``finetune:`` section as the entry read it; None: the defaults), then
    ``overrides``. An unknown key or a bad value of ``overrides`` raises
    :class:`~airpose_lib.errors.ConfigError` naming the field."""
    values = {} if base is None else {f.name: getattr(base, f.name) for f in dataclasses.fields(base)}
    return config_from(FineTuneConfig, {**values, **overrides}, "fine-tuning options")
