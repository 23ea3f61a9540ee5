"""Real-data figures (airpose_lib.viz.trajectories): the plotted data are the inputs, overlays
blend only where the mesh was hit."""
from __future__ import annotations

import numpy as np
import pytest

from airpose_lib.viz.style import METHOD_COLORS
from airpose_lib.viz.trajectories import (
    line_style,
    overlay_mesh,
    plot_mesh_overlays,
    plot_person_positions,
    plot_relative_camera,
)


def test_line_style_dashes_pretrained_in_the_same_colour():
    assert line_style("AirPose")["color"] == METHOD_COLORS["AirPose"]
    assert line_style("AirPose (pre-trained)") == {**line_style("AirPose"), "ls": "--"}
    assert line_style("something else")["color"] == "#777777"


def test_person_positions_plot_draws_each_coordinate_of_each_view():
    import matplotlib.pyplot as plt

    rng = np.random.default_rng(0)
    F, V = 20, 2
    t = np.arange(F) / 30
    est = {"AirPose": rng.normal(size=(F, V, 3)), "Baseline": rng.normal(size=(F, V, 3))}
    gt = rng.normal(size=(F, V, 3))
    fig = plot_person_positions(est, t, gt, axes="xz")
    axes = np.array(fig.axes).reshape(2, V)
    for r, k in enumerate((0, 2)):
        for v in range(V):
            lines = {ln.get_label(): ln for ln in axes[r, v].get_lines()}
            np.testing.assert_array_equal(lines["Ground truth"].get_ydata(), gt[:, v, k])
            np.testing.assert_array_equal(lines["AirPose"].get_ydata(), est["AirPose"][:, v, k])
            np.testing.assert_array_equal(lines["Baseline"].get_xdata(), t)
    plt.close(fig)

    fig = plot_relative_camera({"AirPose+": gt[:, 0]}, t, ground_truth=gt[:, 1])
    assert len(fig.axes) == 3
    np.testing.assert_array_equal(fig.axes[1].get_lines()[1].get_ydata(), gt[:, 0, 1])
    plt.close(fig)


def test_overlay_blends_only_where_the_mesh_was_hit():
    image = np.full((4, 5, 3), 100, np.uint8)
    rgb = np.full((4, 5, 3), 200, np.uint8)
    depth = np.full((4, 5), np.inf)
    depth[1, 2] = 3.0
    out = overlay_mesh(image, rgb, depth, alpha=0.75)
    assert out[1, 2].tolist() == [175, 175, 175]  # 0.25 * 100 + 0.75 * 200
    mask = np.ones((4, 5), bool)
    mask[1, 2] = False
    assert np.all(out[mask] == 100)


@pytest.mark.slow
def test_mesh_overlay_lands_on_the_projected_mesh(open_model):
    """The rendered mesh covers the pixels its vertices project to (off-screen, real renderer)."""
    import matplotlib.pyplot as plt

    from airpose_lib.viz.render import OffscreenRenderer

    v = open_model().vertices[0].detach().numpy() * np.array([1, -1, -1]) + [0, 0, 4]  # facing the camera
    faces = np.asarray(open_model.faces, np.int64)
    K = np.array([[300.0, 0, 80], [0, 300, 60], [0, 0, 1]])
    with OffscreenRenderer((160, 120), K) as r:
        _, depth = r.render(v, faces, return_depth=True)
    uv = (v @ K.T)[:, :2] / v[:, 2:3]
    inside = (uv[:, 0] > 1) & (uv[:, 0] < 158) & (uv[:, 1] > 1) & (uv[:, 1] < 118)
    px = np.round(uv[inside]).astype(int)
    assert np.isfinite(depth[px[:, 1], px[:, 0]]).mean() > 0.85  # misses: silhouette edges, fingers
    images = np.zeros((1, 2, 120, 160, 3), np.uint8)
    for Ks in (np.stack([K, K]), np.stack([K, K])[None]):  # per view, or per image (crops)
        fig = plot_mesh_overlays(images, {"AirPose": np.stack([v, v])[None]}, faces, Ks)
        assert len(fig.axes) == 2
        plt.close(fig)
