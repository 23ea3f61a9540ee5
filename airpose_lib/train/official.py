"""Table I from the official assets: the authors' four synthetic-data checkpoints evaluated on the
official synthetic test split, through the same evaluation as the kit's own runs.

Needs ``official_checkpoints`` (hmr_synthetic/, muhmr_synthetic/, copenet_singleview_ckpt/,
copenet_twoview_synthetic_ckpt/), ``official_synthetic`` and the licensed SMPL-X v1.1 files (the
release's betas are SMPL-X coefficients); see ``data_manifests/``.
"""
from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Any

import torch

from airpose_lib.atomic import atomic_path
from airpose_lib.data.official_synthetic import OfficialSyntheticDataset
from airpose_lib.engine.checkpoint import FORMAT_VERSION, kit_version
from airpose_lib.model import AirPoseNet
from airpose_lib.model.official import backbone_name, load_official_checkpoint

from .ablation import VARIANT_LABELS, AblationRun
from .config import TrainConfig
from .evaluate import evaluate

__all__ = ["OFFICIAL_CHECKPOINT_FOLDERS", "find_official_checkpoint", "official_ablation", "save_kit_checkpoint"]

#: Kit variant -> folder of the official synthetic-data checkpoint (data_manifests/official_checkpoints.yaml).
OFFICIAL_CHECKPOINT_FOLDERS = {
    "baseline": "hmr_synthetic",
    "multiview": "muhmr_synthetic",
    "fullcam": "copenet_singleview_ckpt",
    "airpose": "copenet_twoview_synthetic_ckpt",
}


def find_official_checkpoint(root: str | Path, variant: str) -> Path:
    """The ``.ckpt`` of a variant under the official checkpoints folder (the last by name if several)."""
    if variant not in OFFICIAL_CHECKPOINT_FOLDERS:
        raise ValueError(f"unknown variant {variant!r}; known: {list(OFFICIAL_CHECKPOINT_FOLDERS)}")
    folder = Path(root) / OFFICIAL_CHECKPOINT_FOLDERS[variant]
    found = sorted(folder.glob("**/*.ckpt"))
    if not found:
        raise FileNotFoundError(
            f"no .ckpt under {folder}; unpack {OFFICIAL_CHECKPOINT_FOLDERS[variant]} of the official release there "
            "(data_manifests/official_checkpoints.yaml; `airpose data verify official_checkpoints`)")
    return found[-1]


def official_ablation(checkpoints_root: str | Path, data_root: str | Path, variants=tuple(VARIANT_LABELS),
                      max_samples: int | None = None, batch_size: int = 8, backbone: str | None = "resnet50",
                      split_by: str = "auto", body: str = "smplx", input_size: int = 224
                      ) -> dict[tuple[str, int], AblationRun]:
    """Evaluate the official checkpoints on the official synthetic test split.

    ``body`` is the body model of the predictions' joints (the paper's: licensed SMPL-X; "open"
    only for fixtures); ``backbone=None`` detects it from the checkpoint.

    Returns:
        (variant, 0) -> :class:`AblationRun` (same tables as :func:`~.ablation.run_ablation`), so
        :func:`airpose_lib.eval.ablation.ablation_table` builds Table I from it unchanged.
    """
    test = OfficialSyntheticDataset(data_root, split="test", split_by=split_by, input_size=input_size,
                                    body_source=body)
    runs = {}
    for variant in variants:
        ckpt = find_official_checkpoint(checkpoints_root, variant)
        model = load_official_checkpoint(ckpt, variant=variant, backbone=backbone).eval()
        tables = evaluate(model, test, VARIANT_LABELS[variant], batch_size=batch_size, max_samples=max_samples,
                          body=body)
        runs[variant, 0] = AblationRun(variant, 0, ckpt, tables)
    return runs


def save_kit_checkpoint(model: AirPoseNet, path: str | Path, *, source: str | Path | None = None,
                        **config: Any) -> Path:
    """Write ``model`` (e.g. converted official weights) as a kit checkpoint (atomically) that
    :func:`~.evaluate.load_trained_model` and :func:`~.checkpoint.load_checkpoint` read.

    It holds ``model``, ``step`` 0 and a ``config`` (``TrainConfig`` with the model's variant and
    backbone, ``steps=0``, plus ``config`` overrides), an empty optimiser state and no RNG state:
    weights for evaluation or fine-tuning, not a run to resume. ``source`` (e.g. the official
    file) is recorded with its SHA-256. No network record: the crop size and camera come from
    ``config``'s data, as for checkpoints from before the record (:mod:`airpose_lib.model.record`).
    """
    cfg = TrainConfig(**{"variant": model.variant, "backbone": backbone_name(model), "steps": 0,
                         "model": {"num_iterations": model.num_iterations}, **config})
    state = {"format_version": FORMAT_VERSION, "kit_version": kit_version(),
             "model": {k: v.detach().cpu().contiguous().clone() for k, v in model.state_dict().items()},
             "optimizer": {}, "rng": [], "step": 0, "epoch": 0, "batch_in_epoch": 0, "world_size": 1,
             "config": cfg.to_dict()}
    if source is not None:
        src = Path(source)
        state["source"] = {"file": str(src), "sha256": hashlib.sha256(src.read_bytes()).hexdigest()}
    path = Path(path)
    with atomic_path(path) as tmp:
        torch.save(state, tmp)
    return path
