"""Notebook 00's figures of the body model: rendered views side by side, the shape-space sweep,
BODY_25 keypoints on a render and the 22 body joints in 3D."""
from __future__ import annotations

from collections.abc import Mapping, Sequence

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from airpose_lib.body import BODY22_NAMES, BODY_25_EDGES, BODY_25_FROM_SMPLX, BODY_25_NAMES, SMPLX_PARENTS

from .skeleton import plot_keypoints_2d, plot_skeleton_3d

__all__ = ["plot_views", "plot_beta_sweep", "plot_body25_keypoints", "plot_body22_skeletons"]


def plot_views(views: Sequence, titles: Sequence[str], suptitle: str | None = None):
    """Renders (objects with an ``image`` ``(H, W, 3)``, :func:`~airpose_lib.viz.render.render_views`)
    in one row, one title each."""
    fig, axes = plt.subplots(1, len(views), figsize=(2.6 * len(views), 3.0))
    for ax, v, title in zip(np.atleast_1d(axes), views, titles):
        ax.imshow(v.image)
        ax.set_title(title)
        ax.set_axis_off()
    if suptitle:
        fig.suptitle(suptitle)
    return fig


def plot_beta_sweep(images: Mapping[tuple[int, float], np.ndarray], statures: pd.DataFrame,
                    components: Sequence[int], beta_values: Sequence[float]):
    """One row per shape component, one column per value, the stature under each render.

    Args:
        images: ``(component, value)`` -> ``(H, W, 3)`` render.
        statures: index ``beta_<component + 1>``, columns the values, metres.
    """
    fig, axes = plt.subplots(len(components), len(beta_values),
                             figsize=(2.0 * len(beta_values), 2.3 * len(components)), squeeze=False)
    for r, k in enumerate(components):
        for c, b in enumerate(beta_values):
            ax = axes[r, c]
            ax.imshow(images[k, b])
            ax.set_title(f"$\\beta_{k + 1}$ = {b:+.1f}\n{statures.loc[f'beta_{k + 1}', b]:.2f} m", fontsize=8)
            ax.set_axis_off()
    fig.suptitle("shape space: first three components (stature under each render)")
    return fig


def plot_body25_keypoints(view, joints: np.ndarray, label_joints: bool = False):
    """The BODY_25 keypoints of SMPL-X ``joints (J, 3)`` projected with a render's camera
    (``view.project``) onto its image; keypoints without a model joint are hidden."""
    idx = np.asarray(BODY_25_FROM_SMPLX)
    keypoints = view.project(joints[np.clip(idx, 0, None)])  # (25, 2) pixels
    fig, ax = plt.subplots(figsize=(5, 5))
    plot_keypoints_2d(ax, keypoints, BODY_25_EDGES, image=view.image, names=BODY_25_NAMES,
                      visible=idx >= 0, label_joints=label_joints)
    ax.set_title("BODY_25 keypoints projected with the render's camera")
    return fig


def plot_body22_skeletons(poses: Mapping[str, np.ndarray]):
    """The 22 SMPL-X body joints of two poses in 3D (``title -> joints (J, 3)``; the first with
    joint indices) and the joint table."""
    fig = plt.figure(figsize=(11, 4.8))
    for i, (title, joints) in enumerate(poses.items()):
        ax = fig.add_subplot(1, 3, i + 1, projection="3d")
        plot_skeleton_3d(ax, joints[:22], SMPLX_PARENTS[:22], names=BODY22_NAMES,
                         label_joints=(i == 0), labels=[str(k) for k in range(22)])
        ax.view_init(elev=10, azim=-70)
        ax.set_title(title)
    table = "\n".join(f"{k:>2}  {name}  (parent {SMPLX_PARENTS[k]})" for k, name in enumerate(BODY22_NAMES))
    fig.text(0.70, 0.5, table, family="monospace", fontsize=7, va="center")
    fig.suptitle("the 22 SMPL-X body joints used for MPJPE (blue = left, vermillion = right)")
    return fig
