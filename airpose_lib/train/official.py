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

from airpose_lib.data.official.synthetic import OfficialSyntheticDataset
from airpose_lib.engine.checkpoint import write_checkpoint
from airpose_lib.model import AirPoseNet
from airpose_lib.model.official import backbone_name, load_official_checkpoint

from .ablation import VARIANT_LABELS, AblationRun
from .config import TrainConfig
from .evaluate import evaluate

__all__ = ["OFFICIAL_CHECKPOINT_FOLDERS", "OFFICIAL_TEST_BATCH", "find_official_checkpoint", "official_test_samples",
           "official_ablation", "save_kit_checkpoint"]

#: Kit variant -> folder of the official synthetic-data checkpoint (data_manifests/official_checkpoints.yaml).
OFFICIAL_CHECKPOINT_FOLDERS = {
    "baseline": "hmr_synthetic",
    "multiview": "muhmr_synthetic",
    "fullcam": "copenet_singleview_ckpt",
    "airpose": "copenet_twoview_synthetic_ckpt",
}


def find_official_checkpoint(root: str | Path, variant: str) -> Path:
    """The ``.ckpt`` of a variant under the official checkpoints folder: the only one, or the
    newest by name when several (e.g. ``epoch=...``); :func:`official_ablation` takes an explicit
    file per variant (``checkpoints=``) when that is not the one wanted."""
    if variant not in OFFICIAL_CHECKPOINT_FOLDERS:
        raise ValueError(f"unknown variant {variant!r}; known: {list(OFFICIAL_CHECKPOINT_FOLDERS)}")
    folder = Path(root) / OFFICIAL_CHECKPOINT_FOLDERS[variant]
    found = sorted(folder.glob("**/*.ckpt"))
    if not found:
        raise FileNotFoundError(
            f"no .ckpt under {folder}; unpack {OFFICIAL_CHECKPOINT_FOLDERS[variant]} of the official release there "
            "(data_manifests/official_checkpoints.yaml; `airpose data verify official_checkpoints`)")
    return found[-1]


#: The official test loader's batch (``drop_last`` drops the incomplete last one).
OFFICIAL_TEST_BATCH = 30


def official_test_samples(n: int, max_samples: int | None = None, drop_last: bool = False) -> int:
    """How many test samples are evaluated: all (or ``max_samples``), or with ``drop_last`` only
    whole batches of :data:`OFFICIAL_TEST_BATCH`, as the official test loader."""
    n = n if max_samples is None else min(n, max_samples)
    return (n // OFFICIAL_TEST_BATCH) * OFFICIAL_TEST_BATCH if drop_last else n


def official_ablation(checkpoints_root: str | Path, data_root: str | Path, variants=tuple(VARIANT_LABELS),
                      max_samples: int | None = None, batch_size: int = 8, backbone: str | None = "resnet50",
                      split_by: str = "auto", body: str = "smplx", input_size: int = 224, *,
                      draws: int = 3, seed: int = 0, tight: bool = True, drop_last: bool = False,
                      checkpoints: dict[str, str | Path] | None = None) -> dict[tuple[str, int], AblationRun]:
    """Evaluate the official checkpoints on the official synthetic test split, with the official
    loader's test crops.

    The official loader grows every test box by 1-200 px per side at random, unseeded, as in
    training (:func:`airpose_lib.data.official.synthetic.official_growth`); here each of ``draws``
    seeded draws (``jitter_seed = seed + k``) is one run, so Table I reports their mean and spread
    over draws (its ``seeds`` column counts draws). With ``tight`` every run also carries the
    tight-box crops' table (``per_view_tight``: the "tight box" columns). The official printed MPE
    is camera 0's (``ablation_table(..., camera0=True)`` adds that column beside both cameras').

    Args:
        drop_last: evaluate whole batches of 30 only, as the official test loader.
        checkpoints: variant -> an explicit ``.ckpt`` (default :func:`find_official_checkpoint`).
        body: the body model of the predictions' joints (the paper's: licensed SMPL-X; "open"
            only for fixtures); ``backbone=None`` detects it from the checkpoint.

    Returns:
        (variant, k) -> :class:`AblationRun` for draw ``k`` (same tables as
        :func:`~.ablation.run_ablation`), so :func:`airpose_lib.eval.ablation.ablation_table`
        builds Table I from it unchanged.
    """
    if draws < 1:
        raise ValueError(f"draws must be >= 1, got {draws}")

    def split(**kw) -> OfficialSyntheticDataset:
        return OfficialSyntheticDataset(data_root, split="test", split_by=split_by, input_size=input_size,
                                        body_source=body, augment=False, **kw)

    tight_set = split(jitter=False)
    n = official_test_samples(len(tight_set), max_samples, drop_last)
    if n == 0:
        raise ValueError(f"no test sample to evaluate: {len(tight_set)} samples, max_samples {max_samples}, "
                         f"drop_last {drop_last} (whole batches of {OFFICIAL_TEST_BATCH} only)")
    runs = {}
    for variant in variants:
        ckpt = Path(checkpoints[variant]) if checkpoints and variant in checkpoints else \
            find_official_checkpoint(checkpoints_root, variant)
        model = load_official_checkpoint(ckpt, variant=variant, backbone=backbone).eval()
        label = VARIANT_LABELS[variant]
        tight_tables = evaluate(model, tight_set, label, batch_size=batch_size, max_samples=n, body=body) \
            if tight else None
        for k in range(draws):
            tables = evaluate(model, split(jitter=True, jitter_seed=seed + k), label, batch_size=batch_size,
                              max_samples=n, body=body)
            if tight_tables is not None:
                tables["per_view_tight"] = tight_tables["per_view"]
            runs[variant, k] = AblationRun(variant, k, ckpt, tables)
    return runs


def save_kit_checkpoint(model: AirPoseNet, path: str | Path, *, source: str | Path | None = None,
                        **config: Any) -> Path:
    """Write ``model`` (e.g. converted official weights) as a kit checkpoint (atomically) that
    :func:`~.evaluate.load_network` reads (:func:`airpose_lib.engine.checkpoint.write_checkpoint`).

    It holds ``model``, ``step`` 0 and a ``config`` (``TrainConfig`` with the model's variant and
    backbone, ``steps=0``, plus ``config`` overrides), an empty optimiser state and no RNG state:
    weights for evaluation or fine-tuning, not a run to resume. ``source`` (e.g. the official
    file) is recorded with its SHA-256. No network record: the crop size and camera come from
    ``config``'s data, as for checkpoints from before the record (:mod:`airpose_lib.model.record`).
    """
    cfg = TrainConfig(**{"variant": model.variant, "backbone": backbone_name(model), "steps": 0,
                         "model": {"num_iterations": model.num_iterations}, **config})
    state = {"model": {k: v.detach().cpu().contiguous().clone() for k, v in model.state_dict().items()},
             "optimizer": {}, "rng": [], "step": 0, "epoch": 0, "batch_in_epoch": 0, "world_size": 1,
             "config": cfg.to_dict()}
    if source is not None:
        src = Path(source)
        state["source"] = {"file": str(src), "sha256": hashlib.sha256(src.read_bytes()).hexdigest()}
    return write_checkpoint(path, state)
