"""The shared pretrained backbone of a profile: trained once, gated on held-out data, cached.

``ensure_backbone(setup, ...)`` returns the path of the profile's backbone file (:class:`PretrainSetup`:
what the entry read of the profile for it). It is looked for, in
order, in the kit cache (``<cache>/backbones/<key>.pt``), in the repository's committed reference
(``results/<profile>/pretrained_backbone.pt``, used when its recorded key matches and its SHA-256
is the recorded one), and otherwise trained with the profile's ``pretrain:`` section by the one
training engine (:func:`airpose_lib.train.loop.start_training`, task ``"pretrain"``;
:mod:`airpose_lib.model.pretrain` has the network, :mod:`airpose_lib.losses.pretrain` the
objective). The key hashes the ``pretrain:`` settings and the dataset's configuration fingerprint,
so a change of either trains a new backbone.

A ``pretrain:`` section may name an earlier stage (``continue_from:``, the same settings with a
few changed, e.g. ``{steps: 4000}``): that stage is made first (or found), and this one starts from
its backbone with new heads and a new optimiser. The key of a later stage includes the key of the
stage it starts from, so a user without the committed file rebuilds the whole chain from nothing.

The file holds the backbone's weights in float16 (half the size; the features differ from the
float32 network's by about 1e-3 relative, far below what the regressors resolve) and a JSON
record: backbone name, key, the gate's measurements on the validation split, the wall time and the
command that rebuilds it (``airpose pretrain --profile <profile>``).
"""
from __future__ import annotations

import hashlib
import inspect
import json
import shutil
import time
from dataclasses import dataclass, fields
from pathlib import Path

import torch
from torch.utils.data import DataLoader

from airpose_lib.atomic import atomic_path, atomic_torch_save
from airpose_lib.config_fields import config_from
from airpose_lib.data.still.dataset import StillFrameDataset
from airpose_lib.data.still.generate import GenerationConfig, ensure_still_dataset
from airpose_lib.data.still.manifest import load_manifest
from airpose_lib.data.still.shards import sha256_file
from airpose_lib.engine.checkpoint import kit_version, load_checkpoint
from airpose_lib.engine.launch import resolve_device, resolve_precision, single_process
from airpose_lib.errors import ConfigError, DamagedFileError, ProfileError, ProfileSettingError, reading
from airpose_lib.eval.metrics import root_yaw_tilt, rotation_error
from airpose_lib.eval.reference import git_commit
from airpose_lib.folder_lock import file_lock
from airpose_lib.geometry import axis_angle_to_matrix, rot6d_to_matrix
from airpose_lib.losses.pretrain import PretrainLossConfig, heading_bin
from airpose_lib.model.backbone import build_backbone
from airpose_lib.model.pretrain import PretrainNet
from airpose_lib.paths import RunFolders, cache_dir, portable

from .config import TrainConfig
from .loop import check_data_root, default_model_factory, start_training

__all__ = ["PRETRAIN_VERSION", "DATA_OPTIONS", "PretrainSetup", "pretrain_config", "pretrain_stages", "backbone_key",
           "stage_keys", "stage_key_options", "ensure_backbone", "profile_backbone", "profile_backbone_key",
           "profile_backbone_keys", "own_backbone_keys", "OTHER_PROFILE",
           "other_profile", "own_backbone_key", "other_profile_backbone", "export_backbone",
           "import_torchvision_backbone", "gate_metrics", "reference_backbone_path",
           "write_reference_backbone"]

#: Bumped when the same settings would train another backbone.
PRETRAIN_VERSION = 1
#: Training-data options a pretraining stage's ``data:`` may set (StillFrameDataset keywords).
DATA_OPTIONS = ("mirror",)


