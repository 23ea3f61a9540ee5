"""Table I bar figure: legend clear of the bars, swatches that match them, paper bars on scale."""
import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from matplotlib.colors import to_hex  # noqa: E402

from airpose_lib.eval.ablation import ablation_table  # noqa: E402
from airpose_lib.eval.mean_body import (  # noqa: E402
    GENDERED_LABEL,
    MEAN_BODY_LABELS,
    NEUTRAL_LABEL,
    PROPORTION_LABEL,
)
from airpose_lib.viz.ablation import SOURCE_COLORS, plot_table1  # noqa: E402


def _table():
    runs = {}
    for s in (1, 2):
        for v, mpe, mpjpe in (("baseline", 9.3, 0.37), ("multiview", 9.0, 0.36), ("fullcam", 1.2, 0.27),
                              ("airpose", 1.2 + 0.1 * s, 0.26)):
            runs[v, s] = pd.DataFrame({"sample": [0], "view": [0], "mpe_m": [mpe], "mpjpe_m": [mpjpe],
                                       "pa_mpjpe_m": [mpjpe / 2]})
    return ablation_table(runs, references=pd.DataFrame({"method": [NEUTRAL_LABEL, GENDERED_LABEL, PROPORTION_LABEL],
                                                         "mpe_m": [0.55, 0.45, 0.05]}))


def test_table1_figure_is_readable():
    t = _table()
    fig = plot_table1(t, reference=t * 1.1, kit_label="kit (smoke)", line_rows=MEAN_BODY_LABELS)
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    legend = fig.legends[0]
    box = legend.get_window_extent(renderer)
    for ax in fig.axes:
        assert ax.get_yscale() == "log" and "[m]" in ax.get_ylabel()
        assert not box.overlaps(ax.get_window_extent(renderer))  # the legend covers no bar
        # every source's bars carry the colour of its legend swatch; 4 methods x 3 sources
        colors = [to_hex(p.get_facecolor()) for p in ax.patches]
        assert len(colors) == 12 and sorted(set(colors)) == sorted(to_hex(c) for c in SOURCE_COLORS.values())
        heights = np.array([p.get_height() for p in ax.patches])
        low, high = ax.get_ylim()
        assert low < heights.min() and heights.max() < high  # paper bars (0.15 m) visible next to 9 m ones
    swatches = {t.get_text(): to_hex(h.get_facecolor()) for t, h in zip(legend.get_texts(), legend.legend_handles)
                if hasattr(h, "get_facecolor")}
    assert swatches["kit (smoke)"] == to_hex(SOURCE_COLORS["kit"])
    assert swatches["paper"] == to_hex(SOURCE_COLORS["paper"])
    assert set(MEAN_BODY_LABELS) <= {t.get_text() for t in legend.get_texts()}
    # the three reference lines (MPE only), one dash style each
    assert [(ln.get_ydata()[0], ln.get_linestyle()) for ln in fig.axes[0].lines[-3:]] == [
        (0.55, "--"), (0.45, ":"), (0.05, "-.")]
    assert not [ln for ln in fig.axes[1].lines if ln.get_linestyle() in ("--", ":", "-.")]


def test_without_reference_two_bars_per_method():
    fig = plot_table1(_table().drop(index=list(MEAN_BODY_LABELS)))
    assert all(len(ax.patches) == 8 for ax in fig.axes)


def _title_overlaps(fig) -> list[str]:
    """Panel titles the figure title covers (after a draw with the layout engine)."""
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    top = fig._suptitle.get_window_extent(renderer)
    return [ax.get_title() for ax in fig.axes
            if ax.get_title() and top.overlaps(ax.title.get_window_extent(renderer))]


def test_qualitative_figures_keep_the_title_clear_of_the_panel_titles():
    """The title is given to the plot functions (a notebook's own ``suptitle(y=1.0)`` on a
    constrained layout was drawn over the first row's titles)."""
    import matplotlib.pyplot as plt

    from airpose_lib.viz.ablation import plot_ablation_meshes, plot_ablation_samples

    rng = np.random.default_rng(0)
    n, V, S = 2, 2, 64
    crops = np.zeros((n, V, S, S, 3), np.uint8)
    methods = ["Baseline", "Baseline+Multi-view", "Baseline+Fullcam", "AirPose"]
    uv = {m: rng.uniform(8, 56, (n, V, 22, 2)) for m in methods}
    pos = {m: rng.normal(size=(n, V, 3)) for m in methods}
    fig = plot_ablation_samples(crops, uv, rng.uniform(8, 56, (n, V, 22, 2)), pos, np.zeros((n, 3)),
                                title="ablation variants on 2 test samples (smoke profile)")
    assert fig._suptitle.get_text().startswith("ablation variants") and not _title_overlaps(fig)
    plt.close(fig)

    verts = np.array([[-0.3, -0.3, 3.0], [0.3, -0.3, 3.0], [0.0, 0.4, 3.0], [0.0, 0.0, 2.6]])
    faces = np.array([[0, 1, 2], [0, 1, 3], [1, 2, 3], [0, 2, 3]])
    K = np.broadcast_to(np.array([[80.0, 0, 32], [0, 80.0, 32], [0, 0, 1]]), (n, V, 3, 3))
    vertices = {m: np.broadcast_to(verts, (n, V, 4, 3)) for m in ["Ground truth", *methods]}
    fig = plot_ablation_meshes(crops, vertices, faces, K, title="ablation variants: meshes in the crops")
    assert fig._suptitle.get_text() == "ablation variants: meshes in the crops" and not _title_overlaps(fig)
    plt.close(fig)
