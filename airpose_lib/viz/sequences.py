"""Figures of two-drone recordings: frames with keypoint detections, trajectories over time."""
from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from airpose_lib.body.joint_sets import BODY_25_EDGES

from .style import VIEW_COLORS

DETECTOR_COLORS = {"openpose": "#CC79A7", "alphapose": "#E69F00", "ground truth": VIEW_COLORS["ground truth"]}


def _zoom_box(points: np.ndarray, shape: tuple[int, int], margin: float = 0.35) -> tuple[int, int, int, int]:
    """Square window around (N, 2) points with a relative margin, clipped to the image."""
    lo, hi = points.min(0), points.max(0)
    centre, half = (lo + hi) / 2, (hi - lo).max() * (0.5 + margin) + 10
    h, w = shape
    x0, y0 = np.maximum(centre - half, 0).astype(int)
    x1, y1 = int(min(centre[0] + half, w)), int(min(centre[1] + half, h))
    return x0, y0, x1, y1


def plot_detections_grid(
    images: Sequence[Sequence[np.ndarray]],
    detections: Mapping[str, np.ndarray],
    ground_truth: np.ndarray | None = None,
    frame_labels: Sequence[str] | None = None,
    min_confidence: float = 0.05,
    edges: Mapping[str, Sequence[tuple[int, int]]] | None = None,
    title: str | None = None,
):
    """Frames (rows) x views (columns), zoomed on the person, with every detector's keypoints.

    Args:
        images: ``images[i][v]`` RGB (H, W, 3) of frame i in view v.
        detections: detector name -> (n, V, J, 3) ``[x, y, confidence]`` (missing = 0).
        ground_truth: (n, V, J, 2) projected keypoints, drawn as small crosses, or None.
        frame_labels: one title per row.
        min_confidence: keypoints below it are not drawn.
        edges: detector name -> limb pairs to draw (default: BODY_25 limbs for ``openpose``).
        title: figure title (wrapped to the figure's width).
    Returns:
        the matplotlib figure.
    """
    import matplotlib.pyplot as plt

    edges = dict(edges or {"openpose": BODY_25_EDGES})
    n, V = len(images), len(images[0])
    fig, axes = plt.subplots(n, V, figsize=(3.2 * V, 3.2 * n + 0.5), squeeze=False, layout="constrained")
    for i in range(n):
        for v in range(V):
            ax, img = axes[i, v], images[i][v]
            pts = [d[i, v, :, :2][d[i, v, :, 2] > min_confidence] for d in detections.values()]
            if ground_truth is not None:
                pts.append(ground_truth[i, v])
            pts = np.concatenate([p for p in pts if len(p)]) if any(len(p) for p in pts) else None
            ax.imshow(img)
            if pts is not None:
                x0, y0, x1, y1 = _zoom_box(pts, img.shape[:2])
                ax.set_xlim(x0, x1)
                ax.set_ylim(y1, y0)
            for name, det in detections.items():
                colour = DETECTOR_COLORS.get(name, "k")
                kp, ok = det[i, v, :, :2], det[i, v, :, 2] > min_confidence
                for a, b in edges.get(name, ()):
                    if ok[a] and ok[b]:
                        ax.plot(kp[[a, b], 0], kp[[a, b], 1], color=colour, lw=0.8, alpha=0.7)
                ax.scatter(kp[ok, 0], kp[ok, 1], s=9, color=colour, label=name if (i, v) == (0, 0) else None)
            if ground_truth is not None:
                g = ground_truth[i, v]
                ax.scatter(g[:, 0], g[:, 1], marker="+", s=16, lw=0.8, color=DETECTOR_COLORS["ground truth"],
                           label="ground truth" if (i, v) == (0, 0) else None)
            ax.set_title(f"UAV{v + 1}" + (f", {frame_labels[i]}" if frame_labels else ""), fontsize=8)
            ax.set_xticks([])
            ax.set_yticks([])
            ax.grid(False)
    fig.legend(loc="outside lower center", ncol=len(detections) + 1, frameon=False)
    if title:
        import textwrap

        fig.suptitle("\n".join(textwrap.wrap(title, width=int(13 * 3.2 * V))))
    return fig


def plot_recording_overview(camera_centres: np.ndarray, person_positions: np.ndarray, timestamps: np.ndarray,
                            title: str | None = None):
    """Top view of a recording (drone and person paths) and the clock offset between the drones.

    Args:
        camera_centres: (F, V, 3) drone camera positions in the world (Y up).
        person_positions: (F, 3) person (pelvis) positions in the world.
        timestamps: (F, V) capture time of each view's frame, seconds.
        title: figure title.
    """
    import matplotlib.pyplot as plt

    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 4), layout="constrained")
    a.plot(person_positions[:, 0], person_positions[:, 2], color=VIEW_COLORS["ground truth"], label="person")
    for v in range(camera_centres.shape[1]):
        c = camera_centres[:, v]
        a.plot(c[:, 0], c[:, 2], color=VIEW_COLORS[f"camera {v + 1}"], label=f"UAV{v + 1}")
        a.scatter(c[0, 0], c[0, 2], color=VIEW_COLORS[f"camera {v + 1}"], marker="^")
    a.set_aspect("equal")
    a.set_xlabel("x [m]")
    a.set_ylabel("z [m]")
    a.set_title("paths seen from above (triangles: start)")
    a.legend(fontsize=7)
    t = timestamps - timestamps[0, 0]
    offsets = 1e3 * (t[:, 1:] - t[:, :1])  # (F, V-1) ms
    for v in range(offsets.shape[1]):
        b.plot(t[:, 0], offsets[:, v], label=f"UAV{v + 2} - UAV1")
    centre = float(np.round(offsets.mean(), 3))
    b.set_ylim(min(centre - 5.0, offsets.min() - 1.0), max(centre + 5.0, offsets.max() + 1.0))
    b.ticklabel_format(useOffset=False)
    b.set_xlabel("UAV1 time [s]")
    b.set_ylabel("shutter offset [ms]")
    b.set_title(f"time stamps of matching frames (mean offset {centre:.1f} ms)")
    b.legend(fontsize=7)
    if title:
        fig.suptitle(title)
    return fig
