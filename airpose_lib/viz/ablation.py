"""Figures of the ablation (Table I): the table as bars next to the paper, and each variant's
estimate on a few test samples."""
from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from airpose_lib.body.joint_sets import SMPLX_PARENTS

from .style import PAPER_COLOR, VIEW_COLORS, method_color

__all__ = ["plot_table1", "plot_ablation_samples"]

#: Markers of the per-view position estimates (UAV1, UAV2, ...) in the top views.
VIEW_MARKERS = "o^sD"


def plot_table1(table, metrics: Sequence[str] = ("MPE", "MPJPE"), profile: str | None = None,
                title: str | None = None):
    """Table I as bars: the kit's value per variant (its colour, +- std over seeds) beside the
    paper's (grey, hatched), one panel per metric, the value written over every bar.

    Args:
        table: one row per variant (index: method names) with columns ``"<metric> [m]"``,
            optionally ``"<metric> std [m]"`` and ``"<metric> paper [m]"``.
        metrics: the panels.
        profile: named in the legend ("kit (smoke)").
        title: figure title (default: "Table I: kit next to the paper").

    A panel whose values span more than a factor 20 (a short training's errors next to the
    paper's) uses a log axis, so the paper's bars stay visible.
    """
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch

    fig, axes = plt.subplots(1, len(metrics), figsize=(4.6 * len(metrics), 3.6), squeeze=False,
                             layout="constrained")
    x = np.arange(len(table))
    for ax, metric in zip(axes[0], metrics):
        kit = table[f"{metric} [m]"].to_numpy(float)
        std = table[f"{metric} std [m]"].fillna(0).to_numpy(float) if f"{metric} std [m]" in table else None
        paper_col = f"{metric} paper [m]"
        paper = table[paper_col].to_numpy(float) if paper_col in table else np.full(len(table), np.nan)
        ax.bar(x - 0.2, kit, width=0.4, yerr=std, color=[method_color(m) for m in table.index],
               edgecolor="black", linewidth=0.5, capsize=2)
        ax.bar(x + 0.2, paper, width=0.4, color=PAPER_COLOR, hatch="///", edgecolor="0.35", linewidth=0.5)
        values = np.concatenate([kit, paper])
        values = values[np.isfinite(values) & (values > 0)]
        if len(values) and values.max() / values.min() > 20:
            ax.set_yscale("log")
        for xi, v in zip(np.concatenate([x - 0.2, x + 0.2]), np.concatenate([kit, paper])):
            if np.isfinite(v):
                ax.annotate(f"{v:.3g}", (xi, v), xytext=(0, 2), textcoords="offset points", ha="center",
                            va="bottom", fontsize=6.5)
        ax.set_xticks(x, [m.replace("+", "\n+") for m in table.index], fontsize=7.5)
        ax.set_ylabel(f"{metric} [m]")
        ax.set_title(metric)
        ax.margins(y=0.15)
        ax.grid(axis="x", visible=False)
    kit_label = f"kit, {profile} profile (colour = variant)" if profile else "kit (colour = variant)"
    handles = [Patch(facecolor="white", edgecolor="black", label=kit_label),
               Patch(facecolor=PAPER_COLOR, hatch="///", edgecolor="0.35", label="paper (RA-L 2022)")]
    fig.suptitle(title or "Table I: kit next to the paper")
    fig.legend(handles=handles, loc="outside lower center", ncol=2, frameon=False)
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