@dataclass(frozen=True)
class PretrainSetup:
    """What makes a profile's shared backbone, read once at the entry: its ``pretrain:``
    settings, its still-frame dataset's, its folders.

    Attributes:
        section: the ``pretrain:`` settings, as the profile has them (checked by :meth:`stages`).
        where: how messages name the section (the file and the section).
        still: the profile's ``data: still:`` settings (None: it has none; only a stage with
            ``data: still:`` changes needs them).
        folders: the profile's folders (its dataset, pretraining runs, committed backbone).
        label: how records and commands name the profile.
    """

    section: dict
    where: str
    still: GenerationConfig | None
    folders: RunFolders
    label: str

    def stages(self, **overrides) -> list[TrainConfig]:
        """:func:`pretrain_stages` of this setup."""
        return pretrain_stages(self, **overrides)


def pretrain_stages(setup: PretrainSetup, **overrides) -> list[TrainConfig]:
    """The stages of a profile's pretraining, first to last, as :class:`TrainConfig` s (task
    ``pretrain``). A ``pretrain:`` section may name the stage it continues (``continue_from:``, the
    earlier stage's settings as changes to its own), which may name one in turn, and so on.
    ``overrides`` apply to the last stage.

    A stage with ``data: {still: {...}}`` pretrains on its own still-frame dataset: the profile's
    ``data: still:`` settings with those changes (e.g. the smaller dataset that earlier stages were
    trained on, when the profile's grew). Its ``cfg.data`` then holds that dataset's ``root``,
    ``fingerprint`` and ``generation`` settings; the other stages take the dataset that
    :func:`ensure_backbone` is given. A stage's ``data:`` may also set the training augmentation
    (:data:`DATA_OPTIONS`, e.g. ``mirror: true``, :class:`~airpose_lib.data.still.dataset.StillFrameDataset`'s
    keywords); they are part of the stage's key.
    """
    chain = [dict(setup.section)]
    while (earlier := chain[-1].pop("continue_from", None)) is not None:
        if not isinstance(earlier, dict):
            raise ProfileError(f"profile {setup.label}: `pretrain: continue_from:` must be a mapping of settings "
                               f"(e.g. {{steps: 4000}}), not {earlier!r}")
        chain.append({**chain[-1], **earlier})
    where = setup.where

    def stage(values: dict, extra: dict) -> TrainConfig:
        values = dict(values)
        data = values.pop("data", None) or {}
        # the section's settings blamed on the file (config_from, as every section), then the
        # caller's overrides as options
        values = {"variant": "pretrain", "task": "pretrain", **values}
        config_from(TrainConfig, values, where, error=ProfileSettingError)
        extra = dict(extra)
        if "data" in extra:  # an override's data replaces the section's
            data = extra.pop("data") or {}
        cfg = config_from(TrainConfig, {**values, **extra}, "training options")
        unknown = set(data) - {"still", *DATA_OPTIONS}
        if unknown:
            raise ProfileError(f"profile {setup.label}: a pretraining stage's `data:` takes only `still:` "
                               f"(changes to the profile's `data: still:`) and {', '.join(DATA_OPTIONS)}, "
                               f"not {sorted(unknown)}")
        options = {k: data[k] for k in DATA_OPTIONS if k in data}
        if "still" in data:
            cfg = cfg.replace(data=_stage_dataset(setup, data["still"] or {}))
        return cfg.replace(data={**cfg.data, **options}) if options else cfg

    return [stage(values, overrides if i == 0 else {}) for i, values in reversed(list(enumerate(chain)))]


def _stage_dataset(setup: PretrainSetup, changes: dict) -> dict:
    """``root``, ``fingerprint`` and ``generation`` of the profile's still-frame dataset with
    ``changes``; the profile's own folder when the changes change nothing."""
    base = setup.still
    if base is None:
        raise ProfileError(f"{setup.where}: a stage's `data: still:` changes the profile's `data: still:` "
                           "section, which it has none of; add one")
    config = GenerationConfig.from_dict({**base.to_dict(), **changes})
    fp, root = config.fingerprint(), setup.folders.still
    if fp != base.fingerprint():
        root = root.with_name(f"{root.name}-{fp[:12]}")
    return {"root": str(root), "fingerprint": fp, "generation": config.to_dict()}


def pretrain_config(setup: PretrainSetup, **overrides) -> TrainConfig:
    """The last stage of a profile's pretraining (:func:`pretrain_stages`)."""
    return pretrain_stages(setup, **overrides)[-1]


