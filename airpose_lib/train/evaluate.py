"""Run a trained network over a still-frame split and turn the result into evaluation tables.

Two sets of joints are scored (:func:`airpose_lib.eval.tables.per_view_table`):

- Table I's MPJPE as the official evaluation defines it (``test_epoch_end`` of
  ``copenet/copenet_twoview.py``): prediction and ground truth both on the neutral body with
  **zero betas**, their own root rotation, no translation, the first 22 joints; body shape is not
  scored (``joints_zero_beta``, pelvis-aligned: the official SMPL-X rotates about the pelvis);
  the same with the true root orientation (``joints_zero_beta_true_root``) scores the body pose alone.
- the kit's shape-aware MPJPE: the predicted neutral body with its predicted betas in the paper's
  convention (``phi J0 + tau``, camera frame) against the sample's ``j3d_cam`` (gendered model).
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import torch
from torch import nn
from torch.utils.data import DataLoader

from airpose_lib.body import load_body_model
from airpose_lib.body.forward import BodyForward
from airpose_lib.data.still.training_input import training_input
from airpose_lib.engine.checkpoint import load_checkpoint
from airpose_lib.engine.launch import resolve_device
from airpose_lib.eval import per_joint_table, per_view_table, relative_camera_table
from airpose_lib.geometry import axis_angle_to_matrix
from airpose_lib.model import to_smplx_params
from airpose_lib.model.record import NetworkRecord, network_from_checkpoint

from .config import TrainConfig
from .features import FeatureDataset, ensure_features
from .loop import default_dataset_factory
from .run import prepare_data

__all__ = ["predict", "evaluate", "load_network", "load_trained_model", "evaluate_checkpoint", "evaluate_features"]


@torch.no_grad()
def predict(model: nn.Module, dataset, batch_size: int = 8, device: str | torch.device = "cpu",
            body: BodyForward | str = "open", num_workers: int = 0, max_samples: int | None = None,
            feature_cut: str | None = None) -> tuple[dict[str, torch.Tensor], dict[str, torch.Tensor]]:
    """Predictions and matching ground truth for a dataset, in order.

    Args:
        body: the neutral body of the predictions: a :class:`~airpose_lib.body.forward.BodyForward`
            (22 body joints) or a body-model source
            (``"open"``, ``"smplx"``).

    The dataset may serve crops (``images``) or cached backbone ``features`` (a
    :class:`~airpose_lib.train.features.FeatureDataset`; then only the regressor runs, after the
    backbone blocks from ``feature_cut`` when the features are that block's input).

    Returns:
        ``pred``: phi (N, V, 3, 3), theta (N, V, 21, 3, 3), beta (N, V, 10), tau (N, V, 3),
        joints (N, V, 22, 3), joints_zero_beta (N, V, 22, 3), joints_zero_beta_true_root
        (N, V, 22, 3) (the predicted pose with the true root orientation); ``gt``: phi, tau, j3d_cam
        (N, V, 22, 3), joints_zero_beta, index (N,). CPU tensors.
    """
    device = torch.device(device)
    if isinstance(body, str):
        body = BodyForward(load_body_model(body, "neutral"), vertices=None)
    body = body.to(device)
    model = model.to(device).eval()
    loader = DataLoader(dataset, batch_size=batch_size, shuffle=False, num_workers=num_workers)
    preds: dict[str, list] = {}
    gts: dict[str, list] = {}
    n = 0
    for batch in loader:
        batch = {k: v.to(device) if isinstance(v, torch.Tensor) else v for k, v in batch.items()}
        if "features" in batch:
            feat = batch["features"] if feature_cut is None else model.features_from(batch["features"], feature_cut)
            out = model.regress(feat, batch["P"])
            size = int(batch["crop_size"][0])
        else:
            out = model(batch["images"], batch["P"])
            size = int(batch["images"].shape[-1])
        p = dict(to_smplx_params(out, batch["P"], batch["K"], input_size=size))
        p["joints"], _ = body(p["theta"], p["beta"], p["phi"], p["tau"], vertices=False)
        zero = torch.zeros_like(p["beta"])
        p["joints_zero_beta"], _ = body(p["theta"], zero, p["phi"], vertices=False)
        # the body pose alone: the same body with the true root orientation (Table I's extra column)
        p["joints_zero_beta_true_root"], _ = body(p["theta"], zero, batch["phi"].to(p["theta"].dtype), vertices=False)
        for k, v in p.items():
            preds.setdefault(k, []).append(v.float().cpu())
        theta_gt = axis_angle_to_matrix(batch["theta"].to(p["theta"].dtype)).unsqueeze(1).expand_as(p["theta"])
        gt_zero, _ = body(theta_gt, zero, batch["phi"].to(p["theta"].dtype), vertices=False)
        gts.setdefault("joints_zero_beta", []).append(gt_zero.float().cpu())
        for k in ("phi", "tau", "j3d_cam", "index"):
            if k in batch:
                gts.setdefault(k, []).append(batch[k].cpu())
        n += batch["phi"].shape[0]
        if max_samples is not None and n >= max_samples:
            break
    cat = lambda d: {k: torch.cat(v)[:max_samples] for k, v in d.items()}  # noqa: E731
    return cat(preds), cat(gts)


def evaluate(model: nn.Module, dataset, method: str = "", **predict_kwargs) -> dict[str, pd.DataFrame]:
    """Tables of a model on a dataset: ``per_view``, ``per_joint`` and (two views or more)
    ``relative_camera`` (see :mod:`airpose_lib.eval.tables`)."""
    pred, gt = predict(model, dataset, **predict_kwargs)
    ids = gt.get("index")
    tables = {"per_view": per_view_table(pred, gt, method, ids), "per_joint": per_joint_table(pred, gt, method, ids)}
    if pred["tau"].shape[1] >= 2:
        tables["relative_camera"] = relative_camera_table(pred, gt, method, ids)
    return tables


def load_network(checkpoint: str | Path, device: str | torch.device = "cpu") -> tuple[nn.Module, NetworkRecord, dict]:
    """The network of a kit checkpoint (training or fine-tuning), its network record and the
    checkpoint, from one read of the file.

    Args:
        checkpoint: a ``checkpoints/*.pt`` of ``airpose train`` or ``airpose finetune`` (or a
            converted official file, ``train.official.save_kit_checkpoint``).
        device: ``auto``, ``cpu``, ``cuda``, ``cuda:N`` (:func:`airpose_lib.engine.launch.resolve_device`).

    Returns:
        ``(model, record, state)``: the network in eval mode on ``device``
        (:func:`airpose_lib.model.record.network_from_checkpoint`), its
        :class:`~airpose_lib.model.record.NetworkRecord` (old checkpoints: crop size and camera
        from their data, :func:`airpose_lib.data.still.training_input.training_input`) and the loaded
        checkpoint dict (``config``, ``step``, ...).
    """
    device = resolve_device(str(device))
    state = load_checkpoint(checkpoint)
    model, record = network_from_checkpoint(state, legacy=training_input)
    return model.to(device).eval(), record, state


def load_trained_model(checkpoint: str | Path, device: str | torch.device = "cpu") -> tuple[nn.Module, TrainConfig]:
    """The network of a training checkpoint (:func:`load_network`) on ``device`` and its
    :class:`TrainConfig`."""
    model, _, state = load_network(checkpoint, device)
    return model, TrainConfig.from_dict(state["config"])


def evaluate_checkpoint(checkpoint: str | Path, split: str = "test", method: str | None = None,
                        data: dict | None = None, batch_size: int = 8, device: str | torch.device = "auto",
                        max_samples: int | None = None, crops: str | None = None) -> dict[str, pd.DataFrame]:
    """Evaluate a checkpoint on a split of the dataset it was trained with (or ``data`` kwargs).

    ``crops="tight"`` evaluates on the test split's tight-box crops instead of the jittered ones.
    A checkpoint of the ``regressor`` task is evaluated on the cached features of its backbone.
    """
    device = resolve_device(str(device))
    model, cfg = load_trained_model(checkpoint, device)
    if data is not None:
        cfg = cfg.replace(data=dict(data))
    if crops is not None:
        cfg = cfg.replace(data=dict(cfg.data, crops=crops))
    dataset = default_dataset_factory(prepare_data(cfg, progress=False, device=device), split)
    return evaluate(model, dataset, method or cfg.variant, batch_size=batch_size, device=device,
                    max_samples=max_samples, body=cfg.body_source, feature_cut=cfg.trainable_from)


def evaluate_features(checkpoint: str | Path, backbone_file: str | Path, data_root: str | Path, method: str,
                      split: str = "test", crops: str = "jittered", max_samples: int | None = None,
                      batch_size: int = 64) -> dict[str, pd.DataFrame]:
    """Evaluate a checkpoint of a frozen shared backbone on any dataset's split through the cached
    features of ``backbone_file`` (computed once per dataset, split and crops, shared by every
    variant; the checkpoint's own training data need not exist). A checkpoint that trained the
    backbone's last blocks (``trainable_from``) reads the cached input of its first such block and
    runs its own blocks.

    Returns:
        :func:`evaluate`'s tables.
    """
    model, cfg = load_trained_model(checkpoint, "cpu")
    features = ensure_features(backbone_file, data_root, split, crops=crops, cut=cfg.trainable_from)
    dataset = FeatureDataset(data_root, split, features, crops=crops, augment=False)
    return evaluate(model, dataset, method, batch_size=batch_size, body=cfg.body_source, max_samples=max_samples,
                    feature_cut=cfg.trainable_from)
