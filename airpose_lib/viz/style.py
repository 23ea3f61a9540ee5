"""One figure style for every kit figure, and the colours that stand for methods and views.

Colours follow the Okabe-Ito palette (distinguishable with the common colour-vision
deficiencies), chosen so that the methods drawn together stay apart: Baseline grey, AirPose blue,
AirPose+ vermillion (the real-data figures); Baseline, Multi-view orange, Fullcam purple, AirPose
(Table I). The per-camera colours keep the paper's convention for 3D scenes (Fig. 4): red for the
estimate from the first camera, blue for the second, green for the ground truth.

Axis labels write units in brackets, ``"depth [m]"``, ``"latency [ms]"``. Every figure saved with
:func:`save_figure` names the profile and data source that made it in a footer.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path

import matplotlib as mpl

from airpose_lib import __version__  # the package root holds only the version
from airpose_lib.paths import profile_name

__all__ = [
    "METHOD_COLORS",
    "VIEW_COLORS",
    "SIDE_COLORS",
    "MESH_COLOR",
    "PAPER_COLOR",
    "method_color",
    "figure_footer",
    "use_kit_style",
    "save_figure",
]

#: One colour per method of the paper's tables and plots, plus the ground truth.
METHOD_COLORS: dict[str, str] = {
    "Baseline": "#7A7A7A",             # grey
    "Baseline+Multi-view": "#E69F00",  # orange
    "Baseline+Fullcam": "#CC79A7",     # reddish purple
    "AirPose": "#0072B2",              # blue
    "AirPose+": "#D55E00",             # vermillion
    "SPIN-style": "#000000",           # black: the crop-only weak-perspective regressor
    "Ground truth": "#009E73",         # bluish green
}

#: Bars and lines of the paper's own numbers next to the kit's.
PAPER_COLOR = "#BBBBBB"

#: Estimates per camera in 3D scenes, as in the paper's figures.
VIEW_COLORS: dict[str, str] = {"camera 1": "#D55E00", "camera 2": "#0072B2",
                               "ground truth": "#009E73"}

#: Left / right / centre limbs in skeleton drawings.
SIDE_COLORS: dict[str, str] = {"left": "#0072B2", "right": "#D55E00", "centre": "#444444"}

#: Body mesh colour in renders, RGB in [0, 1].
MESH_COLOR: tuple[float, float, float] = (0.70, 0.74, 0.82)


def _key(name: str) -> str:
    return "".join(ch for ch in name.lower() if ch.isalnum() or ch == "+")


_METHOD_KEYS = {_key(k): v for k, v in METHOD_COLORS.items()}
_METHOD_KEYS.update({"gt": METHOD_COLORS["Ground truth"], "groundtruth": METHOD_COLORS["Ground truth"]})


def method_color(name: str) -> str:
    """Colour of a method, tolerant of case, spaces and dashes (``"airpose+"``, ``"GT"``)."""
    try:
        return _METHOD_KEYS[_key(name)]
    except KeyError:
        raise KeyError(f"no colour for method {name!r}; known: {list(METHOD_COLORS)}") from None


def use_kit_style() -> None:
    """Set matplotlib defaults for kit figures (call once at the top of a notebook)."""
    mpl.rcParams.update({
        "figure.dpi": 100,
        "savefig.dpi": 150,
        "savefig.bbox": "tight",
        "savefig.pad_inches": 0.05,
        "figure.facecolor": "white",
        "savefig.facecolor": "white",
        "font.size": 9,
        "axes.titlesize": 10,
        "axes.labelsize": 9,
        "xtick.labelsize": 8,
        "ytick.labelsize": 8,
        "legend.fontsize": 8,
        "legend.frameon": False,
        "axes.spines.top": False,
        "axes.spines.right": False,
        "axes.grid": True,
        "grid.alpha": 0.3,
        "grid.linewidth": 0.5,
        "lines.linewidth": 1.5,
        "image.interpolation": "antialiased",
        "axes.prop_cycle": mpl.cycler(color=list(METHOD_COLORS.values())),
    })


def figure_footer(params: Mapping | None) -> str:
    """``"profile smoke · data generated · airpose_lib 0.1.0"`` from a figure's ``params``
    (``profile``, ``data_source``, else ``source``; absent keys are left out)."""
    params = dict(params or {})
    parts = []
    if params.get("notebook"):
        parts.append(str(params["notebook"]))
    if params.get("profile") is not None:
        parts.append(f"profile {profile_name(params['profile'])}")
    data = params.get("data_source", params.get("source"))
    if data is not None:
        parts.append(f"data {data}")
    parts.append(f"airpose_lib {__version__}")
    return " \u00b7 ".join(parts)


def _add_footer(fig, text: str) -> None:
    """``text`` right-aligned just above everything drawn (titles included): the saved (tight)
    bounding box grows to include it and nothing is covered."""
    dpi = mpl.rcParams["savefig.dpi"]
    if dpi != "figure":  # lay out at the saving resolution: "outside" legends move with the dpi
        fig.set_dpi(float(dpi))
    fig.canvas.draw()  # lays out the figure (constrained layout included) so that its extent is final
    box = fig.get_tightbbox(fig.canvas.get_renderer())  # inches
    w, h = fig.get_size_inches()
    fig.text(box.x1 / w, box.y1 / h + 2 / 72 / h, text, ha="right", va="bottom", fontsize=6.5, color="0.4")


def save_figure(fig, path: str | Path, *, params: Mapping | None = None, show: bool = True,
                close: bool = True, footer: bool = True) -> Path:
    """Save a matplotlib figure as a kit artefact and (in IPython) display the saved file.

    The PNG's metadata carries the kit version and ``params`` (JSON), and a grey line over the
    figure names the notebook, profile and data source (:func:`figure_footer`), so a figure found
    on disk or pasted in a document says what made it. Displaying the saved file rather than the
    live figure makes the notebook look the same under any matplotlib backend (the reproduction
    runner uses Agg).

    Args:
        fig: a ``matplotlib.figure.Figure``.
        path: output file; parent folders are created.
        params: parameters to record (JSON-serialisable); ``profile`` and ``data_source`` (or
            ``source``) go into the footer.
        show: display the saved image when running inside IPython.
        close: close the figure afterwards (frees memory in long notebooks).
        footer: draw the footer (when ``params`` is given).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if footer and params is not None:
        _add_footer(fig, figure_footer(params))
    meta = {"Software": f"airpose_lib {__version__}"}
    if params is not None and path.suffix.lower() == ".png":
        meta["Description"] = json.dumps(dict(params), default=str, sort_keys=True)
    fig.savefig(path, metadata=meta if path.suffix.lower() == ".png" else None)
    if close:
        import matplotlib.pyplot as plt

        plt.close(fig)
    if show:
        try:
            from IPython import get_ipython
            from IPython.display import Image, display

            if get_ipython() is not None:
                display(Image(filename=str(path)))
        except ImportError:
            pass
    return path
