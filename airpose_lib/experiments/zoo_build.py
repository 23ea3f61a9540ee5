"""Build a profile's shipped networks (``airpose zoo build``): its runs, trained first where
missing, exported with their manifest into ``results/<profile>/networks/`` (:mod:`airpose_lib.zoo`)."""
from __future__ import annotations

import json
import os
from pathlib import Path

import torch

from airpose_lib.eval.ablation import VARIANT_LABELS
from airpose_lib.eval.reference import git_commit
from airpose_lib.paths import portable
from airpose_lib.prior.build import ensure_prior
from airpose_lib.train.ablation import trained_checkpoint
from airpose_lib.train.evaluate import evaluate_features
from airpose_lib.train.pretrain import profile_backbone, reference_backbone_path
from airpose_lib.zoo import export_regressor, half_state, kit_checkpoint, sha256_file, write_manifest, zoo_dir

from .configs import KitConfigs
from .recordings import run_recording_experiment
from .shipped import REBUILD

__all__ = ["build_shipped"]


def build_shipped(configs: KitConfigs, progress: bool = True, folder: str | Path | None = None) -> Path:
    """Make ``results/<profile>/networks/`` from the profile's runs (trained first where missing):
    the first seed's four variants, the clean and field recordings' fine-tuned Baseline and
    AirPose, the kit's prior; every file float16, listed with its SHA-256 in the manifest.

    ``folder`` replaces ``results/<profile>/networks/``.

    Returns:
        the manifest's path.
    """
    name = configs.folders.name
    folder = Path(folder) if folder is not None else zoo_dir(configs.folders)
    folder.mkdir(parents=True, exist_ok=True)
    backbone = reference_backbone_path(configs.folders)
    if not backbone.is_file():
        backbone = profile_backbone(configs.pretrain, progress=progress)
    trainings = configs.train_inputs()
    seed = trainings.section.config("airpose").seed
    commit = git_commit()
    rebuild = REBUILD.format(profile=name)
    entries = [_entry("backbone", backbone, folder, kind="backbone", made_by="airpose pretrain", rebuild=rebuild)]
    for variant in VARIANT_LABELS:
        ckpt = trained_checkpoint(trainings, variant, seed, progress=progress)
        dst = export_regressor(ckpt, backbone, folder / f"{variant}.pt")
        entries.append(_entry(variant, dst, folder, kind="regressor", variant=variant, seed=seed,
                              metric=_val_metric(ckpt, dst, backbone, configs.folders.still, variant), made_by=_made_by(ckpt),
                              rebuild=rebuild))
    for field in (False, True):
        exp = run_recording_experiment(configs, progress=progress, field=field)
        for method, label in (("Baseline", "baseline_tuned"), ("AirPose", "airpose_tuned")):
            entry = label + ("_field" if field else "")
            dst = export_regressor(exp.checkpoints[method], backbone, folder / f"{entry}.pt")
            info = exp.finetune_info.get(method, {})
            entries.append(_entry(entry, dst, folder, kind="fine-tuned regressor", variant=method.lower(), seed=seed,
                                  metric={"kept step": info.get("selected_step"),
                                          "person1 held-out 2D [px]": _round(info.get("heldout_j2d"), 2)},
                                  made_by=f"recordings{' (field)' if field else ''} of notebook 05",
                                  rebuild=rebuild))
    prior = folder / "prior.pt"
    blob = torch.load(ensure_prior(configs.prior, progress=progress), map_location="cpu", weights_only=True)
    # its provenance is committed: named without this machine's folders
    torch.save({**portable({k: v for k, v in blob.items() if k != "state_dict"}),
                "state_dict": half_state(blob["state_dict"])}, prior)
    entries.append(_entry("prior", prior, folder, kind="pose prior", made_by=f"airpose prior train --profile {name}",
                          rebuild=rebuild, metric={k: _round(v, 4) for k, v in
                                                   (blob.get("provenance", {}).get("metrics") or {}).items()}))
    about = {"profile": name, "exported_at_commit": commit.get("commit"), "dirty": commit.get("dirty"),
             "rebuild": rebuild, "precision": "float16 weights (float32 at run time)"}
    return write_manifest(folder, entries, about)


def _entry(name: str, path: Path, folder: Path, **facts) -> dict:
    return {"name": name, "file": os.path.relpath(path, folder), "bytes": Path(path).stat().st_size,
            "sha256": sha256_file(path), **{k: v for k, v in facts.items() if v is not None}}


def _made_by(checkpoint: Path) -> str:
    """The commit that trained a run (its ``result.json``), for the manifest."""
    try:
        git = json.loads((Path(checkpoint).parents[1] / "result.json").read_text()).get("git") or {}
    except (OSError, ValueError):
        git = {}
    commit = git.get("commit")
    return f"airpose train at {commit[:7]}{' (dirty)' if git.get('dirty') else ''}" if commit else "airpose train"


def _round(x, digits: int):
    return None if x is None else round(float(x), digits)


def _val_metric(checkpoint: Path, shipped: Path, backbone: Path, root: Path, variant: str) -> dict:
    """The validation split's MPE and MPJPE of the float32 run and of the float16 shipped file
    (``root``: the profile's still-frame dataset)."""
    label = VARIANT_LABELS[variant]
    full = evaluate_features(checkpoint, backbone, root, label, split="val")["per_view"]
    half = evaluate_features(kit_checkpoint(shipped, backbone), backbone, root, label, split="val")["per_view"]
    return {"val MPE [m]": _round(half["mpe_m"].mean(), 4), "val MPJPE [m]": _round(half["mpjpe_m"].mean(), 4),
            "val MPE fp32 [m]": _round(full["mpe_m"].mean(), 4),
            "val MPJPE fp32 [m]": _round(full["mpjpe_m"].mean(), 4)}