#: Loss and network options that leave a backbone's key as it was when set at their defaults:
#: ``{TrainConfig field: {option: default}}``, the defaults read from
#: ``losses.pretrain.PretrainLossConfig`` and ``model.pretrain.PretrainNet``.
KEY_FREE_DEFAULTS = {"loss": {f.name: f.default for f in fields(PretrainLossConfig)
                              if f.name in ("w_beta", "w_stature", "w_gender")},
                     "model": {"body_scalars": inspect.signature(PretrainNet).parameters["body_scalars"].default}}


def backbone_key(cfg: TrainConfig, data_fingerprint: str, start_key: str | None = None) -> str:
    """First 16 hex digits of the SHA-256 of the settings that make the backbone.

    ``start_key`` is the key of the backbone this stage starts from (``None``: from scratch); it
    takes the place of ``cfg.pretrained``, a path that differs between machines.
    """
    settings = {k: v for k, v in cfg.to_dict().items()
                if k not in ("progress", "data", "num_workers", "log_every", "checkpoint_every", "keep_checkpoints",
                             "val_every", "val_batches", "device", "num_threads", "profile",
                             "trainable_from", "backbone_lr_scale")}  # the last two: regressor-task fields
    settings["pretrained"] = start_key
    options = {k: cfg.data[k] for k in DATA_OPTIONS if cfg.data.get(k)}
    if options:  # only when set, so that the keys of the backbones made before the options stay
        settings["data_options"] = options
    for name, default in (("lr_schedule", "constant"), ("warmup_steps", 0), ("precision", "fp32"),
                          ("sync_batchnorm", False)):
        if settings.get(name) == default:  # added after the first committed backbone, whose key stays
            settings.pop(name)
    for part, defaults in KEY_FREE_DEFAULTS.items():
        # the shape terms spelled out at their defaults (a profile undoing an inherited shape stage)
        # make the backbone that leaving them out makes
        if isinstance(settings.get(part), dict):
            settings[part] = {k: v for k, v in settings[part].items() if not (k in defaults and defaults[k] == v)}
    blob = json.dumps({"version": PRETRAIN_VERSION, "settings": settings, "data": data_fingerprint},
                      sort_keys=True, default=str)
    return hashlib.sha256(blob.encode()).hexdigest()[:16]


def reference_backbone_path(folders: RunFolders) -> Path:
    """Where a profile's committed backbone lives in the repository."""
    return folders.results / "pretrained_backbone.pt"


@torch.no_grad()
def gate_metrics(model: torch.nn.Module, dataset, batch_size: int = 32, max_samples: int | None = None,
                 device: str | torch.device = "cpu") -> dict[str, float]:
    """The pretrained heads on held-out data: heading accuracy, root-rotation and body-pose errors.

    Returns ``heading_acc`` (fraction), ``root_rot_median_deg`` / ``root_rot_mean_deg`` of the
    linear ``phi6d`` head with its yaw and tilt medians (:func:`~airpose_lib.eval.metrics.root_yaw_tilt`)
    and the share of crops above 90 deg (``root_rot_over_90``, a fraction), ``theta_mean_deg``
    (mean over the 21 joints) and ``n`` crops.
    """
    model = model.to(device).eval()
    n_bins = model.n_heading_bins
    rot, yaw, tilt, th, hit = [], [], [], [], []
    n = 0
    for batch in DataLoader(dataset, batch_size=batch_size, shuffle=False):
        B, V = batch["phi"].shape[:2]
        out = {k: v.cpu() for k, v in model(batch["images"].flatten(0, 1).to(device)).items()}
        phi = batch["phi"].flatten(0, 1)
        R = rot6d_to_matrix(out["phi6d"]).double()
        rot.append(torch.rad2deg(rotation_error(R, phi.double())))
        y, t = root_yaw_tilt(R, phi.double())
        yaw.append(torch.rad2deg(y))
        tilt.append(torch.rad2deg(t))
        theta = axis_angle_to_matrix(batch["theta"]).unsqueeze(1).expand(B, V, 21, 3, 3).flatten(0, 1)
        th.append(torch.rad2deg(rotation_error(rot6d_to_matrix(out["theta6d"]).double(), theta.double())).mean(-1))
        hit.append(out["heading"].argmax(-1) == heading_bin(phi, n_bins))
        n += B
        if max_samples is not None and n >= max_samples:
            break
    rot_all, th_all, hit_all = torch.cat(rot), torch.cat(th), torch.cat(hit)
    return {"heading_acc": float(hit_all.float().mean()), "root_rot_median_deg": float(rot_all.median()),
            "root_rot_mean_deg": float(rot_all.mean()), "root_yaw_median_deg": float(torch.cat(yaw).median()),
            "root_tilt_median_deg": float(torch.cat(tilt).median()),
            "root_rot_over_90": float((rot_all > 90.0).double().mean()), "theta_mean_deg": float(th_all.mean()),
            "n": int(len(rot_all))}


