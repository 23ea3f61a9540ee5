"""A training from a config: its prerequisites first, then the loop.

:func:`train` resolves what the run needs before the training starts (:func:`prepare_data`: the
still-frame dataset, generated if missing; the profile's pretrained backbone, pretrained if missing
(:func:`airpose_lib.train.pretrain.ensure_backbone`), or another profile's (``pretrained:
profile:<name>``); the feature caches of the ``regressor`` task), from the :class:`TrainInputs` the
entry read of the profile (this module reads none),
then hands the resolved config to the loop (:func:`airpose_lib.train.loop.start_training`). The
loop itself never makes a prerequisite, so the pretraining, which is a run of the loop, and the
loop do not import each other.

Under ``torchrun`` the prerequisites are resolved before the process group exists, in each process
alone (:func:`airpose_lib.engine.launch.single_process`) and one after the other (a file lock in
the run folder): the first builds what is missing, a nested pretraining included, the others find
it made (see :mod:`airpose_lib.train.loop`).
"""
from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import torch

from airpose_lib.assets import locate
from airpose_lib.data.still.config import GenerationConfig
from airpose_lib.data.still.generate import ensure_still_dataset
from airpose_lib.data.still.manifest import load_manifest
from airpose_lib.engine.launch import check_precision, launch_env, resolve_device, single_process
from airpose_lib.errors import ConfigError
from airpose_lib.folder_lock import file_lock
from airpose_lib.paths import RunFolders

from .config import TrainConfig, TrainSection
from .features import ensure_features
from .loop import TrainResult, check_data_root, start_training
from .pretrain import PretrainSetup, ensure_backbone, other_profile, other_profile_backbone

__all__ = ["TrainInputs", "train", "prepare_data"]


@dataclass(frozen=True)
class TrainInputs:
    """What a profile's trainings need besides their configs, read once at the entry.

    Attributes:
        section: the ``train:`` section (the config of each variant and seed).
        still: the ``data: still:`` dataset's settings (None: the profile has none; a config
            must then name its ``data.root``).
        folders: the profile's folders (its dataset's, its runs'; ``default`` without a profile).
        pretrain: the profile's backbone (``pretrained: profile``; None: it has no ``pretrain:``).
        others: the backbones of the profiles that ``pretrained: profile:<name>`` names, by name.
    """

    section: TrainSection = field(default_factory=TrainSection)
    still: GenerationConfig | None = None
    folders: RunFolders = RunFolders("default")
    pretrain: PretrainSetup | None = None
    others: Mapping[str, PretrainSetup] = field(default_factory=dict)


def train(variant: str, inputs: TrainInputs | None = None, seed: int | None = None,
          out_dir: str | Path | None = None, resume: bool = True, *, config: TrainConfig | None = None,
          overrides: Mapping | None = None, model_factory: Callable | None = None,
          dataset_factory: Callable | None = None, loss_factory: Callable | None = None,
          stop_at: int | None = None) -> TrainResult:
    """Train a variant with a profile's sizes.

    Args:
        variant: ``baseline``, ``multiview``, ``fullcam`` or ``airpose``.
        inputs: the profile's :class:`TrainInputs` (its ``train:`` section, dataset and
            backbone); None: the defaults, and a ``data.root`` of the config's.
        seed: overrides the profile's seed.
        out_dir: run folder (default ``inputs.folders.train(variant, seed)``): ``config.json``, ``log.csv``, ``checkpoints/``, ``result.json``.
        resume: continue from ``<out_dir>/checkpoints/last.pt`` if present; otherwise (or with
            False) start afresh, deleting earlier checkpoints in ``out_dir``.
        config: a ready :class:`TrainConfig` (then seed and overrides are ignored).
        overrides: TrainConfig fields, applied after the profile.
        model_factory: ``cfg -> nn.Module`` (default :func:`~airpose_lib.train.loop.default_model_factory`).
        dataset_factory: ``(cfg, split) -> Dataset`` (default
            :func:`~airpose_lib.train.loop.default_dataset_factory`, whose prerequisites
            :func:`prepare_data` resolves first; a dataset factory of the caller's gets none).
        loss_factory: ``cfg -> nn.Module`` (default :func:`~airpose_lib.train.loop.default_loss_factory`).
        stop_at: stop (with a checkpoint) once this step is reached, as if interrupted there;
            a later call with ``resume=True`` continues to ``cfg.steps``.

    Returns:
        :class:`~airpose_lib.train.loop.TrainResult`.
    """
    inputs = inputs if inputs is not None else TrainInputs()
    cfg = config if config is not None else inputs.section.config(variant, seed, **dict(overrides or {}))
    out = Path(out_dir) if out_dir is not None else inputs.folders.train(cfg.variant, cfg.seed)
    launch = launch_env()
    check_precision(cfg.precision, resolve_device(cfg.device, launch[1] if launch else 0))  # before any data
    if dataset_factory is None:
        if launch is None:
            cfg = prepare_data(cfg, inputs, device=resolve_device(cfg.device))
        else:  # torchrun: prerequisites alone, before the loop joins the process group
            cfg = _prepare_alone(cfg, inputs, out, show=cfg.progress and launch[0] == 0)
    return start_training(cfg, out, resume, model_factory=model_factory, dataset_factory=dataset_factory,
                          loss_factory=loss_factory, stop_at=stop_at)


