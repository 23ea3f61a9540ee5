"""Table I bar figure: legend clear of the bars, swatches that match them, paper bars on scale."""
import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from matplotlib.colors import to_hex  # noqa: E402

from airpose_lib.eval.ablation import ablation_table  # noqa: E402
from airpose_lib.eval.oracle import ORACLE_LABEL  # noqa: E402
from airpose_lib.viz.ablation import SOURCE_COLORS, plot_table1  # noqa: E402


def _table():
    runs = {}
    for s in (1, 2):
        for v, mpe, mpjpe in (("baseline", 9.3, 0.37), ("multiview", 9.0, 0.36), ("fullcam", 1.2, 0.27),
                              ("airpose", 1.2 + 0.1 * s, 0.26)):
            runs[v, s] = pd.DataFrame({"sample": [0], "view": [0], "mpe_m": [mpe], "mpjpe_m": [mpjpe],
                                       "pa_mpjpe_m": [mpjpe / 2]})
    return ablation_table(runs, oracle=pd.DataFrame({"mpe_m": [0.55]}))


def test_table1_figure_is_readable():
    t = _table()
    fig = plot_table1(t, reference=t * 1.1, kit_label="kit (smoke)", oracle_label=ORACLE_LABEL)
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
    assert any("oracle" in t.get_text() for t in legend.get_texts())
    assert fig.axes[0].lines and fig.axes[0].lines[-1].get_ydata()[0] == 0.55  # the floor line (MPE only)
    assert not [ln for ln in fig.axes[1].lines if ln.get_linestyle() == "--"]


def test_without_reference_two_bars_per_method():
    fig = plot_table1(_table().drop(index=ORACLE_LABEL))
    assert all(len(ax.patches) == 8 for ax in fig.axes)
