"""Figures of the online runtime (notebook 06): where each frame's time goes, latency and rate
against the paper, online = offline, and the slot states of a run with faults.

Inputs are the drones' records as :func:`airpose_lib.runtime.results.load_node_results` returns
them (``.frames`` arrays, ``.valid``, ``.meta``); this module only draws.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from .style import VIEW_COLORS

__all__ = ["PHASES", "SLOT_STATES", "plot_timeline", "plot_latency", "plot_online_vs_offline",
           "slot_states", "plot_fault_states"]

#: (start mark, end mark, colour, legend label) of each phase of a frame; None: not in the legend.
PHASES = [("wake", "captured", "0.8", "capture"), ("captured", "acquired", "#CC79A7", "acquisition"),
          ("stage1_start", "stage1_end", "#0072B2", "stage 1"), ("stage1_end", "stage2_start", "#E69F00", "exchange"),
          ("stage2_start", "stage2_end", "#009E73", "stage 2"), ("stage2_end", "stage3_start", "#E69F00", None),
          ("stage3_start", "stage3_end", "#D55E00", "stage 3")]
#: Slot states of :func:`slot_states`, in code order, with their colours.
SLOT_STATES = [("ok", "#009E73"), ("fallback (mean parameters)", "#F0E442"), ("alone (no peer)", "#E69F00"),
               ("dropped / skipped", "#D55E00"), ("not running", "0.85")]
#: Colours of the two schedules in every figure.
SCHEDULE_COLORS = ("#0072B2", "#E69F00")


def _gantt(ax, res: Sequence, window_s: float, title: str, lanes: int = 1) -> None:
    t0 = min(r.frames["target"][0] for r in res)
    h = 0.8 / lanes
    for r in res:
        f = r.frames
        for i in range(len(r)):
            base = f["target"][i] - t0
            if base > window_s:
                break
            y = r.meta["view"] - 0.4 + h * (i % lanes + 0.5)  # frames in flight at once: separate lanes
            for a, b, color, _ in PHASES:
                ka, kb = f"marks_{a}", f"marks_{b}"
                if ka in f and kb in f and np.isfinite(f[ka][i]) and np.isfinite(f[kb][i]):
                    ax.barh(y, 1000 * (f[kb][i] - f[ka][i]), left=1000 * (base + f[ka][i]), color=color,
                            height=0.85 * h)
            if not r.valid[i]:
                ax.plot(1000 * base, y, "kx")
    ax.set_yticks(range(len(res)), [f"drone {r.meta['drone']}" for r in res])
    ax.set_xlabel("time since the first slot [ms]")
    ax.set_title(title)
    ax.grid(axis="y", visible=False)


def plot_timeline(fixed: Sequence, pipelined: Sequence, title: str | None = None):
    """Each frame of each drone as a bar per phase: fixed 240 ms windows (first second) above,
    pipelined 20 fps (first half second, frames in flight on separate lanes) below; x = dropped."""
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    fig, axes = plt.subplots(2, 1, figsize=(10, 5.2), layout="constrained")
    _gantt(axes[0], fixed, 1.0, "fixed 240 ms windows (the paper's schedule)")
    _gantt(axes[1], pipelined, 0.5, "pipelined, 20 fps, 150 ms budget", lanes=3)
    handles = [plt.Rectangle((0, 0), 1, 1, color=c, label=lab) for _, _, c, lab in PHASES if lab]
    handles.append(Line2D([], [], color="k", marker="x", ls="", label="dropped frame"))
    fig.legend(handles=handles, ncol=len(handles), loc="outside lower center")
    if title:
        fig.suptitle(title)
    return fig


def plot_latency(runs: Mapping[str, Sequence], fps: Mapping[str, float], title: str | None = None):
    """Left: the distribution of end-to-end latency per schedule with the paper's 150 ms
    conjecture and the 240 ms window; right: frames per second per drone, the paper's next to the
    kit's, with the fixed window's nominal 4.17 fps."""
    import matplotlib.pyplot as plt

    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 3.8), layout="constrained")
    for (name, res), color in zip(runs.items(), SCHEDULE_COLORS):
        lat = np.sort(np.concatenate([r.frames["latency"][r.valid] for r in res])) * 1000
        a.plot(lat, np.arange(1, len(lat) + 1) / max(1, len(lat)), color=color, label=name)
    a.axvline(150, color="k", ls="--", lw=1, label="150 ms (paper's conjecture)")
    a.axvline(240, color="0.5", ls=":", lw=1, label="240 ms window")
    a.set_xlabel("end-to-end latency, shutter to result [ms]")
    a.set_ylabel("fraction of frames")
    a.set_title("latency (cumulative)")
    a.legend(loc="lower right")
    names = ["paper: fixed\n(TX2)", "paper: pipelined\n(conjecture)"] + [n.replace(" ", "\n", 1) for n in fps]
    vals = [3.0, 20.0] + [float(v) for v in fps.values()]
    colors = ["0.7", "0.85", *SCHEDULE_COLORS[: len(fps)]]
    bars = b.bar(names, vals, color=colors, edgecolor="black", linewidth=0.5)
    b.bar_label(bars, fmt="%.2f", fontsize=7)
    b.axhline(1 / 0.240, color="0.4", ls=":", lw=1, label="4.17 fps: one frame per 240 ms window")
    b.set_ylim(0, 1.3 * max(vals))  # room for the legend above the tallest bar and its label
    b.set_ylabel("frames per second per drone")
    b.set_title("achieved rate (dropped frames excluded)")
    b.legend(loc="upper right")
    b.grid(axis="x", visible=False)
    if title:
        fig.suptitle(title)
    return fig


def plot_online_vs_offline(frame_index: np.ndarray, online_tau: np.ndarray, offline_tau: np.ndarray,
                           ground_truth_tau: np.ndarray | None = None, title: str | None = None):
    """Depth of the person per camera: the drones' (online) results as dots over the same frames
    computed in one process (offline), same colours in every view; ground truth if known.

    Args:
        frame_index: ``(n, V)`` frame of each completed slot per view.
        online_tau, offline_tau: ``(n, V, 3)`` root translations.
        ground_truth_tau: ``(F, V, 3)`` over the whole recording, or None.
    """
    import matplotlib.pyplot as plt

    V = online_tau.shape[1]
    fig, axes = plt.subplots(1, V, figsize=(5.0 * V, 3.4), layout="constrained", squeeze=False)
    for v, ax in enumerate(axes[0]):
        if ground_truth_tau is not None:
            ax.plot(np.arange(len(ground_truth_tau)), ground_truth_tau[:, v, 2], color=VIEW_COLORS["ground truth"],
                    lw=1.2, label="ground truth")
        ax.plot(frame_index[:, v], offline_tau[:, v, 2], color="#0072B2", lw=1.5, label="offline (one process)")
        ax.plot(frame_index[:, v], online_tau[:, v, 2], "k.", ms=3, label="online (drone processes)")
        ax.set_xlabel("frame")
        ax.set_ylabel(r"depth $\tau_z$ [m]")
        ax.set_title(f"UAV{v + 1}")
    handles, labels = axes[0][0].get_legend_handles_labels()
    fig.legend(handles, labels, ncol=len(labels), loc="outside lower center")
    if title:
        fig.suptitle(title)
    return fig


def slot_states(frames: Mapping[str, np.ndarray], n_slots: int, flags) -> np.ndarray:
    """``(n_slots,)`` index into :data:`SLOT_STATES` of each schedule slot of one drone.

    Args:
        frames: the drone's records (``slot``, ``flags``).
        n_slots: slots of the run; slots without a record are "not running".
        flags: the record flag bits (``airpose_lib.runtime.results``: ``INVALID``, ``NO_PEERS``,
            ``FALLBACK_S2``, ``FALLBACK_S3``).
    """
    s = np.full(n_slots, 4)
    for slot, f in zip(frames["slot"], frames["flags"]):
        if f & flags.INVALID:
            s[slot] = 3
        elif f & flags.NO_PEERS:
            s[slot] = 2
        elif f & (flags.FALLBACK_S2 | flags.FALLBACK_S3):
            s[slot] = 1
        else:
            s[slot] = 0
    return s


def plot_fault_states(states: np.ndarray, period_s: float, conditions: str, title: str | None = None):
    """One row per drone, one cell per schedule slot, coloured by :data:`SLOT_STATES`.

    Args:
        states: ``(D, n_slots)`` from :func:`slot_states`.
        period_s: slot length.
        conditions: what was done to the run (packet loss, kill/restart ...), written under the title.
    """
    import matplotlib.pyplot as plt
    from matplotlib.colors import ListedColormap

    D, n = states.shape
    fig, ax = plt.subplots(figsize=(10, 1.0 + 0.45 * D), layout="constrained")
    ax.imshow(states, aspect="auto", cmap=ListedColormap([c for _, c in SLOT_STATES]), vmin=0,
              vmax=len(SLOT_STATES) - 1, interpolation="nearest", extent=(0, n * period_s, D - 0.5, -0.5))
    ax.set_yticks(range(D), [f"drone {d + 1}" for d in range(D)])
    ax.set_xlabel("schedule time [s]")
    ax.grid(False)
    ax.set_title(conditions, fontsize=8)
    fig.legend([plt.Rectangle((0, 0), 1, 1, color=c) for _, c in SLOT_STATES], [n for n, _ in SLOT_STATES],
               ncol=len(SLOT_STATES), loc="outside lower center")
    if title:
        fig.suptitle(title)
    return fig