def _prepare_alone(cfg: TrainConfig, inputs: TrainInputs, out: Path, show: bool) -> TrainConfig:
    """:func:`prepare_data` in each torchrun process before the process group exists, one process
    at a time (a waiting lock in the run folder): a nested pretraining runs in that one process
    and no collective waits on it (see the module docstring)."""
    device = resolve_device(cfg.device, launch_env()[1])
    with single_process(), file_lock(Path(out) / ".prerequisites.lock"):
        return prepare_data(cfg, inputs, progress=show, device=device)


def prepare_data(cfg: TrainConfig, inputs: TrainInputs | None = None, progress: bool | None = None,
                 device: str | torch.device = "cpu") -> TrainConfig:
    """Resolve the dataset folder: ``cfg.data["root"]``, or the profile's ``data: still:``
    dataset (``inputs``), generated (``airpose_lib.data``) if missing; a
    pretraining or feature cache it needs runs on ``device`` (the caller's: a checkpoint's
    recorded device may not exist where it is evaluated).

    Returns the config with ``data["root"]`` set. Called by :func:`train` before any training process opens the data.
    """
    data = dict(cfg.data)
    if data.get("source", "generated") == "official_synthetic":
        # The official release (data_manifests/official_synthetic.yaml): nothing to generate.
        if data.get("root") is None:
            data["root"] = str(locate("official_synthetic").path)
        if cfg.body_source != "smplx":
            raise ConfigError("training on the official synthetic data needs body_source='smplx' (its betas "
                             "are SMPL-X v1.1 shape coefficients; see data_manifests/smplx_v1_1.yaml)")
        return cfg.replace(data=data)
    show = cfg.progress if progress is None else progress
    if data.get("root") is None:
        if inputs is None or inputs.still is None:
            raise ConfigError("no still-frame dataset: set data.root, or train with a profile that has a "
                             "`data: still:` section")
        data["root"] = str(ensure_still_dataset(config=inputs.still, root=inputs.folders.still, progress=show))
    else:
        check_data_root(cfg)
    cfg = cfg.replace(data=data)
    if cfg.pretrained == "profile":
        if inputs is None or inputs.pretrain is None:
            raise ConfigError("pretrained: profile needs the profile's `pretrain:` section; train with a profile "
                              "that has one, or give a backbone file")
        fingerprint = load_manifest(Path(data["root"]))["fingerprint"]
        cfg = cfg.replace(pretrained=str(ensure_backbone(inputs.pretrain, data["root"], fingerprint, progress=show,
                                                         device=str(device))))
    elif (other := other_profile(cfg.pretrained)) is not None:  # another profile's, for its own data
        if inputs is None or other not in inputs.others:
            raise ConfigError(f"pretrained: {cfg.pretrained} names a profile the command did not read; "
                              "train through `airpose train`, `airpose reproduce` or a notebook")
        cfg = cfg.replace(pretrained=str(other_profile_backbone(inputs.others[other], progress=show)))
    if cfg.task == "regressor":
        if cfg.pretrained is None:
            raise ConfigError("the regressor task trains on the features of a pretrained backbone: set pretrained")
        for split in {cfg.train_split} | ({cfg.val_split} if cfg.val_every is not None else set()):
            ensure_features(cfg.pretrained, data["root"], split, progress=show, cut=cfg.trainable_from,
                            device=device)
    return cfg
