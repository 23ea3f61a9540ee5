"""Notebook 01's figures of the synthetic still-frame data: crops with their joints, one sample's
scene from above and from the side, and the sampled distributions."""
from __future__ import annotations

from collections.abc import Sequence

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
import torch

from airpose_lib.body import SMPLX_PARENTS
from airpose_lib.geometry import full_to_crop_pixels

from .style import VIEW_COLORS

__all__ = ["plot_crop_grid", "plot_sample_scene", "plot_distributions", "distribution_table"]

#: Colour of the ground-truth joints drawn over the crops (visible on any background).
JOINT_COLOR = "#FFD400"


def plot_crop_grid(dataset, pick: Sequence[int]):
    """Both views' crops of the samples ``pick`` of a still-frame split, with the ground-truth
    22 body joints and each crop's vector P.

    Args:
        dataset: a ``StillFrameDataset`` (``arrays``, ``rgb(i)``, ``num_views``, ``crop_size``).
        pick: sample indices, one column each.
    """
    arr, V, S = dataset.arrays, dataset.num_views, dataset.crop_size
    fig, axes = plt.subplots(V, len(pick), figsize=(2.0 * len(pick), 2.1 * V), squeeze=False)
    for col, i in enumerate(pick):
        crops = dataset.rgb(int(i))
        for c in range(V):
            ax = axes[c, col]
            ax.imshow(crops[c])
            uv = full_to_crop_pixels(torch.from_numpy(arr["j2d"][i, c]).double(),
                                     torch.from_numpy(arr["bbox"][i, c]).double(), S).numpy()
            for j, parent in enumerate(SMPLX_PARENTS[:22]):
                if parent >= 0:
                    ax.plot(uv[[j, parent], 0], uv[[j, parent], 1], color=JOINT_COLOR, lw=0.6, alpha=0.55)
            ax.scatter(uv[:, 0], uv[:, 1], s=1.5, color=JOINT_COLOR, alpha=0.8)
            bx, by, s = arr["P"][i, c]
            ax.set_title(f"#{int(arr['index'][i])} view {c + 1}\nP=[{bx:+.2f}, {by:+.2f}, {s:.2f}]", fontsize=7)
            ax.set_xticks([])
            ax.set_yticks([])
            ax.grid(False)
    fig.suptitle(f"synthetic training crops ({S} px, both views; yellow: ground-truth joints)")
    return fig


def plot_sample_scene(arr: dict, i0: int, vertices: np.ndarray):
    """One sample's person and cameras among all samples' cameras and people, from above (x, z)
    and from the side (x, height y).

    Args:
        arr: the split's arrays (``cam_centre (N, V, 3)``, ``R_cw (N, V, 3, 3)``, ``t_wb (N, 3)``, ``index``).
        i0: the sample shown.
        vertices: ``(Nv, 3)`` its body in the world frame.
    """
    centres = arr["cam_centre"]  # (N, V, 3) optical centres in the world
    forward = arr["R_cw"][:, :, 2, :]  # (N, V, 3) optical axes in the world
    V = centres.shape[1]
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.8))
    for ax, (a, b, name) in zip(axes, ((0, 2, "from above (x, z)"), (0, 1, "from the side (x, height y)"))):
        ax.scatter(centres[:, :, a].ravel(), centres[:, :, b].ravel(), marker="x", s=8, color="0.6",
                   label="other cameras")
        if b == 2:
            ax.add_patch(plt.Rectangle((-2.75, -2.75), 5.5, 5.5, fill=False, ls="--", color="0.4", label="person area"))
            ax.scatter(arr["t_wb"][:, 0], arr["t_wb"][:, 2], s=4, color="0.75", label="other people")
        else:
            ax.axhline(0.0, color="0.4", lw=1, label="ground")
        ax.scatter(vertices[::15, a], vertices[::15, b], s=0.5, color=VIEW_COLORS["ground truth"], label="person")
        for c in range(V):
            col = VIEW_COLORS[f"camera {c + 1}"]
            p, d = centres[i0, c], forward[i0, c]
            ax.scatter(p[a], p[b], marker="^", s=60, color=col, label=f"camera {c + 1}")
            ax.annotate("", xy=(p[a] + 3 * d[a], p[b] + 3 * d[b]), xytext=(p[a], p[b]),
                        arrowprops=dict(arrowstyle="->", color=col))
        ax.set_aspect("equal")
        ax.set_xlabel("x [m]")
        ax.set_ylabel(("z" if b == 2 else "height y") + " [m]")
        ax.set_title(name)
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=len(labels), fontsize=8, bbox_to_anchor=(0.5, -0.02))
    fig.suptitle(f"sample #{int(arr['index'][i0])}: cameras around the origin at ~10 m, pitch 0-45 deg")
    return fig


def _distributions(arr: dict) -> dict[str, np.ndarray]:
    """Per view and sample: camera-person distance, camera pitch (deg), crop vector P."""
    return {"distance": np.linalg.norm(arr["tau"], axis=-1).ravel(),  # tau: model origin in each camera
            "pitch": np.degrees(np.arcsin(-arr["R_cw"][:, :, 2, 1])).ravel(),
            "P": arr["P"].reshape(-1, 3)}


def plot_distributions(arr: dict):
    """Histograms of the camera-person distance, camera pitch and crop scale s, and scatters of
    the person positions and of the crop centres (b_x, b_y)."""
    d = _distributions(arr)
    pos, P = arr["t_wb"], d["P"]
    fig, axes = plt.subplots(1, 5, figsize=(15, 3))
    axes[0].hist(d["distance"], bins=30, color="#0072B2")
    axes[0].set_xlabel("camera-person distance [m]")
    axes[1].hist(d["pitch"], bins=30, range=(0, 45), color="#0072B2")
    axes[1].set_xlabel("camera pitch [deg]")
    axes[2].scatter(pos[:, 0], pos[:, 2], s=3, color="#009E73")
    axes[2].set_aspect("equal")
    axes[2].set_xlabel("person x [m]")
    axes[2].set_ylabel("person z [m]")
    axes[3].hist(P[:, 2], bins=30, color="#E69F00")
    axes[3].set_xlabel("crop scale s")
    axes[4].scatter(P[:, 0], P[:, 1], s=3, color="#CC79A7")
    axes[4].set_xlabel("$b_x$")
    axes[4].set_ylabel("$b_y$")
    for ax in axes[[0, 1, 3]]:
        ax.set_ylabel("count")
    V = arr["P"].shape[1]
    fig.suptitle(f"{len(arr['P'])} training samples x {V} views")
    return fig


def distribution_table(arr: dict) -> pd.DataFrame:
    """``describe()`` of what :func:`plot_distributions` shows, rounded to 3 decimals."""
    d = _distributions(arr)
    P = d["P"]
    return pd.DataFrame({"distance [m]": d["distance"], "pitch [deg]": d["pitch"], "s": P[:, 2], "bx": P[:, 0],
                         "by": P[:, 1]}).describe().round(3)
