"""The real-data figures of the paper, with ground truth: positions over time and mesh overlays.

- :func:`plot_person_positions`: the person's position (x, y, z) in each UAV's camera frame over
  time, one line per method (paper: Baseline vs AirPose vs AirPose+, both persons; the depth-only
  panel compares AirPose with the crop-only SPIN-style regressor).
- :func:`plot_relative_camera`: UAV2's position in UAV1's frame from the two per-view body poses.
- :func:`plot_mesh_overlays`: each method's mesh rendered over the frames of each view.

Methods named ``"<name> (pre-trained)"`` are drawn dashed in ``<name>``'s colour.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from .style import MESH_COLOR, METHOD_COLORS, method_color

__all__ = ["line_style", "plot_person_positions", "plot_relative_camera", "plot_mesh_overlays",
           "overlay_mesh"]

_AXES = {"x": 0, "y": 1, "z": 2}
_PRETRAINED = " (pre-trained)"


def line_style(method: str) -> dict:
    """Matplotlib style of a method's line: its colour, dashed when pre-trained."""
    base = method[: -len(_PRETRAINED)] if method.endswith(_PRETRAINED) else method
    try:
        color = method_color(base)
    except KeyError:
        color = "#777777"
    return {"color": color, "ls": "--" if base != method else "-", "lw": 1.1}


def _gt_style() -> dict:
    return {"color": METHOD_COLORS["Ground truth"], "lw": 2.2, "alpha": 0.55}


def plot_person_positions(positions: Mapping[str, np.ndarray], time_s: np.ndarray,
                          ground_truth: np.ndarray | None = None, axes: str = "xyz",
                          title: str = "", view_names: Sequence[str] | None = None):
    """The person's position relative to each UAV over time.

    Args:
        positions: method -> ``(F, V, 3)`` position (model origin) in each camera frame, metres.
        time_s: ``(F,)`` seconds.
        ground_truth: ``(F, V, 3)`` or None.
        axes: which coordinates to plot, rows of the figure (``"xyz"``, ``"z"`` ...).
        view_names: column titles (default ``UAV1, UAV2, ...``).

    Returns:
        the matplotlib figure (rows = coordinates, columns = views).
    """
    import matplotlib.pyplot as plt

    V = next(iter(positions.values())).shape[1]
    names = list(view_names) if view_names is not None else [f"UAV{v + 1}" for v in range(V)]
    fig, ax = plt.subplots(len(axes), V, figsize=(5.2 * V, 1.9 * len(axes) + 1.0), squeeze=False,
                           sharex=True, layout="constrained")
    for r, a in enumerate(axes):
        k = _AXES[a]
        for v in range(V):
            if ground_truth is not None:
                ax[r, v].plot(time_s, ground_truth[:, v, k], label="Ground truth", **_gt_style())
            for method, pos in positions.items():
                ax[r, v].plot(time_s, pos[:, v, k], label=method, **line_style(method))
            ax[r, v].set_ylabel(f"{a} [m]")
            if r == 0:
                ax[r, v].set_title(f"person in {names[v]}'s camera frame")
    for v in range(V):
        ax[-1, v].set_xlabel("time [s]")
    handles, labels = ax[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=min(len(labels), 6), frameon=False)
    if title:
        fig.suptitle(title)
    return fig


def plot_relative_camera(positions: Mapping[str, np.ndarray], time_s: np.ndarray,
                         ground_truth: np.ndarray | None = None, title: str = ""):
    """UAV2's position in UAV1's camera frame over time.

    Args:
        positions: method -> ``(F, 3)`` camera 2's centre in camera 1's frame, metres.
        time_s: ``(F,)`` seconds.
        ground_truth: ``(F, 3)`` or None.
    """
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 3, figsize=(12, 3.4), sharex=True, layout="constrained")
    for k, a in enumerate("xyz"):
        if ground_truth is not None:
            ax[k].plot(time_s, ground_truth[:, k], label="Ground truth", **_gt_style())
        for method, t in positions.items():
            ax[k].plot(time_s, t[:, k], label=method, **line_style(method))
        ax[k].set_title(f"UAV2 {a} in UAV1's frame")
        ax[k].set_xlabel("time [s]")
        ax[k].set_ylabel(f"{a} [m]")
    handles, labels = ax[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=min(len(labels), 6), frameon=False)
    if title:
        fig.suptitle(title)
    return fig


