"""Kinematic trees and 2D keypoints drawn with matplotlib.

A skeleton is joints plus either a parent array (``parents[j]`` is the parent of joint ``j``,
-1 for the root, as ``SMPLX_PARENTS``) or an explicit edge list (for keypoint sets like
OpenPose BODY_25 that are not trees of the body model's joints; the keypoint sets and their
edges live in ``airpose_lib.body``). Limbs are coloured by body side when joint names are
given (``left_knee``, ``LKnee``, ``l_knee`` ...).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from airpose_lib.viz.style import SIDE_COLORS

__all__ = [
    "edges_from_parents",
    "joint_side",
    "plot_skeleton_3d",
    "plot_keypoints_2d",
]


def edges_from_parents(parents: Sequence[int] | np.ndarray) -> list[tuple[int, int]]:
    """(parent, child) pairs of a kinematic tree given ``parents`` (J,), -1 marking roots."""
    return [(int(p), j) for j, p in enumerate(np.asarray(parents).tolist()) if p >= 0]


def joint_side(name: str) -> str:
    """``"left"``, ``"right"`` or ``"centre"`` from a joint name in SMPL-X or OpenPose style."""
    low = name.lower()
    if low.startswith(("left", "l_", "l.")) or (len(name) > 1 and name[0] == "L" and name[1].isupper()):
        return "left"
    if low.startswith(("right", "r_", "r.")) or (len(name) > 1 and name[0] == "R" and name[1].isupper()):
        return "right"
    return "centre"


def _edge_colors(edges, names, color) -> list:
    if color is not None:
        return [color] * len(edges)
    if names is None:
        return [SIDE_COLORS["centre"]] * len(edges)
    out = []
    for a, b in edges:
        sides = {joint_side(names[a]), joint_side(names[b])} - {"centre"}
        out.append(SIDE_COLORS[sides.pop()] if len(sides) == 1 else SIDE_COLORS["centre"])
    return out


def _resolve_edges(parents, edges) -> list[tuple[int, int]]:
    if (parents is None) == (edges is None):
        raise ValueError("give exactly one of `parents` and `edges`")
    return edges_from_parents(parents) if edges is None else [tuple(map(int, e)) for e in edges]


def plot_skeleton_3d(
    ax,
    joints: np.ndarray,
    parents: Sequence[int] | np.ndarray | None = None,
    *,
    edges: Sequence[tuple[int, int]] | None = None,
    names: Sequence[str] | None = None,
    label_joints: bool = False,
    labels: Sequence[str] | None = None,
    color: str | None = None,
    marker_size: float = 12.0,
    line_width: float = 2.0,
):
    """Draw a skeleton in a matplotlib 3D axis, world Y shown upwards.

    SMPL-X world axes (Y up, subject facing +Z) are shown as matplotlib (x, y, z) =
    (X, -Z, Y), a proper rotation, so the default 3D view sees the subject from the front.

    Args:
        ax: an ``Axes3D`` (``fig.add_subplot(projection="3d")``).
        joints: (J, 3) positions, metres.
        parents: (J,) parent indices (-1 = root); or give ``edges``.
        edges: (E, 2) joint index pairs.
        names: (J,) joint names: colours limbs by side and labels joints if ``label_joints``.
        label_joints: write a label next to each joint: ``labels`` if given, else ``names``.
        labels: (J,) label texts, e.g. joint indices (shorter than names in crowded places).
        color: one colour for all limbs instead of per-side colours.
    Returns:
        ``ax``.
    """
    from matplotlib.ticker import MaxNLocator

    j = np.asarray(joints, dtype=np.float64)
    p = np.stack([j[:, 0], -j[:, 2], j[:, 1]], axis=1)
    edges = _resolve_edges(parents, edges)
    for (a, b), c in zip(edges, _edge_colors(edges, names, color)):
        ax.plot(*p[[a, b]].T, color=c, linewidth=line_width)
    ax.scatter(*p.T, s=marker_size, color="black", depthshade=False, zorder=3)
    text = labels if labels is not None else names
    if label_joints and text is not None:
        for k, label in enumerate(text[: len(p)]):
            ax.text(*p[k], f" {label}", fontsize=6)
    # Equal scale on all axes: metres look like metres.
    centre = (p.max(0) + p.min(0)) / 2
    half = (p.max(0) - p.min(0)).max() / 2 * 1.05
    ax.set_xlim(centre[0] - half, centre[0] + half)
    ax.set_ylim(centre[1] - half, centre[1] + half)
    ax.set_zlim(centre[2] - half, centre[2] + half)
    ax.set_box_aspect((1, 1, 1))
    for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
        axis.set_major_locator(MaxNLocator(4))
    ax.set_xlabel("X [m]")
    ax.set_ylabel("-Z [m]")
    ax.set_zlabel("Y [m]")
    return ax


def plot_keypoints_2d(
    ax,
    keypoints: np.ndarray,
    edges: Sequence[tuple[int, int]] | None = None,
    *,
    parents: Sequence[int] | np.ndarray | None = None,
    image: np.ndarray | None = None,
    names: Sequence[str] | None = None,
    visible: np.ndarray | None = None,
    label_joints: bool = False,
    color: str | None = None,
    marker_size: float = 14.0,
    line_width: float = 2.0,
):
    """Draw 2D keypoints (pixels, y down) and their skeleton, optionally over an image.

    Args:
        ax: a 2D matplotlib axis.
        keypoints: (J, 2) pixel coordinates (u right, v down).
        edges: (E, 2) index pairs, e.g. ``airpose_lib.body.BODY_25_EDGES``; or give ``parents``.
        image: (H, W, 3) image shown underneath; the axis then spans the image.
        names: (J,) names: colour limbs by side, label points if ``label_joints``.
        visible: (J,) bool or confidences (> 0 = drawn); hidden points and their limbs are skipped.
    Returns:
        ``ax``.
    """
    kp = np.asarray(keypoints, dtype=np.float64)
    vis = np.ones(len(kp), bool) if visible is None else np.asarray(visible) > 0
    vis &= np.isfinite(kp).all(1)
    if image is not None:
        ax.imshow(image)
    if edges is None and parents is None:
        edges = []
    else:
        edges = _resolve_edges(parents, edges)
    for (a, b), c in zip(edges, _edge_colors(edges, names, color)):
        if vis[a] and vis[b]:
            ax.plot(kp[[a, b], 0], kp[[a, b], 1], color=c, linewidth=line_width)
    ax.scatter(kp[vis, 0], kp[vis, 1], s=marker_size, color="white", edgecolors="black",
               linewidths=0.8, zorder=3)
    if label_joints and names is not None:
        for k in np.flatnonzero(vis):
            ax.annotate(names[k], kp[k], fontsize=6, xytext=(3, 3), textcoords="offset points")
    if image is not None:
        h, w = image.shape[:2]
        ax.set_xlim(-0.5, w - 0.5)
        ax.set_ylim(h - 0.5, -0.5)
    else:
        ax.invert_yaxis()
        ax.set_aspect("equal")
    ax.set_axis_off()
    return ax
