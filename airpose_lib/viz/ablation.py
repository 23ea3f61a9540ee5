"""Figures of the ablation (notebook 02): Table I as bars next to the reference and the paper, and
each variant's estimate on a few test samples (skeletons, positions, meshes)."""
from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import pandas as pd

from airpose_lib.body.joint_sets import SMPLX_PARENTS

from .style import METHOD_COLORS, VIEW_COLORS, method_color
from .trajectories import plot_mesh_overlays

__all__ = ["SOURCE_COLORS", "plot_table1", "plot_ablation_samples", "plot_ablation_meshes"]

#: Bar colours of :func:`plot_table1`, one per source of numbers (the methods are on the x axis).
SOURCE_COLORS = {"kit": "#0072B2", "reference": "#56B4E9", "paper": "#999999"}


#: Dash styles of :func:`plot_table1`'s line rows, in order.
_LINE_STYLES = ("--", ":", "-.")

#: Markers of the per-view position estimates (UAV1, UAV2, ...) in the top views.
VIEW_MARKERS = "o^sD"

def plot_table1(table: pd.DataFrame, reference: pd.DataFrame | None = None, kit_label: str = "kit",
                metrics: tuple[str, ...] = ("MPE", "MPJPE"), line_rows: Sequence[str] = ()):
    """Table I as grouped bars: this run (seed std as error bars), the committed reference and
    the paper, one panel per metric on a log axis (the kit's and the paper's MPE can differ by
    more than 10x; a linear axis would flatten the paper's bars).

    Args:
        table: :func:`airpose_lib.eval.ablation.ablation_table` (``<metric> [m]``, ``<metric> std [m]``,
            ``<metric> paper [m]``); a row named in ``line_rows`` (the mean-body references,
            ``eval.mean_body.MEAN_BODY_LABELS``) is drawn as a horizontal line, one dash style
            each, on the panels where it has a value, not as bars.
        reference: Table I of the committed reference (``results/<profile>/table1.csv``) or None.
        kit_label: legend entry of this run's bars (e.g. ``"kit (cpu, 3 seeds)"``).
    Returns:
        the figure; the legend sits above the panels, clear of the bars.
    """
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    rows = [m for m in table.index if m not in line_rows]
    sources = [("kit", kit_label, table)] + ([("reference", "committed reference", reference)]
                                             if reference is not None else []) + [("paper", "paper", None)]
    width = 0.8 / len(sources)
    fig, axes = plt.subplots(1, len(metrics), figsize=(5.2 * len(metrics), 3.9), squeeze=False)
    handles = [Patch(color=SOURCE_COLORS[key], label=label) for key, label, _ in sources]
    x = np.arange(len(rows))
    for ax, metric in zip(axes[0], metrics):
        values = []
        for k, (key, _, src) in enumerate(sources):
            if key == "paper":
                y, err = table.loc[rows, f"{metric} paper [m]"].to_numpy(float), None
            else:
                y = src[f"{metric} [m]"].reindex(rows).to_numpy(float)
                std = src[f"{metric} std [m]"].reindex(rows).to_numpy(float) if f"{metric} std [m]" in src else None
                err = None if std is None or np.isnan(std).all() else np.nan_to_num(std)
            xs = x + (k - (len(sources) - 1) / 2) * width
            ax.bar(xs, y, width=width * 0.95, color=SOURCE_COLORS[key], yerr=err, capsize=2,
                   error_kw={"lw": 0.8})
            tops = y + (err if err is not None else 0.0)  # labels above the error bars
            for xi, yi, top in zip(xs, y, tops):
                if np.isfinite(yi):
                    ax.annotate(f"{yi:.2f}" if yi >= 0.995 else f"{yi:.3f}", (xi, top), xytext=(0, 2),
                                textcoords="offset points", ha="center", va="bottom", fontsize=6, rotation=90)
            values.append(y)
        for label, dashes in zip(line_rows, _LINE_STYLES):
            level = table[f"{metric} [m]"].get(label, np.nan)
            if np.isfinite(level):
                ax.axhline(level, color=METHOD_COLORS["Ground truth"], ls=dashes, lw=1.2)
                values.append(np.array([level]))
                if not any(h.get_label() == label for h in handles):
                    handles.append(Line2D([], [], color=METHOD_COLORS["Ground truth"], ls=dashes, label=label))
        finite = np.concatenate(values)
        finite = finite[np.isfinite(finite) & (finite > 0)]
        ax.set_yscale("log")
        if finite.size:  # head room above the tallest bar for its value label
            ax.set_ylim(finite.min() / 2.5, finite.max() * 4.0)
        ax.set_xticks(x, [m.replace(" + ", "\n+ ") for m in rows], fontsize=8)
        ax.set_ylabel(f"{metric} [m] (log scale)")
        ax.set_title(metric)
    # the reference lines' labels are long: at most three entries a row, the panels below the rows
    ncol = min(len(handles), 3)
    fig.legend(handles=handles, loc="upper center", ncol=ncol, frameon=False, fontsize=8,
               bbox_to_anchor=(0.5, 1.0))
    fig.tight_layout(rect=(0, 0, 1, 0.96 - 0.06 * -(-len(handles) // ncol)))
    return fig


def plot_ablation_samples(crops: np.ndarray, joints_crop: Mapping[str, np.ndarray], gt_crop: np.ndarray,
                          positions_world: Mapping[str, np.ndarray], gt_world: np.ndarray,
                          title: str | None = None):
    """Rows = samples; per view the crop with every method's 22-joint skeleton, then a top view.

    Args:
        crops: (n, V, S, S, 3) uint8 network crops.
        joints_crop: method -> (n, V, 22, 2) predicted joints projected into the crop (pixels).
        gt_crop: (n, V, 22, 2) ground-truth joints in the crop.
        positions_world: method -> (n, V, 3) each view's estimate of the person's position (model
            origin) in the world frame (ground-truth extrinsics), Y up.
        gt_world: (n, 3) ground-truth position.
        title: figure title, placed above the legend (never over a panel title).
    """
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    n, V = crops.shape[:2]
    fig, axes = plt.subplots(n, V + 1, figsize=(2.7 * (V + 1), 2.7 * n + 0.6), squeeze=False,
                             layout="constrained")
    bones = [(j, p) for j, p in enumerate(SMPLX_PARENTS[:22]) if p >= 0]
    gt_colour = VIEW_COLORS["ground truth"]
    for i in range(n):
        for v in range(V):
            ax = axes[i, v]
            ax.imshow(crops[i, v])
            for method, uv in joints_crop.items():
                for j, p in bones:
                    ax.plot(uv[i, v, [j, p], 0], uv[i, v, [j, p], 1], color=method_color(method), lw=1.1)
            for j, p in bones:
                ax.plot(gt_crop[i, v, [j, p], 0], gt_crop[i, v, [j, p], 1], color=gt_colour, lw=1.0, ls="--")
            S = crops.shape[2]
            ax.set_xlim(0, S)
            ax.set_ylim(S, 0)
            ax.set_title(f"sample {i + 1}, UAV{v + 1} crop")
            ax.set_xticks([])
            ax.set_yticks([])
            ax.grid(False)
        ax = axes[i, V]
        for method, pos in positions_world.items():
            for v, marker in zip(range(V), VIEW_MARKERS):
                ax.scatter(pos[i, v, 0], pos[i, v, 2], color=method_color(method), marker=marker, s=28,
                           edgecolor="black", linewidth=0.3)
        ax.scatter(gt_world[i, 0], gt_world[i, 2], color=gt_colour, marker="*", s=110, edgecolor="black",
                   linewidth=0.3)
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_xlabel("x [m]")
        ax.set_ylabel("z [m]")
        ax.set_title(f"sample {i + 1}: position from above")
    handles = [Line2D([], [], color=method_color(m), lw=1.5, label=m) for m in joints_crop]
    handles.append(Line2D([], [], color=gt_colour, lw=1.2, ls="--", label="ground truth"))
    handles += [Line2D([], [], color="0.3", marker=mk, ls="", label=f"estimate from UAV{v + 1}")
                for v, mk in zip(range(V), VIEW_MARKERS)]
    handles.append(Line2D([], [], color=gt_colour, marker="*", ms=9, ls="", label="true position"))
    if title:
        fig.suptitle(title)
    fig.legend(handles=handles, loc="outside lower center", ncol=min(len(handles), 4), frameon=False)
    return fig


def plot_ablation_meshes(crops: np.ndarray, vertices: Mapping[str, np.ndarray], faces: np.ndarray,
                         K_crop: np.ndarray, title: str | None = None):
    """Each estimate's body mesh rendered into the crops with the crop's own intrinsics (mesh and
    image align exactly when the estimate is right), ground truth first.

    Args:
        crops: ``(n, V, S, S, 3)`` uint8 crops.
        vertices: method -> ``(n, V, Nv, 3)`` camera-frame vertices.
        faces: ``(M, 3)`` triangles.
        K_crop: ``(n, V, 3, 3)`` crop intrinsics.
        title: figure title, above the column titles (never over them).
    """
    n, V, S = crops.shape[:3]
    whole_crop = np.broadcast_to(np.array([[0.0, 0.0], [S - 1.0, S - 1.0]]), (n, V, 2, 2))
    return plot_mesh_overlays(crops, vertices, faces, K_crop, frame_labels=[f"sample {i + 1}" for i in range(n)],
                              zoom_points=whole_crop, title=title)
