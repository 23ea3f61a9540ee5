"""Training configuration: defaults, the profile's ``train:`` section, per-variant overrides.

A profile (``airpose_lib/profiles/<name>.yaml``, the one place sizes live) holds

.. code-block:: yaml

    train:
      steps: 200            # any TrainConfig field
      batch_size: 4
      backbone: resnet18
      data: {...}           # keyword arguments of the still-frame dataset
      variants:             # per-variant overrides of the fields above
        baseline: {lr: 1.0e-4}

The file is read by :mod:`airpose_lib.profiles`; ``train`` imports nothing from ``reproduce``.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from airpose_lib.config_fields import ConfigError, check_fields, check_keys, check_type, config_from, finite, require
from airpose_lib.devices import PRECISION_CHOICES, is_device_name
from airpose_lib.errors import ProfileSettingError
from airpose_lib.profiles import profile_section, section_where

__all__ = ["TrainConfig", "load_train_config"]


@dataclass
class TrainConfig:
    """Everything that determines a training run (saved in every checkpoint).

    Attributes:
        variant: ``baseline``, ``multiview``, ``fullcam`` or ``airpose``.
        steps: optimiser steps in total.
        batch_size: global batch (samples; each holds V views), split over the processes in
            slices whose sizes differ by at most one (any ``world_size <= batch_size``; see
            :func:`airpose_lib.train.sampling.share_bounds`).
        lr, amsgrad, weight_decay: Adam (paper: lr 5e-5, AMSGrad, batch 30, seed 123).
        lr_schedule: ``"constant"`` (the paper) or ``"cosine"`` (from ``lr`` to 0 at ``steps``).
        warmup_steps: the learning rate rises linearly from 0 over this many steps first (0: none).
        grad_clip: clip the gradient norm to this value (None: no clipping, as the paper).
        seed: seeds python, numpy, torch, the data order and every sample's augmentation.
        backbone: ``resnet50`` (paper), ``resnet34``, ``resnet18``.
        model: extra keyword arguments of ``airpose_lib.model.build_model`` (``dropout``,
            ``num_iterations``, ``mean_params`` ...).
        freeze_backbone: train only the regressor; the backbone's BatchNorm stays in eval mode
            (the paper's real-data fine-tuning).
        loss: :class:`airpose_lib.losses.LossConfig` field overrides; ``official_loss`` applies the
            official code's variations first.
        body_source: body model of the losses (``open`` or ``smplx``).
        profile: the profile the config came from (names the default dataset): a kit profile's name,
            or the absolute path of a profile file of one's own.
        data: the still-frame dataset: ``root`` (a generated dataset folder) or ``profile`` (whose
            ``data: still:`` dataset is used, generated on first use; default: ``profile`` above),
            other keys are passed to ``StillFrameDataset`` (e.g. ``augment``).
        train_split, val_split: split names passed to the dataset (``train``, ``val``, ``test``):
            the validation loss, and every choice made on it, reads ``val``; ``test`` is read only
            by the evaluation that makes the reported tables, and a training refuses it.
        num_workers: DataLoader worker processes per training process.
        checkpoint_every: write a checkpoint every this many steps (and always at the end).
        keep_checkpoints: numbered checkpoints kept besides ``last.pt`` (0: only ``last.pt``).
        val_every: validation loss every this many steps (0: only at the end; None: never).
        val_batches: at most this many validation batches (None: the whole split).
        val_batch_size: validation batch (default: ``batch_size``).
        log_every: CSV/TensorBoard row every this many steps.
        world_size: processes (DDP); 1 = single process. Under ``torchrun`` it is the launch's.
        sync_batchnorm: with several processes, BatchNorm statistics over the global batch
            (``torch.nn.SyncBatchNorm``) instead of each process's share.
        device: ``auto`` (CUDA if available), ``cpu``, ``cuda`` (each process its own GPU,
            ``cuda:<LOCAL_RANK>``) or ``cuda:N``; a run records the device it used.
        precision: ``auto`` (bf16 where the device computes it natively, else fp32:
            :func:`airpose_lib.engine.launch.resolve_precision`), ``fp32``, ``bf16`` (autocast, CPU
            and CUDA) or ``fp16`` (autocast with loss scaling, CUDA only) for the training step's
            network; losses and validation in float32.
        num_threads: torch CPU threads per process (None: torch's default, divided by the number
            of processes under DDP).
        deterministic: ``torch.use_deterministic_algorithms`` (warn only).
        progress: tqdm progress bar.
        task: what the engine trains: ``"supervised"`` (a variant end to end on the crops, the
            paper), ``"regressor"`` (a variant's regressor on the cached features of a frozen,
            shared pretrained backbone: the CPU protocol, :mod:`airpose_lib.train.features`) or
            ``"pretrain"`` (that backbone, :mod:`airpose_lib.train.pretrain`).
        pretrained: a pretrained backbone file (:func:`airpose_lib.train.pretrain.ensure_backbone`)
            to start from; ``"profile"`` resolves the profile's own; None: random initialisation.
        trainable_from: task ``regressor`` only: the first backbone block that trains with the
            regressor (e.g. ``"layer4.1"``, the last block of a ResNet-18); the features are then
            cached at that block's input and the blocks from it on adapt to the variant's loss
            (their BatchNorm statistics stay frozen). None: the whole backbone is frozen.
        backbone_lr_scale: the learning rate of those blocks, as a fraction of ``lr``.
    """

    variant: str = "airpose"
    steps: int = 1000
    batch_size: int = 30
    lr: float = 5e-5
    amsgrad: bool = True
    weight_decay: float = 0.0
    lr_schedule: str = "constant"
    warmup_steps: int = 0
    grad_clip: float | None = None
    seed: int = 123
    backbone: str = "resnet50"
    model: dict = field(default_factory=dict)
    freeze_backbone: bool = False
    loss: dict = field(default_factory=dict)
    official_loss: bool = False
    body_source: str = "open"
    profile: str | None = None
    data: dict = field(default_factory=dict)
    train_split: str = "train"
    val_split: str = "val"
    num_workers: int = 0
    checkpoint_every: int = 500
    keep_checkpoints: int = 2
    val_every: int | None = 500
    val_batches: int | None = None
    val_batch_size: int | None = None
    log_every: int = 10
    world_size: int = 1
    sync_batchnorm: bool = False
    device: str = "auto"
    precision: str = "auto"
    num_threads: int | None = None
    deterministic: bool = True
    progress: bool = True
    task: str = "supervised"
    pretrained: str | None = None
    trainable_from: str | None = None
    backbone_lr_scale: float = 1.0

    def __post_init__(self) -> None:
        # Types first (a profile's `steps: thirty`), then each field's range, before anything runs.
        check_fields(self)
        variants, backbones = _model_choices()
        variants += ("pretrain",) if self.task == "pretrain" else ()  # the shared backbone's own objective
        require(self.variant in variants, "variant", f"one of {', '.join(variants)}", self.variant)
        require(self.task in ("supervised", "regressor", "pretrain"), "task",
                "'supervised', 'regressor' or 'pretrain'", self.task)
        require(self.lr_schedule in ("constant", "cosine"), "lr_schedule", "'constant' or 'cosine'", self.lr_schedule)
        require(self.backbone in backbones, "backbone", f"one of {', '.join(backbones)}", self.backbone)
        require(self.body_source in ("open", "smplx"), "body_source", "'open' or 'smplx'", self.body_source)
        require(is_device_name(self.device), "device", "'auto', 'cpu', 'cuda' or 'cuda:N'", self.device)
        if self.trainable_from is not None and self.task != "regressor":
            raise ConfigError("trainable_from applies to the regressor task only")
        require(finite(self.lr) and self.lr > 0, "lr", "a finite number > 0", self.lr)
        require(finite(self.weight_decay) and self.weight_decay >= 0, "weight_decay", "a finite number >= 0",
                self.weight_decay)
        require(self.grad_clip is None or finite(self.grad_clip) and self.grad_clip > 0, "grad_clip",
                "null or a finite number > 0", self.grad_clip)
        require(finite(self.backbone_lr_scale) and self.backbone_lr_scale > 0, "backbone_lr_scale",
                "a finite number > 0", self.backbone_lr_scale)
        require(self.warmup_steps >= 0, "warmup_steps", ">= 0", self.warmup_steps)
        require(self.steps >= 0, "steps", ">= 0", self.steps)
        require(self.batch_size >= 1, "batch_size", ">= 1", self.batch_size)
        require(self.world_size >= 1, "world_size", ">= 1", self.world_size)
        if self.batch_size < self.world_size:
            raise ConfigError(f"batch_size {self.batch_size} must be at least world_size {self.world_size} "
                              "(every process needs a sample)")
        # Never choose on the test split: a training (its validation loss included) does not read it.
        require(self.train_split != "test", "train_split", "not 'test' (the reported tables' split)", self.train_split)
        require(self.val_split != "test", "val_split", "not 'test' (choose on 'val'; the test split makes the "
                "reported tables only)", self.val_split)
        require(self.precision in PRECISION_CHOICES, "precision", "'auto', 'fp32', 'bf16' or 'fp16'", self.precision)
        require(self.checkpoint_every >= 1, "checkpoint_every", ">= 1", self.checkpoint_every)
        require(self.log_every >= 1, "log_every", ">= 1", self.log_every)
        require(self.keep_checkpoints >= 0, "keep_checkpoints", ">= 0 (0: only last.pt)", self.keep_checkpoints)
        require(self.val_every is None or self.val_every >= 0, "val_every", "null (never) or >= 0 (0: at the end)",
                self.val_every)
        require(self.val_batches is None or self.val_batches >= 1, "val_batches", "null (all) or >= 1",
                self.val_batches)
        require(self.val_batch_size is None or self.val_batch_size >= 1, "val_batch_size", "null or >= 1",
                self.val_batch_size)
        require(self.num_workers >= 0, "num_workers", ">= 0", self.num_workers)
        require(self.num_threads is None or self.num_threads >= 1, "num_threads", "null or >= 1", self.num_threads)
        _check_model_options(self.model, self.task)

    def lr_at(self, step: int) -> float:
        """The learning rate of optimiser step ``step + 1`` (``step`` steps done)."""
        scale = 1.0
        if self.warmup_steps and step < self.warmup_steps:
            scale = (step + 1) / self.warmup_steps
        elif self.lr_schedule == "cosine" and self.steps > self.warmup_steps:
            done = (step - self.warmup_steps) / (self.steps - self.warmup_steps)
            scale = 0.5 * (1.0 + math.cos(math.pi * min(max(done, 0.0), 1.0)))
        return self.lr * scale

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    def replace(self, **changes: Any) -> "TrainConfig":
        return dataclasses.replace(self, **changes)

    # Fields whose change makes a resumed run differ from a straight one.
    RESUME_KEYS = ("variant", "batch_size", "lr", "lr_schedule", "warmup_steps", "amsgrad", "weight_decay", "grad_clip", "seed", "backbone",
                   "model", "freeze_backbone", "loss", "official_loss", "body_source", "data", "train_split",
                   "task", "pretrained", "trainable_from", "backbone_lr_scale", "precision", "sync_batchnorm")

    def resume_keys(self) -> tuple[str, ...]:
        """:attr:`RESUME_KEYS`, and ``steps`` when the rate schedule depends on the total: a
        cosine run of 2,000 steps resumed to 6,000 would restart its decay at step 2,000 (rate 0
        back to 0.75 of the peak), which a straight 6,000-step run never does. A constant-rate run
        may still be extended by resuming."""
        return self.RESUME_KEYS + (("steps",) if self.lr_schedule != "constant" else ())


def _model_choices() -> tuple[tuple[str, ...], tuple[str, ...]]:
    """The variant and backbone names the model package knows."""
    from airpose_lib.model.backbone import BACKBONES  # lazy: model imports torch
    from airpose_lib.model.variants import VARIANTS

    return tuple(VARIANTS), tuple(BACKBONES)


def _check_model_options(model: dict, task: str) -> None:
    """``model:`` holds keyword arguments of the task's network (:class:`~airpose_lib.model.variants.AirPoseNet`,
    or :class:`~airpose_lib.model.pretrain.PretrainNet` for ``pretrain``): each key one of its
    parameters, each value of the parameter's annotated type."""
    import inspect
    import typing

    # lazy: model imports torch
    from airpose_lib.model.pretrain import PretrainNet
    from airpose_lib.model.variants import AirPoseNet

    net = PretrainNet if task == "pretrain" else AirPoseNet
    hints = typing.get_type_hints(net.__init__)
    params = [p for p in inspect.signature(net.__init__).parameters if p not in ("self", "variant", "backbone")]
    for key, value in model.items():
        if key not in params:
            raise ConfigError(f"model: unknown option {key!r}; {net.__name__} takes {', '.join(params)}")
        model[key] = check_type(f"model.{key}", value, hints.get(key, typing.Any))