def export_backbone(checkpoint: str | Path, path: str | Path, meta: dict) -> Path:
    """Write the backbone of a pretraining checkpoint as a float16 file with its JSON record."""
    state = load_checkpoint(checkpoint)
    sd = {k[len("backbone."):]: v.half() if v.is_floating_point() else v
          for k, v in state["model"].items() if k.startswith("backbone.")}
    return _write_backbone_file(sd, path, meta)


def _write_backbone_file(sd: dict, path: str | Path, meta: dict) -> Path:
    """A backbone file (``state_dict`` + ``meta_json``, read by ``features.load_backbone_file``)
    and its JSON record beside it (``meta`` with the file's ``sha256`` and ``bytes``), each
    written atomically. ``meta``'s paths are written :func:`~airpose_lib.paths.portable`: the file
    may become the committed reference (:func:`write_reference_backbone`), and nothing reads a
    path back out of it."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    meta = portable(meta)
    atomic_torch_save({"state_dict": sd, "meta_json": json.dumps(meta, sort_keys=True)}, path)
    record = dict(meta, sha256=sha256_file(path), bytes=path.stat().st_size)
    with atomic_path(path.with_suffix(".json")) as tmp:
        tmp.write_text(json.dumps(record, indent=2, sort_keys=True) + "\n")
    return path


def import_torchvision_backbone(weights: str | Path, backbone: str = "resnet50", out: str | Path | None = None
                                ) -> Path:
    """A torchvision ResNet state dict (e.g. ImageNet weights the user downloaded:
    ``torchvision.models.resnet50(weights="IMAGENET1K_V2").state_dict()`` saved with
    ``torch.save``) as a kit backbone file, float32, for ``train: pretrained: <file>`` (the
    paper starts from ImageNet weights).

    Args:
        weights: the ``.pth`` file: a state dict, or a dict holding one under ``state_dict`` /
            ``model``; ``fc.*`` is dropped, a ``module.`` prefix stripped.
        backbone: the kit's name of the architecture (``resnet50``, ``resnet34``, ``resnet18``).
        out: the file to write (default ``<cache>/backbones/imagenet-<backbone>-<sha256[:12]>.pt``).

    Raises:
        DamagedFileError: not a state dict of that architecture (the missing/unexpected keys or
            the shape mismatch, one line).
    """
    weights = Path(weights)
    with reading(weights, f"a torchvision {backbone} state dict (torch.save of model.state_dict())",
                 "save the weights again with torch.save(model.state_dict(), FILE)"):
        blob = torch.load(weights, map_location="cpu", weights_only=True)
    for key in ("state_dict", "model"):
        if isinstance(blob, dict) and isinstance(blob.get(key), dict):
            blob = blob[key]
    if not isinstance(blob, dict) or not all(isinstance(v, torch.Tensor) for v in blob.values()):
        raise DamagedFileError(weights, "a state dict of tensors", "save one with torch.save(model.state_dict(), FILE)")
    net = build_backbone(backbone)
    try:
        net.load_torchvision_state_dict({k: v.float() if v.is_floating_point() else v for k, v in blob.items()})
    except RuntimeError as e:
        raise DamagedFileError(weights, f"a torchvision {backbone} state dict",
                               f"give the weights of a {backbone} or choose the matching --backbone", e) from None
    digest = sha256_file(weights)
    path = Path(out) if out is not None else cache_dir() / "backbones" / f"imagenet-{backbone}-{digest[:12]}.pt"
    meta = {"backbone": backbone, "key": f"imported-{digest[:16]}", "source": str(weights.absolute()),
            "source_sha256": digest, "kit_version": kit_version(),
            "command": f"airpose backbone import {weights} --backbone {backbone}"}
    return _write_backbone_file(net.state_dict(), path, meta)


def _reference_if_valid(folders: RunFolders, key: str) -> Path | None:
    ref = reference_backbone_path(folders)
    try:
        record = json.loads(ref.with_suffix(".json").read_text())
    except (OSError, ValueError):
        return None
    if record.get("key") != key or not ref.is_file() or sha256_file(ref) != record.get("sha256"):
        return None
    return ref


def _at_hand(folders: RunFolders, key: str) -> Path | None:
    """The backbone ``key`` from the cache, or from the committed reference (copied into the cache)."""
    target = cache_dir() / "backbones" / f"{key}.pt"
    if target.is_file():
        return target
    ref = _reference_if_valid(folders, key)
    if ref is None:
        return None
    target.parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(ref, target)
    shutil.copyfile(ref.with_suffix(".json"), target.with_suffix(".json"))
    return target


def stage_keys(stages: list[TrainConfig], data_fingerprint: str, auto_as: str | None = None) -> list[str]:
    """The key of each stage of :func:`pretrain_stages` (each includes the one before).

    ``data_fingerprint`` is that of the dataset the stages without their own dataset train on.
    A stage of ``precision: auto`` is keyed by the precision it trains in: ``auto_as``, or (None)
    the one :func:`~airpose_lib.engine.launch.resolve_precision` picks on this machine.
    """
    keys: list[str] = []
    for cfg in stages:
        if cfg.precision == "auto":
            cfg = cfg.replace(precision=auto_as or resolve_precision("auto", resolve_device(cfg.device))[0])
        fp = cfg.data.get("fingerprint", data_fingerprint)
        keys.append(backbone_key(cfg, fp, keys[-1] if keys else None))
    return keys


def stage_key_options(stages: list[TrainConfig], data_fingerprint: str) -> list[list[str]]:
    """The stage keys this machine trains (first), then, for stages of ``precision: auto``, those
    of the other precision auto may pick (``bf16`` / ``fp32``): a backbone that auto made on
    another CPU is the one the profile asks for, so it is taken where it is at hand."""
    options = [stage_keys(stages, data_fingerprint)]
    if any(cfg.precision == "auto" for cfg in stages):
        options += [k for p in ("bf16", "fp32") if (k := stage_keys(stages, data_fingerprint, p)) not in options]
    return options


def _with_data(stages: list[TrainConfig], data_root: str | Path, data_fingerprint: str) -> list[TrainConfig]:
    """The dataset in ``data_root`` (``root`` and ``fingerprint``) for the stages that have none
    of their own."""
    given = {"root": str(data_root), "fingerprint": data_fingerprint}
    return [cfg if "generation" in cfg.data else cfg.replace(data={**cfg.data, **given}) for cfg in stages]


def ensure_backbone(setup: PretrainSetup, data_root: str | Path, data_fingerprint: str, out_root: str | Path | None = None,
                    progress: bool = False, device: str | None = None, **overrides) -> Path:
    """The profile's pretrained backbone file (see the module docstring for where it comes from).

    Args:
        setup: the profile's pretraining (:class:`PretrainSetup`).
        data_root: the still-frame dataset to pretrain on (train split; the validation split gates).
        data_fingerprint: that dataset's configuration fingerprint (part of the key).
        out_root: parent of the pretraining run folders (default ``<runs>/pretrain/<profile>``).
        device: where the stages that must be trained train and are gated (default: their
            ``device``, ``auto``); not part of the key.
        overrides: TrainConfig fields over the ``pretrain:`` section (its last stage).
    """
    stages = _with_data(pretrain_stages(setup, **overrides), data_root, data_fingerprint)
    if device is not None:
        stages = [cfg.replace(device=device) for cfg in stages]
    options = stage_key_options(stages, data_fingerprint)
    for other in options[1:]:  # made in the other precision auto may pick: complete, or not at all
        with file_lock(cache_dir() / "backbones" / f"{other[-1]}.lock"):
            found = _at_hand(setup.folders, other[-1])
        if found is not None:
            return found
    keys = options[0]
    start, path = 0, None
    for i in reversed(range(len(stages))):  # the latest stage already made needs nothing before it
        with file_lock(cache_dir() / "backbones" / f"{keys[i]}.lock"):
            found = _at_hand(setup.folders, keys[i])
        if found is not None:
            start, path = i + 1, found
            break
    for i in range(start, len(stages)):
        path = _train_stage(setup, stages[i], keys[i], path, out_root, progress)
    return path


def _train_stage(setup: PretrainSetup, cfg: TrainConfig, key: str, start: Path | None, out_root: str | Path | None,
                 progress: bool) -> Path:
    """Train one stage (from ``start``'s backbone, or from scratch) on its dataset (``cfg.data``),
    gate it on that dataset's validation split, export it as ``key``."""
    target = cache_dir() / "backbones" / f"{key}.pt"
    target.parent.mkdir(parents=True, exist_ok=True)
    with file_lock(target.with_suffix(".lock")):
        found = _at_hand(setup.folders, key)
        if found is not None:
            return found
        data_root, data_fingerprint = cfg.data["root"], cfg.data["fingerprint"]
        if "generation" in cfg.data:  # a dataset of the stage's own, made only when the stage trains
            ensure_still_dataset(config=GenerationConfig.from_dict(cfg.data["generation"]), root=data_root,
                                 progress=progress)
        options = {k: cfg.data[k] for k in DATA_OPTIONS if k in cfg.data}
        cfg = cfg.replace(pretrained=None if start is None else str(start), data={"root": str(data_root), **options})
        out = Path(out_root) if out_root is not None else setup.folders.pretrain
        t0 = time.time()
        # One process trains a backbone (the others, torchrun's ranks included, wait on the lock
        # above): a pretraining nested in a distributed training must not join its process group.
        with single_process():
            run_cfg = cfg.replace(progress=progress)
            check_data_root(run_cfg)  # its data is made: the check that train.run.prepare_data does
            run = start_training(run_cfg, out / key)
        wall = time.time() - t0
        model = _load_pretrain_model(run.checkpoint, cfg)
        gate = gate_metrics(model, StillFrameDataset(data_root, "val", augment=False),  # the whole validation split
                            device=resolve_device(cfg.device))
        meta = {"backbone": cfg.backbone, "key": key, "profile": setup.label, "kit_version": kit_version(),
                "config": cfg.to_dict(), "data_fingerprint": data_fingerprint, "gate": gate, "gate_split": "val",
                "train_wall_s": round(wall, 1), "steps": run.step, "git": git_commit(),  # the code that trained it
                "command": f"airpose pretrain --profile {setup.label}"}
        if start is not None:
            earlier = json.loads(Path(start).with_suffix(".json").read_text())
            meta["continued_from"] = {k: earlier.get(k) for k in ("key", "steps", "train_wall_s", "gate", "sha256",
                                                                  "continued_from")}
            meta["total_steps"] = run.step + int(earlier.get("total_steps", earlier.get("steps", 0)))
        export_backbone(run.checkpoint, target, meta)
    return target


def _load_pretrain_model(checkpoint: str | Path, cfg: TrainConfig) -> torch.nn.Module:
    model = default_model_factory(cfg)
    model.load_state_dict(load_checkpoint(checkpoint)["model"])
    return model.eval()


def profile_backbone_key(setup: PretrainSetup, data_root: str | Path) -> str:
    """The key of the backbone a profile asks for on the dataset in ``data_root`` (its last stage),
    as this machine would train it."""
    return profile_backbone_keys(setup, data_root)[0]


def profile_backbone_keys(setup: PretrainSetup, data_root: str | Path) -> list[str]:
    """Every key a backbone the profile asks for may have (:func:`stage_key_options`; this
    machine's first)."""
    fingerprint = load_manifest(Path(data_root))["fingerprint"]
    return [k[-1] for k in stage_key_options(_with_data(pretrain_stages(setup), data_root, fingerprint), fingerprint)]


def profile_backbone(setup: PretrainSetup, progress: bool = False) -> Path:
    """The backbone of a profile for its own still-frame dataset (generated first if missing)."""
    pretrain_stages(setup)  # a bad `pretrain:` setting fails before a dataset is made
    root = ensure_still_dataset(config=_own_still(setup), root=setup.folders.still, progress=progress)
    return ensure_backbone(setup, root, load_manifest(Path(root))["fingerprint"], progress=progress)


def _own_still(setup: PretrainSetup) -> GenerationConfig:
    if setup.still is None:
        raise ProfileError(f"profile {setup.label} has no `data: still:` section (the still-frame dataset sizes) "
                           "to pretrain its backbone on; add one")
    return setup.still


#: ``pretrained: profile:<name>`` in a training config: the backbone of profile ``<name>`` for its
#: own data (e.g. ``cpu_paper_layout`` trains its regressors on cpu's features).
OTHER_PROFILE = "profile:"


def other_profile(pretrained: str | None) -> str | None:
    """The profile named by ``pretrained: profile:<name>``; None for any other value."""
    if pretrained is None or not str(pretrained).startswith(OTHER_PROFILE):
        return None
    name = str(pretrained)[len(OTHER_PROFILE):]
    if not name:
        raise ConfigError(f"pretrained: {pretrained!r} names no profile; write e.g. `pretrained: profile:cpu`")
    return name


def own_backbone_key(setup: PretrainSetup) -> str:
    """The key of :func:`profile_backbone` (from the profile's settings; no dataset is read), as
    this machine would train it."""
    return own_backbone_keys(setup)[0]


def own_backbone_keys(setup: PretrainSetup) -> list[str]:
    """Every key :func:`profile_backbone` may have (:func:`stage_key_options`; this machine's first)."""
    fingerprint = _own_still(setup).fingerprint()
    stages = _with_data(pretrain_stages(setup), setup.folders.still, fingerprint)
    return [k[-1] for k in stage_key_options(stages, fingerprint)]


def other_profile_backbone(setup: PretrainSetup, progress: bool = False) -> Path:
    """:func:`profile_backbone`, without making the profile's dataset when the backbone is at hand
    (in the cache, or the committed reference)."""
    for key in own_backbone_keys(setup):
        with file_lock(cache_dir() / "backbones" / f"{key}.lock"):
            found = _at_hand(setup.folders, key)
        if found is not None:
            return found
    return profile_backbone(setup, progress)


def write_reference_backbone(folders: RunFolders, backbone_file: str | Path) -> Path:
    """Copy a backbone file and its record into ``results/<profile>/`` (the committed reference).

    A file whose record names this machine's folders (written before records were made
    :func:`~airpose_lib.paths.portable`) is written again with a portable record, in the file
    (``meta_json``) and beside it: the reference's ``sha256`` and ``bytes`` are then its own, not
    the cache file's, so that :func:`_reference_if_valid` accepts it.
    """
    src = Path(backbone_file)
    ref = reference_backbone_path(folders)
    ref.parent.mkdir(parents=True, exist_ok=True)
    blob = torch.load(src, map_location="cpu", weights_only=True)
    meta = json.loads(blob["meta_json"])
    record = json.loads(src.with_suffix(".json").read_text())
    if portable(meta) != meta or portable(record) != record:
        return _write_backbone_file(blob["state_dict"], ref, meta)
    for s, dst in ((src, ref), (src.with_suffix(".json"), ref.with_suffix(".json"))):
        with atomic_path(dst) as tmp:
            shutil.copyfile(s, tmp)
    return ref
