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

The entry (the command, ``airpose reproduce``, a notebook's set-up) reads the section once into a
:class:`TrainSection` (:func:`train_section`); ``train`` reads no profile.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from airpose_lib.config_fields import (
    ConfigError,
    check_fields,
    check_keys,
    check_keys_in,
    check_type,
    config_from,
    ranged,
    require,
)
from airpose_lib.devices import PRECISION_CHOICES, is_device_name
from airpose_lib.errors import ProfileSettingError

__all__ = ["DATA_KEYS", "TrainConfig", "TrainSection", "check_options", "load_train_config", "option_types",
           "train_section"]


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
        data: the still-frame dataset: ``root`` (a generated dataset folder; default: the
            profile's ``data: still:`` dataset, generated on first use,
            :class:`~airpose_lib.train.run.TrainInputs`), other keys are passed to
            ``StillFrameDataset`` (e.g. ``augment``).
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
    steps: int = ranged(1000, ge=0)
    batch_size: int = ranged(30, ge=1)
    lr: float = ranged(5e-5, gt=0)
    amsgrad: bool = True
    weight_decay: float = ranged(0.0, ge=0)
    lr_schedule: str = "constant"
    warmup_steps: int = ranged(0, ge=0)
    grad_clip: float | None = ranged(None, gt=0)
    seed: int = 123
    backbone: str = "resnet50"
    model: dict = field(default_factory=dict)
    freeze_backbone: bool = False
    loss: dict = field(default_factory=dict)
    official_loss: bool = False
    body_source: str = "open"
    data: dict = field(default_factory=dict)
    train_split: str = "train"
    val_split: str = "val"
    num_workers: int = ranged(0, ge=0)
    checkpoint_every: int = ranged(500, ge=1)
    keep_checkpoints: int = ranged(2, ge=0)  # 0: only last.pt
    val_every: int | None = ranged(500, ge=0)  # 0: at the end; null: never
    val_batches: int | None = ranged(None, ge=1)
    val_batch_size: int | None = ranged(None, ge=1)
    log_every: int = ranged(10, ge=1)
    world_size: int = ranged(1, ge=1)
    sync_batchnorm: bool = False
    device: str = "auto"
    precision: str = "auto"
    num_threads: int | None = ranged(None, ge=1)
    deterministic: bool = True
    progress: bool = True
    task: str = "supervised"
    pretrained: str | None = None
    trainable_from: str | None = None
    backbone_lr_scale: float = ranged(1.0, gt=0)

    def __post_init__(self) -> None:
        # Types and declared ranges first (a profile's `steps: thirty`), before anything runs.
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
        if self.batch_size < self.world_size:
            raise ConfigError(f"batch_size {self.batch_size} must be at least world_size {self.world_size} "
                              "(every process needs a sample)")
        # Never choose on the test split: a training (its validation loss included) does not read it.
        require(self.train_split != "test", "train_split", "not 'test' (the reported tables' split)", self.train_split)
        require(self.val_split != "test", "val_split", "not 'test' (choose on 'val'; the test split makes the "
                "reported tables only)", self.val_split)
        require(self.precision in PRECISION_CHOICES, "precision", "'auto', 'fp32', 'bf16' or 'fp16'", self.precision)
        check_options(self)

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

    #: Keys that configs written by earlier versions of the kit hold and this one drops
    #: (``profile``: the profile's name, which the kit now reads once at the entry).
    LEGACY_KEYS = ("profile",)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> "TrainConfig":
        """A config as :meth:`to_dict` wrote it, by this version of the kit or an earlier one."""
        return cls(**{k: v for k, v in d.items() if k not in cls.LEGACY_KEYS})

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


#: Keys of ``data:`` that the training itself reads (the other keys are the dataset's keywords).
DATA_KEYS = {"root": str | None, "source": str, "fingerprint": str | None,
             "generation": dict}


def option_types(name: str, task: str = "supervised", source: str = "generated") -> tuple[dict[str, Any], dict]:
    """What a dict field of :class:`TrainConfig` may hold: ``({key: annotation}, {key: Range})``.

    ``model``: the keyword arguments of the task's network (:class:`~airpose_lib.model.variants.AirPoseNet`,
    or :class:`~airpose_lib.model.pretrain.PretrainNet` for ``pretrain``) and the ranges the
    network declares (``OPTION_RANGES``); ``data``: :data:`DATA_KEYS` and the keywords of the
    dataset ``source`` names (the kit's datasets: a training given a dataset factory of its own
    takes other keys); ``loss``: the fields of :class:`~airpose_lib.losses.LossConfig` (of
    :class:`~airpose_lib.losses.pretrain.PretrainLossConfig` for ``pretrain``).
    """
    import inspect
    import typing

    # lazy: model, data and losses import torch
    from airpose_lib.config_fields import field_types
    from airpose_lib.data.official.synthetic import OfficialSyntheticDataset
    from airpose_lib.data.still.dataset import StillFrameDataset
    from airpose_lib.losses import LossConfig
    from airpose_lib.losses.pretrain import PretrainLossConfig
    from airpose_lib.model.pretrain import PretrainNet
    from airpose_lib.model.variants import AirPoseNet

    if name == "loss":
        return field_types(PretrainLossConfig if task == "pretrain" else LossConfig), {}
    if name == "model":
        owner, skip, extra = (PretrainNet if task == "pretrain" else AirPoseNet), ("self", "variant", "backbone"), {}
    else:
        owner = OfficialSyntheticDataset if source == "official_synthetic" else StillFrameDataset
        skip, extra = ("self", "root", "split"), DATA_KEYS
    hints = typing.get_type_hints(owner.__init__)
    types_ = {p: hints.get(p, typing.Any) for p in inspect.signature(owner.__init__).parameters if p not in skip}
    return {**extra, **types_}, dict(getattr(owner, "OPTION_RANGES", {}))


def check_options(config: TrainConfig, names: tuple[str, ...] = ("model", "loss")) -> None:
    """The keys and values of dict fields of ``config`` (:func:`option_types`): an unknown key
    names the closest known one, a value its type or range. ``data`` is checked where the kit's
    own datasets are chosen (``train.loop.check_data_root``)."""
    for name in names:
        options = getattr(config, name)
        types_, ranges = option_types(name, config.task, options.get("source", "generated") if name == "data" else "")
        check_keys_in(options, types_, name)
        for key, value in options.items():
            options[key] = check_type(f"{name}.{key}", value, types_[key])
            if key in ranges:
                require(ranges[key].holds(options[key]), f"{name}.{key}", ranges[key].rule, options[key])


@dataclass(frozen=True)
class TrainSection:
    """A profile's ``train:`` section, checked (:func:`train_section`): the settings every
    variant shares and each variant's changes; :meth:`config` makes one run's :class:`TrainConfig`.

    Attributes:
        values: the shared settings (TrainConfig fields).
        variants: variant -> its changes (``variants:``).
        where: how messages name the section (the file and the section).
    """

    values: dict = field(default_factory=dict)
    variants: dict = field(default_factory=dict)
    where: str = "training options"

    def config(self, variant: str, seed: int | None = None, **overrides: Any) -> TrainConfig:
        """The section's settings, then ``variants[variant]``, then ``seed`` and ``overrides``
        (TrainConfig fields), on top of :class:`TrainConfig`'s defaults. A bad value of the
        section raises ``ProfileSettingError`` naming the file; one of ``overrides``,
        ``ConfigError``."""
        values: dict[str, Any] = {**self.values, **(self.variants.get(variant) or {})}
        if self.values or self.variants.get(variant):
            # the profile's values alone first, so that a bad one is blamed on the file
            config_from(TrainConfig, {**values, "variant": variant}, self.where, error=ProfileSettingError)
        values["variant"] = variant
        if seed is not None:
            values["seed"] = seed
        values.update(overrides)
        check_keys(values, TrainConfig, "training options")
        return TrainConfig(**values)


def train_section(settings: Mapping[str, Any], where: str) -> TrainSection:
    """A ``train:`` section's settings (a plain mapping, as the profile has them) checked into a
    :class:`TrainSection`: unknown keys, here or in a variant's changes, raise
    ``ProfileSettingError`` naming ``where``. The section's ``variants:`` entries are train's own.
    """
    settings = dict(settings)
    per_variant = settings.pop("variants", None) or {}
    check_keys(settings, TrainConfig, where, ProfileSettingError)
    if not isinstance(per_variant, dict) or not all(isinstance(v or {}, dict) for v in per_variant.values()):
        raise ProfileSettingError(f"{where}: `variants:` must map a variant name to its settings")
    for variant, changes in per_variant.items():
        check_keys(changes or {}, TrainConfig, f"{where} `variants: {variant}:`", ProfileSettingError)
    return TrainSection(settings, {k: dict(v or {}) for k, v in per_variant.items()}, where)


def load_train_config(section: TrainSection | None, variant: str, seed: int | None = None,
                      **overrides: Any) -> TrainConfig:
    """``section.config(variant, seed, **overrides)`` (:class:`TrainSection`); ``None``: the
    defaults only."""
    return (section if section is not None else TrainSection()).config(variant, seed, **overrides)