def load_train_config(profile: str | Path | None, variant: str, seed: int | None = None,
                      section: str = "train", **overrides: Any) -> TrainConfig:
    """The profile's ``train`` section (or ``section``), then its ``variants[variant]`` entry, then
    ``seed`` and ``overrides`` (TrainConfig fields), on top of :class:`TrainConfig`'s defaults.

    ``profile=None`` uses the defaults only. Unknown keys and bad values raise ``ConfigError``
    (in the profile: ``ProfileSettingError``, naming the file; typos fail before anything runs);
    an unknown profile raises ``ProfileError``. The section goes through
    ``config_fields.config_from`` as every section does (``profiles.section_config``); its
    ``variants:`` entries are train's own.
    """
    values: dict[str, Any] = {}
    if profile is not None:
        settings = profile_section(profile, section)
        per_variant = settings.pop("variants", None) or {}
        where = section_where(profile, section)
        check_keys(settings, TrainConfig, where, ProfileSettingError)
        if not isinstance(per_variant, dict) or not isinstance(per_variant.get(variant) or {}, dict):
            raise ProfileSettingError(f"{where}: `variants:` must map a variant name to its settings")
        check_keys(per_variant.get(variant) or {}, TrainConfig, f"{where} `variants: {variant}:`", ProfileSettingError)
        values.update(settings)
        values.update(per_variant.get(variant) or {})
        # the profile's values alone first, so that a bad one is blamed on the file
        config_from(TrainConfig, {**values, "variant": variant}, where, error=ProfileSettingError)
    values["variant"] = variant
    if profile is not None:
        # a kit profile by name; a profile file of one's own by its path (read again for its data)
        own = Path(str(profile)).suffix in (".yaml", ".yml")
        values.setdefault("profile", str(Path(profile).absolute()) if own else Path(str(profile)).stem)
    if seed is not None:
        values["seed"] = seed
    values.update(overrides)
    check_keys(values, TrainConfig, "training options")
    return TrainConfig(**values)