def overlay_mesh(image: np.ndarray, rgb: np.ndarray, depth: np.ndarray, alpha: float = 0.75) -> np.ndarray:
    """Blend a rendering over an image where the mesh was hit.

    Args:
        image, rgb: ``(H, W, 3)`` uint8; depth: ``(H, W)``, ``inf`` where nothing was hit.
    """
    hit = np.isfinite(depth)[..., None]
    out = image.astype(np.float32)
    out = np.where(hit, (1 - alpha) * out + alpha * rgb.astype(np.float32), out)
    return out.clip(0, 255).astype(np.uint8)


def _zoom(points: np.ndarray, shape: tuple[int, int], margin: float = 0.5) -> tuple[int, int, int, int]:
    """Square box (x0, y0, x1, y1) around 2D points with a relative margin, inside the image."""
    H, W = shape
    lo, hi = np.nanmin(points, axis=0), np.nanmax(points, axis=0)
    c = 0.5 * (lo + hi)
    half = 0.5 * max(hi - lo) * (1 + margin) + 8
    x0, y0 = int(max(0, c[0] - half)), int(max(0, c[1] - half))
    x1, y1 = int(min(W, c[0] + half)), int(min(H, c[1] + half))
    return x0, y0, max(x1, x0 + 2), max(y1, y0 + 2)


def plot_mesh_overlays(images: np.ndarray, vertices: Mapping[str, np.ndarray], faces: np.ndarray,
                       K: np.ndarray, frame_labels: Sequence[str] | None = None,
                       zoom_points: np.ndarray | None = None, title: str | None = None,
                       panel_in: float = 1.9):
    """Meshes of several methods over the frames of each view (rendered off-screen).

    Args:
        images: ``(n, V, H, W, 3)`` uint8 frames.
        vertices: method -> ``(n, V, N, 3)`` camera-frame vertices of that method's estimate.
        faces: ``(M, 3)`` triangles.
        K: ``(V, 3, 3)`` intrinsics of the images, or ``(n, V, 3, 3)`` per image (e.g. crops).
        frame_labels: n row titles.
        zoom_points: optional ``(n, V, J, 2)`` pixels to zoom on (e.g. ground-truth joints);
            default: the first method's projected vertices.
        title: figure title.
        panel_in: side of one panel in inches (the figure stays within a page's width for up
            to five methods).

    Returns:
        the figure: rows = (frame, view), columns = methods (titled in the method's colour);
        the row label (frame, UAV) is written in black on the left.
    """
    import matplotlib.pyplot as plt

    from .render import OffscreenRenderer  # VTK: imported only when a figure is rendered (optional GL)

    n, V, H, W = images.shape[:4]
    methods = list(vertices)
    M = len(methods)
    fig, ax = plt.subplots(n * V, M, figsize=(panel_in * M + 0.4, panel_in * n * V + 0.4), squeeze=False,
                           layout="constrained")
    K = np.asarray(K, dtype=np.float64)
    with OffscreenRenderer((W, H), K.reshape(-1, 3, 3)[0]) as renderer:
        for i in range(n):
            for v in range(V):
                Kiv = K[i, v] if K.ndim == 4 else K[v]
                if zoom_points is not None:
                    box = _zoom(zoom_points[i, v], (H, W))
                else:
                    vv = vertices[methods[0]][i, v]
                    uv = (vv @ Kiv.T)[:, :2] / vv[:, 2:3]
                    box = _zoom(uv, (H, W))
                x0, y0, x1, y1 = box
                for m, method in enumerate(methods):
                    rgb, depth = renderer.render(vertices[method][i, v], faces, MESH_COLOR, K=Kiv,
                                                 return_depth=True)
                    a = ax[i * V + v, m]
                    a.imshow(overlay_mesh(images[i, v], rgb, depth)[y0:y1, x0:x1])
                    a.set_xticks([])
                    a.set_yticks([])
                    a.grid(False)
                    if i == 0 and v == 0:
                        a.set_title(method, color=line_style(method)["color"], fontweight="bold")
                    if m == 0:
                        row = f"UAV{v + 1}" if frame_labels is None else f"{frame_labels[i]}\nUAV{v + 1}"
                        a.set_ylabel(row, color="black")
    if title:
        fig.suptitle(title)
    return fig
