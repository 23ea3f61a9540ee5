"""Qualitative figure of the ablation: each variant's estimate on a few test samples."""
from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from airpose_lib.body.joint_sets import SMPLX_PARENTS

from .style import VIEW_COLORS, method_color


def plot_ablation_samples(crops: np.ndarray, joints_crop: Mapping[str, np.ndarray], gt_crop: np.ndarray,
                          positions_world: Mapping[str, np.ndarray], gt_world: np.ndarray):
    """Rows = samples; per view the crop with every method's 22-joint skeleton, then a top view.

    Args:
        crops: (n, V, S, S, 3) uint8 network crops.
        joints_crop: method -> (n, V, 22, 2) predicted joints projected into the crop (pixels).
        gt_crop: (n, V, 22, 2) ground-truth joints in the crop.
        positions_world: method -> (n, V, 3) each view's estimate of the person's position (model
            origin) in the world frame (ground-truth extrinsics), Y up.
        gt_world: (n, 3) ground-truth position.
    """
    import matplotlib.pyplot as plt

    n, V = crops.shape[:2]
    fig, axes = plt.subplots(n, V + 1, figsize=(3.0 * (V + 1), 3.0 * n), squeeze=False)
    bones = [(j, p) for j, p in enumerate(SMPLX_PARENTS[:22]) if p >= 0]
    for i in range(n):
        for v in range(V):
            ax = axes[i, v]
            ax.imshow(crops[i, v])
            for method, uv in joints_crop.items():
                for j, p in bones:
                    ax.plot(uv[i, v, [j, p], 0], uv[i, v, [j, p], 1], color=method_color(method), lw=1.0,
                            label=method if (i, v, j) == (0, 0, bones[0][0]) else None)
            for j, p in bones:
                ax.plot(gt_crop[i, v, [j, p], 0], gt_crop[i, v, [j, p], 1], color=VIEW_COLORS["ground truth"],
                        lw=1.0, ls="--", label="ground truth" if (i, v, j) == (0, 0, bones[0][0]) else None)
            S = crops.shape[2]
            ax.set_xlim(0, S)
            ax.set_ylim(S, 0)
            ax.set_title(f"sample {i + 1}, UAV{v + 1}", fontsize=8)
            ax.set_xticks([])
            ax.set_yticks([])
            ax.grid(False)
        ax = axes[i, V]
        for method, pos in positions_world.items():
            for v, marker in zip(range(V), "o^sD"):
                ax.scatter(pos[i, v, 0], pos[i, v, 2], color=method_color(method), marker=marker, s=25)
        ax.scatter(gt_world[i, 0], gt_world[i, 2], color=VIEW_COLORS["ground truth"], marker="*", s=90)
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_title("position from above (x, z); o UAV1, ^ UAV2", fontsize=8)
    fig.legend(loc="lower center", ncol=len(joints_crop) + 1, frameon=False, fontsize=8)
    fig.tight_layout(rect=(0, 0.04, 1, 1))
    return fig
