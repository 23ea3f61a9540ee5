"""Recording figures: the detection grid zooms on the keypoints and skips low-confidence ones."""
import matplotlib

matplotlib.use("Agg")
import numpy as np

from airpose_lib.viz.sequences import _zoom_box, plot_detections_grid, plot_recording_overview


def test_zoom_box_contains_points_and_stays_in_image():
    pts = np.array([[100.0, 200.0], [140.0, 300.0]])
    x0, y0, x1, y1 = _zoom_box(pts, (540, 960))
    assert x0 <= 100 and x1 >= 140 and y0 <= 200 and y1 >= 300
    x0, y0, x1, y1 = _zoom_box(np.array([[2.0, 3.0], [20.0, 30.0]]), (540, 960))
    assert x0 == 0 and y0 == 0


def test_detection_grid_layout_and_confidence_filter():
    rng = np.random.default_rng(0)
    images = [[np.zeros((540, 960, 3), np.uint8) for _ in range(2)] for _ in range(3)]
    det = np.zeros((3, 2, 25, 3))
    det[..., 0] = 400 + 50 * rng.random((3, 2, 25))
    det[..., 1] = 200 + 100 * rng.random((3, 2, 25))
    det[..., 2] = 0.9
    det[0, 0, 5] = [900.0, 500.0, 0.0]  # a missed keypoint far away must not widen the zoom
    gt = det[..., :2].copy()
    gt[0, 0, 5] = gt[0, 0, 4]
    fig = plot_detections_grid(images, {"openpose": det}, ground_truth=gt)
    axes = fig.axes
    assert len(axes) == 6
    x0, x1 = axes[0].get_xlim()
    assert x1 < 900 and x0 <= det[0, 0, :, 0][det[0, 0, :, 2] > 0].min()
    y_top, y_bottom = sorted(axes[0].get_ylim())
    assert y_top <= 200 and y_bottom >= 300


def test_recording_overview_reports_the_offset():
    F = 30
    t = np.stack([np.arange(F) / 30.0, np.arange(F) / 30.0 + 0.007], axis=1)
    fig = plot_recording_overview(np.zeros((F, 2, 3)), np.zeros((F, 3)), t, title="x")
    assert "7.0 ms" in fig.axes[1].get_title()
