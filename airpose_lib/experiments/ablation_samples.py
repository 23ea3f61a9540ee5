"""Notebook 02's qualitative figures: :func:`ablation_samples` runs the first seed's network of
every variant on the first ``n`` test samples and returns, ready to plot
(:mod:`airpose_lib.viz.ablation`), the crops, the predicted and ground-truth 22 body joints in crop
pixels, each view's estimate of the person position in the world frame, and every estimate's body
mesh in the camera frame (ground truth with the subject's own gendered shape first).
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import torch

from airpose_lib.body import load_body_model
from airpose_lib.body.genders import GENDER_NAMES
from airpose_lib.geometry import axis_angle_to_matrix, crop_intrinsics, full_to_crop_pixels, project_points
from airpose_lib.model import posed_joints_and_vertices
from airpose_lib.model.official import load_official_checkpoint
from airpose_lib.train import load_trained_model, predict

__all__ = ["AblationSamples", "ablation_samples"]


@dataclass
class AblationSamples:
    """Inputs of :func:`airpose_lib.viz.ablation.plot_ablation_samples` and ``plot_ablation_meshes``.

    Attributes:
        crops: ``(n, V, S, S, 3)`` uint8 network crops.
        joints_crop: method -> ``(n, V, 22, 2)`` predicted joints projected into the crop.
        gt_crop: ``(n, V, 22, 2)`` ground-truth joints in the crop.
        positions_world: method -> ``(n, V, 3)`` each view's position estimate, world frame.
        gt_world: ``(n, 3)`` ground-truth position.
        vertices: ``"Ground truth"`` then each method -> ``(n, V, Nv, 3)`` camera-frame vertices.
        faces: ``(M, 3)`` triangles of the neutral body.
        K_crop: ``(n, V, 3, 3)`` intrinsics of the crops.
    """

    crops: np.ndarray
    joints_crop: dict[str, np.ndarray]
    gt_crop: np.ndarray
    positions_world: dict[str, np.ndarray]
    gt_world: np.ndarray
    vertices: dict[str, np.ndarray]
    faces: np.ndarray
    K_crop: np.ndarray


def _network(run, official: bool):
    if official:
        return load_official_checkpoint(run.checkpoint, variant=run.variant, backbone=None)
    return load_trained_model(run.checkpoint)[0]


def ablation_samples(runs: Mapping, dataset, n: int, official: bool = False) -> AblationSamples:
    """Estimates of the first seed's networks on the first ``n`` samples of a test split.

    Args:
        runs: (variant, seed) -> ``AblationRun`` (``checkpoint``, ``variant``, ``tables["per_view"]``
            whose ``method`` names the row).
        dataset: the test split (``StillFrameDataset``, or ``OfficialSyntheticDataset`` when
            ``official``).
        n: number of samples.
        official: the authors' checkpoints and SMPL-X (else the kit's networks and open body).
    """
    idx = list(range(min(n, len(dataset))))
    subset = torch.utils.data.Subset(dataset, idx)
    arr = dataset.arrays_for(idx) if official else {k: v[idx] for k, v in dataset.arrays.items()}
    S = dataset.crop_size
    K = torch.from_numpy(arr["K"]).double()
    bbox = torch.from_numpy(arr["bbox"]).double()
    R_cw, t_cw = arr["R_cw"], arr["t_cw"]
    source = "smplx" if official else "open"
    first_seed = min(seed for _, seed in runs)
    joints_crop, positions, params_of = {}, {}, {}
    for (_, seed), run in runs.items():
        if seed != first_seed:
            continue
        pred, _ = predict(_network(run, official), subset, batch_size=len(idx), body=source)
        label = run.tables["per_view"]["method"].iloc[0]
        params_of[label] = {k: pred[k].double() for k in ("phi", "theta", "beta", "tau")}
        uv = project_points(pred["joints"].double(), K)  # (n, V, 22, 2) full-frame pixels
        joints_crop[label] = full_to_crop_pixels(uv, bbox, S).numpy()
        positions[label] = np.einsum("nvji,nvj->nvi", R_cw, pred["tau"].double().numpy() - t_cw)  # R^T (tau - t)
    gt_uv = project_points(torch.from_numpy(arr["j3d_cam"]).double(), K)
    gt_world = np.einsum("nji,nj->ni", R_cw[:, 0], arr["tau"][:, 0] - t_cw[:, 0])  # R^T (tau - t), view 1

    V = arr["phi"].shape[1]
    gt_vertices = []
    for i in range(len(idx)):  # ground truth with the sample's own (gendered) body
        gendered = load_body_model(source, GENDER_NAMES[int(arr["gender"][i])], dtype=torch.float64)
        p = {"phi": torch.from_numpy(arr["phi"][i]).double(), "tau": torch.from_numpy(arr["tau"][i]).double(),
             "theta": axis_angle_to_matrix(torch.from_numpy(arr["theta"][i]).double()).expand(V, 21, 3, 3),
             "beta": torch.from_numpy(arr["beta"][i]).double().expand(V, 10)}
        gt_vertices.append(posed_joints_and_vertices(gendered, p)["vertices"].numpy())
    body = load_body_model(source, "neutral", dtype=torch.float64)
    vertices = {"Ground truth": np.stack(gt_vertices)}
    vertices.update({m: posed_joints_and_vertices(body, p)["vertices"].numpy() for m, p in params_of.items()})
    return AblationSamples(
        crops=np.stack([dataset.rgb(i) for i in idx]), joints_crop=joints_crop,
        gt_crop=full_to_crop_pixels(gt_uv, bbox, S).numpy(), positions_world=positions, gt_world=gt_world,
        vertices=vertices, faces=np.asarray(body.faces, np.int64), K_crop=crop_intrinsics(K, bbox, S).numpy())
